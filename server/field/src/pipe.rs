//! In-process connections: a byte pipe in place of a TCP connection to an
//! address the process serves itself.
//!
//! A scenario replay runs its own simulated devices in the same process as
//! the poller. Over loopback TCP, each of its millions of transactions costs
//! a send, a receive and a wake-up in the kernel on both sides; over a pipe
//! it costs two buffer copies. The bytes are the same: the poller still
//! frames and decodes Modbus TCP, and the simulator still answers it, so the
//! path under test is the one a real device takes, minus the kernel.
//!
//! **Owns:** which addresses are served in process, and handing each dial the
//! server's end of a new pipe. **Must not touch:** framing (each protocol's),
//! real sockets.

use std::collections::HashMap;
use std::io;
use std::sync::Mutex;

use tokio::io::DuplexStream;
use tokio::sync::mpsc;

/// Bytes a pipe holds in each direction before a writer waits: far more than
/// one request and its answer (a Modbus TCP frame is at most 260 bytes).
const PIPE_BUFFER: usize = 8 * 1024;

/// The addresses this process serves itself, and their waiting servers.
#[derive(Debug, Default)]
pub struct Switchboard {
    lines: Mutex<HashMap<String, mpsc::UnboundedSender<DuplexStream>>>,
}

impl Switchboard {
    pub fn new() -> Self {
        Self::default()
    }

    /// Serves `address` in process: each dial of it hands the server's end
    /// of a new pipe to the receiver. A second listen replaces the first.
    pub fn listen(&self, address: &str) -> mpsc::UnboundedReceiver<DuplexStream> {
        let (tx, rx) = mpsc::unbounded_channel();
        self.lines
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .insert(address.to_string(), tx);
        rx
    }

    /// A new connection to `address`: `None` when this process does not
    /// serve it (connect over the network), an error when it did but its
    /// server has stopped (as a refused TCP connection).
    pub fn dial(&self, address: &str) -> Option<io::Result<DuplexStream>> {
        let lines = self.lines.lock().unwrap_or_else(|e| e.into_inner());
        let server = lines.get(address)?;
        let (client, served) = tokio::io::duplex(PIPE_BUFFER);
        Some(match server.send(served) {
            Ok(()) => Ok(client),
            Err(_) => Err(io::Error::new(
                io::ErrorKind::ConnectionRefused,
                format!("{address}: the in-process server has stopped"),
            )),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tokio::io::{AsyncReadExt, AsyncWriteExt};

    #[tokio::test]
    async fn a_dial_reaches_the_listener_and_bytes_flow_both_ways() {
        let board = Switchboard::new();
        assert!(board.dial("127.0.0.1:502").is_none());
        let mut incoming = board.listen("127.0.0.1:502");
        let mut client = board.dial("127.0.0.1:502").unwrap().unwrap();
        let mut served = incoming.recv().await.unwrap();
        client.write_all(b"ping").await.unwrap();
        let mut buf = [0u8; 4];
        served.read_exact(&mut buf).await.unwrap();
        assert_eq!(&buf, b"ping");
        served.write_all(b"pong").await.unwrap();
        client.read_exact(&mut buf).await.unwrap();
        assert_eq!(&buf, b"pong");
        // The server going away closes the client's end.
        drop(served);
        assert_eq!(client.read(&mut buf).await.unwrap(), 0);
    }

    #[tokio::test]
    async fn a_stopped_server_refuses() {
        let board = Switchboard::new();
        drop(board.listen("10.0.0.1:502"));
        let err = board.dial("10.0.0.1:502").unwrap().unwrap_err();
        assert_eq!(err.kind(), io::ErrorKind::ConnectionRefused);
    }
}
