//! Live-socket caps: open WebSockets counted per session and per address,
//! each place held by a slot that frees it when dropped.

use std::collections::HashMap;
use std::net::IpAddr;
use std::sync::Arc;

use parking_lot::Mutex;

/// Counts open live sockets per session and per address, so one client
/// cannot open hundreds.
#[derive(Default)]
pub struct SocketCounts {
    open: Mutex<HashMap<String, usize>>,
}

/// Most live sockets per session (several tabs) and per address.
pub const MAX_SOCKETS_PER_SESSION: usize = 8;
pub const MAX_SOCKETS_PER_ADDRESS: usize = 64;

/// One open socket; dropping it frees its places.
pub struct SocketSlot {
    counts: Arc<SocketCounts>,
    keys: Vec<String>,
}

impl Drop for SocketSlot {
    fn drop(&mut self) {
        let mut open = self.counts.open.lock();
        for k in &self.keys {
            if let Some(n) = open.get_mut(k) {
                *n -= 1;
                if *n == 0 {
                    open.remove(k);
                }
            }
        }
    }
}

impl SocketCounts {
    /// Takes a place for a socket of `session` from `ip`, or says which
    /// limit is reached.
    pub fn open(self: &Arc<Self>, session: Option<&str>, ip: IpAddr) -> Result<SocketSlot, String> {
        let mut keys = vec![(format!("ip:{ip}"), MAX_SOCKETS_PER_ADDRESS)];
        if let Some(t) = session {
            keys.push((format!("session:{t}"), MAX_SOCKETS_PER_SESSION));
        }
        let mut open = self.open.lock();
        for (k, max) in &keys {
            if open.get(k).copied().unwrap_or(0) >= *max {
                return Err(format!(
                    "too many live connections ({max} per {})",
                    if k.starts_with("ip:") {
                        "address"
                    } else {
                        "session"
                    }
                ));
            }
        }
        for (k, _) in &keys {
            *open.entry(k.clone()).or_insert(0) += 1;
        }
        Ok(SocketSlot {
            counts: self.clone(),
            keys: keys.into_iter().map(|(k, _)| k).collect(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn socket_places_are_capped_and_freed() {
        let c = Arc::new(SocketCounts::default());
        let ip: IpAddr = "127.0.0.1".parse().unwrap();
        let slots: Vec<_> = (0..MAX_SOCKETS_PER_SESSION)
            .map(|_| c.open(Some("t"), ip).unwrap())
            .collect();
        assert!(c.open(Some("t"), ip).is_err());
        assert!(c.open(Some("u"), ip).is_ok());
        drop(slots);
        assert!(c.open(Some("t"), ip).is_ok());
    }
}
