//! Alarm notification: alarms leave the server by email (SMTP with
//! STARTTLS/TLS), a signed webhook or MQTT (a topic per priority band), to the contact on call, escalating to
//! the next one while unacknowledged, with one summary per flood instead of
//! a mail per alarm.
//!
//! **Owns:** the `[[notify]]` routes at run time: routing by priority,
//! selection and tag (`routing.rs`), the on-call rota and escalation
//! (`routing.rs`, `notifier.rs`), flood limiting and back-off (`flood.rs`),
//! what a message says and its link into the HMI (`message.rs`), the
//! channels (`channels.rs`, MQTT `mqtt.rs`), and the planner and delivery tasks with their
//! events, system alarm and figures (`notifier.rs`).
//!
//! **Must not touch:** SQL (the outbox is the store's `notifications`
//! table, reached through `Store`), the alarm state machine (it reads the
//! engine's transitions and views, and raises only its own `notify:<route>`
//! system alarms), HTTP serving, Modbus.

pub mod channels;
pub mod flood;
pub mod message;
pub mod mqtt;
mod notifier;
pub mod routing;

pub use notifier::{Notifier, NotifyFigures, NotifyHandle, RouteCounters};
