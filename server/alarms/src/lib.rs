//! # gridscada-alarms: alarms and events (ISA-18.2 / IEC 62682)
//!
//! **Owns:** the alarm state model ([`machine`]: Normal, Unack-Active,
//! Ack-Active, Unack-RTN, Shelved, Suppressed-by-design, Out-of-service), the
//! plant's alarms as one pure state machine ([`AlarmSet`]: limit alarms with
//! deadband and on/off delays, discrete alarms, communication-failure alarms,
//! system alarms, suppression rules, acknowledge/shelve operations), the thin
//! async [`AlarmEngine`] over the tag database, the ISA-18.2 performance
//! [`metrics`], and the event log model ([`events`]).
//!
//! **Must not touch:** storage, HTTP, Modbus. History, events and state records
//! leave on channels the application wires to the store; persisted states come
//! back in as a list at start-up.

pub mod engine;
pub mod events;
pub mod machine;
pub mod metrics;
pub mod model;
pub mod set;
pub mod suppression;

pub use engine::{AlarmChannels, AlarmEngine, AlarmListUpdate, EngineOptions, EngineStats};
pub use events::{Event, EventType, UnknownEventType};
pub use machine::{Alarm, AlarmDef, Condition};
pub use metrics::{
    compute as compute_metrics, Activation, AlarmMetrics, MetricTargets, MetricsOptions,
};
pub use model::{comm_key, discrete_key, limit_key};
pub use model::{
    AlarmError, AlarmFilter, AlarmId, AlarmKind, AlarmState, AlarmStateRecord, AlarmTransition,
    AlarmView, ServiceInfo, ShelveInfo, TransitionCause,
};
pub use set::{
    plant_defs, tag_alarm_defs, AlarmSet, AlarmSource, InputId, Outputs, RestoreReport, MAX_SHELVE,
};
pub use suppression::{default_rules, plant_rules, AlarmMatch, SuppressionRule};
