//! Whether this server may command the plant: the fencing gate of a
//! redundant pair.
//!
//! One [`Leadership`] is shared by the field writer (which asks it at the
//! moment a write frame goes out) and by whoever keeps the lease (the app's
//! lease keeper, which grants it after each renewal and revokes it when it
//! loses the lease). A grant ends by itself at a deadline on this machine's
//! monotonic clock, set from the moment the renewal was *sent*, minus a
//! margin: so a server that stops renewing (frozen, cut off from the
//! database) stops writing before the lease can expire in the database and
//! another server can take it. The timing argument is in `ARCHITECTURE.md`,
//! "Redundant pair".
//!
//! A server alone (no `[redundancy]`) is [`Leadership::sole`]: always
//! active, epoch 0.

use std::sync::Arc;
use std::time::Instant;

use parking_lot::Mutex;
use tokio::sync::watch;

/// This server's part in the pair, as the rest of the server sees it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Role {
    /// Holding the lease under `epoch`: may command the plant.
    Active { epoch: u64 },
    /// Not holding it; `active` names the server that does, if known.
    Standby { active: Option<String> },
}

impl Role {
    pub fn is_active(&self) -> bool {
        matches!(self, Role::Active { .. })
    }
}

#[derive(Debug)]
enum Grant {
    /// No pair: always allowed.
    Sole,
    Held {
        epoch: u64,
        until: Instant,
    },
    None {
        active: Option<String>,
    },
}

#[derive(Debug)]
struct Inner {
    /// This server's name in the pair (empty when alone).
    server: String,
    grant: Mutex<Grant>,
    role: watch::Sender<Role>,
}

/// The shared gate. Cheap to clone.
#[derive(Debug, Clone)]
pub struct Leadership(Arc<Inner>);

/// Why a command was refused: this server does not hold the lease.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NotActive {
    /// The server that holds it, if known (with its URL, as configured).
    pub active: Option<String>,
}

impl std::fmt::Display for NotActive {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match &self.active {
            Some(a) => write!(
                f,
                "this server is on standby; commands go to the active server {a}"
            ),
            None => write!(
                f,
                "this server is on standby and no server of the pair is active now"
            ),
        }
    }
}

impl Leadership {
    /// A server without a pair: always active, epoch 0.
    pub fn sole() -> Leadership {
        Leadership(Arc::new(Inner {
            server: String::new(),
            grant: Mutex::new(Grant::Sole),
            role: watch::channel(Role::Active { epoch: 0 }).0,
        }))
    }

    /// A server of a pair, `server` by name, starting on standby.
    pub fn standby(server: &str) -> Leadership {
        Leadership(Arc::new(Inner {
            server: server.to_string(),
            grant: Mutex::new(Grant::None { active: None }),
            role: watch::channel(Role::Standby { active: None }).0,
        }))
    }

    /// Whether this server is one of a pair (not [`Leadership::sole`]).
    pub fn is_pair(&self) -> bool {
        !matches!(*self.0.grant.lock(), Grant::Sole)
    }

    /// This server's name in the pair (empty when alone).
    pub fn server(&self) -> &str {
        &self.0.server
    }

    /// Grants commands under `epoch` until `until` (a renewal sent at `t`
    /// for a lease of `L` with margin `m` grants until `t + L - m`).
    pub fn grant(&self, epoch: u64, until: Instant) {
        let mut g = self.0.grant.lock();
        if matches!(*g, Grant::Sole) {
            return;
        }
        *g = Grant::Held { epoch, until };
        drop(g);
        self.0.role.send_if_modified(|r| {
            let new = Role::Active { epoch };
            let changed = *r != new;
            *r = new;
            changed
        });
    }

    /// Ends the grant now; `active` names the holder, if known.
    pub fn revoke(&self, active: Option<String>) {
        let mut g = self.0.grant.lock();
        if matches!(*g, Grant::Sole) {
            return;
        }
        *g = Grant::None {
            active: active.clone(),
        };
        drop(g);
        self.0.role.send_if_modified(|r| {
            let new = Role::Standby { active };
            let changed = *r != new;
            *r = new;
            changed
        });
    }

    /// The epoch to command under, if commands are allowed *now*. Asked at
    /// the last moment before a command goes out.
    pub fn permit(&self) -> Result<u64, NotActive> {
        match &*self.0.grant.lock() {
            Grant::Sole => Ok(0),
            Grant::Held { epoch, until } if Instant::now() < *until => Ok(*epoch),
            Grant::Held { .. } => Err(NotActive { active: None }),
            Grant::None { active } => Err(NotActive {
                active: active.clone(),
            }),
        }
    }

    /// The role as last granted or revoked (a grant that ran out by the
    /// clock shows as active here until the keeper revokes it; [`permit`]
    /// already refuses).
    ///
    /// [`permit`]: Leadership::permit
    pub fn role(&self) -> Role {
        self.0.role.borrow().clone()
    }

    /// Follows role changes.
    pub fn subscribe(&self) -> watch::Receiver<Role> {
        self.0.role.subscribe()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn a_grant_ends_by_itself_at_its_deadline() {
        let l = Leadership::standby("a");
        assert_eq!(l.permit(), Err(NotActive { active: None }));
        l.grant(7, Instant::now() + Duration::from_millis(50));
        assert_eq!(l.permit(), Ok(7));
        assert!(l.role().is_active());
        std::thread::sleep(Duration::from_millis(60));
        assert!(l.permit().is_err(), "no command after the deadline");
        l.revoke(Some("b (http://10.0.0.2:8080)".into()));
        let e = l.permit().unwrap_err();
        assert_eq!(
            e.to_string(),
            "this server is on standby; commands go to the active server b (http://10.0.0.2:8080)"
        );
        assert_eq!(
            l.role(),
            Role::Standby {
                active: Some("b (http://10.0.0.2:8080)".into())
            }
        );
    }

    #[test]
    fn a_sole_server_is_always_active() {
        let l = Leadership::sole();
        l.revoke(None);
        assert_eq!(l.permit(), Ok(0));
    }
}
