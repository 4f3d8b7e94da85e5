//! The load generator of `scripts/bench-memory.py` at scale: many Modbus TCP
//! devices in one lean process, so that the peer side of a million-tag bench
//! costs a few percent of a core, not the cores the Python servers need.
//!
//! `register_walker PER_DEVICE PORT[,PORT...]`: one server per port (unit id
//! any), PER_DEVICE holding registers each, starting at 500. Every second a
//! tenth of each device's registers take a random step of -10..=10, clamped
//! to 0..=1000 (the same walk as the Python servers). Prints `ready` once
//! every port is bound; stops when its stdin closes.

use std::future::{ready, Ready};
use std::io::Read;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use tokio::net::TcpListener;
use tokio_modbus::prelude::*;
use tokio_modbus::server::tcp::{accept_tcp_connection, Server};
use tokio_modbus::server::Service;

const SPAN_RAW: u16 = 1000;

/// One device's holding registers.
type Registers = Arc<Mutex<Vec<u16>>>;

#[derive(Clone)]
struct Device(Registers);

impl Service for Device {
    type Request = SlaveRequest<'static>;
    type Response = Response;
    type Exception = ExceptionCode;
    type Future = Ready<Result<Response, ExceptionCode>>;

    fn call(&self, req: Self::Request) -> Self::Future {
        let regs = self.0.lock().expect("registers");
        ready(match req.request {
            Request::ReadHoldingRegisters(addr, n) => {
                let (from, to) = (addr as usize, addr as usize + n as usize);
                if to <= regs.len() {
                    Ok(Response::ReadHoldingRegisters(regs[from..to].to_vec()))
                } else {
                    Err(ExceptionCode::IllegalDataAddress)
                }
            }
            _ => Err(ExceptionCode::IllegalFunction),
        })
    }
}

/// xorshift64*: enough randomness for a walk, no dependency.
struct Walk(u64);

impl Walk {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let usage = "usage: register_walker PER_DEVICE PORT[,PORT...]";
    let per_device: usize = args.get(1).and_then(|s| s.parse().ok()).expect(usage);
    let ports: Vec<u16> = args
        .get(2)
        .expect(usage)
        .split(',')
        .map(|p| p.parse().expect(usage))
        .collect();
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .expect("runtime");
    rt.block_on(async move {
        let mut devices = Vec::new();
        for port in ports {
            let regs: Registers = Arc::new(Mutex::new(vec![500; per_device]));
            let listener = TcpListener::bind(("127.0.0.1", port))
                .await
                .unwrap_or_else(|e| panic!("bind 127.0.0.1:{port}: {e}"));
            let device = Device(Arc::clone(&regs));
            tokio::spawn(async move {
                let on_connected = |stream, socket_addr| {
                    let device = device.clone();
                    async move {
                        accept_tcp_connection(stream, socket_addr, move |_| {
                            Ok(Some(device.clone()))
                        })
                    }
                };
                let _ = Server::new(listener).serve(&on_connected, |_| {}).await;
            });
            devices.push(regs);
        }
        println!("ready");
        tokio::spawn(async move {
            let mut rng = Walk(0x9e37_79b9_7f4a_7c15);
            let mut tick = tokio::time::interval(Duration::from_secs(1));
            loop {
                tick.tick().await;
                for regs in &devices {
                    let mut regs = regs.lock().expect("registers");
                    for _ in 0..per_device / 10 {
                        let a = (rng.next() % per_device as u64) as usize;
                        let step = (rng.next() % 21) as i32 - 10;
                        regs[a] = (regs[a] as i32 + step).clamp(0, SPAN_RAW as i32) as u16;
                    }
                }
            }
        });
        // Until the parent closes our stdin.
        let _ = tokio::task::spawn_blocking(|| {
            let mut s = Vec::new();
            let _ = std::io::stdin().read_to_end(&mut s);
        })
        .await;
    });
}
