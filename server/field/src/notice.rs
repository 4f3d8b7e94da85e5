//! Notices of a device's own doings that belong in the event log (an
//! outstation that restarted, lost events, had its clock set, a station
//! that ended its initialisation), from a protocol's task to the
//! application, which records them. The protocol crates do not touch the
//! event log themselves.

use tokio::sync::mpsc;

/// One notice: the device and what happened, in words.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DeviceNotice {
    pub device: String,
    pub message: String,
}

/// The sending side, one clone per device task. Never blocks: a notice
/// that finds the queue full is logged and dropped (the device's figures
/// still count what happened).
#[derive(Debug, Clone)]
pub struct Notices(mpsc::Sender<DeviceNotice>);

impl Notices {
    /// A sender and its receiver, holding up to `capacity` notices.
    pub fn channel(capacity: usize) -> (Notices, mpsc::Receiver<DeviceNotice>) {
        let (tx, rx) = mpsc::channel(capacity);
        (Notices(tx), rx)
    }

    pub fn send(&self, device: &str, message: String) {
        if let Err(e) = self.0.try_send(DeviceNotice {
            device: device.to_string(),
            message,
        }) {
            let n = match e {
                mpsc::error::TrySendError::Full(n) | mpsc::error::TrySendError::Closed(n) => n,
            };
            tracing::warn!(device = %n.device, message = %n.message, "device notice not recorded: the queue is full or closed");
        }
    }
}
