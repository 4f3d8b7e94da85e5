//! The field: every protocol the plant's devices speak, started together,
//! with one writer that routes each tag to its protocol and one set of
//! figures over all of them (the neutral interface is `gridscada-field`).

use std::sync::Arc;

use anyhow::Context;
use gridscada_config::Plant;
use gridscada_field::{Router, StatsHandle};
use gridscada_tagdb::{Clock, Leadership, TagDb, TagWriter};

pub(crate) struct Field {
    modbus: gridscada_modbus::FieldIo,
    writer: Arc<dyn TagWriter>,
    stats: StatsHandle,
}

impl Field {
    /// Starts every protocol's tasks; writes are fenced by `leadership`.
    pub(crate) fn start(
        plant: &Plant,
        db: Arc<TagDb>,
        clock: Arc<dyn Clock>,
        leadership: Leadership,
    ) -> anyhow::Result<Field> {
        let modbus =
            gridscada_modbus::FieldIo::start_fenced(plant, db, clock, leadership)
                .context("starting Modbus field I/O")?;
        let writer: Arc<dyn TagWriter> = Arc::new(Router::new([(
            modbus.writer(),
            Router::tags_of(plant, |p| p.is_modbus()),
        )]));
        let stats = StatsHandle::new(vec![modbus.stats_source()]);
        Ok(Field {
            modbus,
            writer,
            stats,
        })
    }

    /// The command path into the field, for control loops, the web API and
    /// northbound.
    pub(crate) fn writer(&self) -> Arc<dyn TagWriter> {
        Arc::clone(&self.writer)
    }

    /// Every protocol's figures (requests, timeouts, operations in flight).
    pub(crate) fn stats_handle(&self) -> StatsHandle {
        self.stats.clone()
    }

    /// Stops every protocol's tasks and waits for them.
    pub(crate) async fn shutdown(self) {
        self.modbus.shutdown().await;
    }
}
