//! The field: every protocol the plant's devices speak, started together,
//! with one writer that routes each tag to its protocol and one set of
//! figures over all of them (the neutral interface is `gridscada-field`).

use std::sync::Arc;

use anyhow::Context;
use gridscada_config::{Plant, Protocol};
use gridscada_field::{DeviceNotice, Router, StatsHandle};
use gridscada_store::NewEvent;
use gridscada_tagdb::{Clock, Leadership, TagDb, TagWriter};
use tokio::sync::mpsc;

pub(crate) struct Field {
    modbus: gridscada_modbus::FieldIo,
    iec104: gridscada_iec104::Iec104Io,
    dnp3: gridscada_dnp3::Dnp3Io,
    iec61850: gridscada_iec61850::client::Iec61850Io,
    writer: Arc<dyn TagWriter>,
    stats: StatsHandle,
}

impl Field {
    /// Starts every protocol's tasks; writes are fenced by `leadership`;
    /// Modbus devices `pipes` serves are reached in process;
    /// the devices' notices (a restart, lost events, a clock set) go to the
    /// event log through `events`.
    pub(crate) fn start(
        plant: &Plant,
        db: Arc<TagDb>,
        clock: Arc<dyn Clock>,
        leadership: Leadership,
        events: mpsc::Sender<NewEvent>,
        pipes: Option<Arc<gridscada_field::Switchboard>>,
    ) -> anyhow::Result<Field> {
        let modbus = gridscada_modbus::FieldIo::start_fenced(
            plant,
            db.clone(),
            clock.clone(),
            leadership.clone(),
            pipes,
        )
        .context("starting Modbus field I/O")?;
        let mut iec104 =
            gridscada_iec104::Iec104Io::start(plant, db.clone(), clock.clone(), leadership.clone())
                .context("starting the IEC 104 client")?;
        let mut dnp3 =
            gridscada_dnp3::Dnp3Io::start(plant, db.clone(), clock.clone(), leadership.clone())
                .context("starting the DNP3 master")?;
        let mut iec61850 = gridscada_iec61850::client::Iec61850Io::start(
            plant,
            db.clone(),
            clock.clone(),
            leadership,
        )
        .context("starting the IEC 61850 client")?;
        for notices in [
            iec104.take_notices(),
            dnp3.take_notices(),
            iec61850.take_notices(),
        ]
        .into_iter()
        .flatten()
        {
            tokio::spawn(record_notices(notices, events.clone(), clock.clone()));
        }
        let writer: Arc<dyn TagWriter> = Arc::new(Router::new(
            db,
            [
                (modbus.writer(), Router::tags_of(plant, |p| p.is_modbus())),
                (
                    iec104.writer(),
                    Router::tags_of(plant, |p| p == Protocol::Iec104),
                ),
                (
                    dnp3.writer(),
                    Router::tags_of(plant, |p| p == Protocol::Dnp3),
                ),
                (
                    iec61850.writer(),
                    Router::tags_of(plant, |p| p == Protocol::Iec61850),
                ),
            ],
        ));
        let stats = StatsHandle::new(vec![
            modbus.stats_source(),
            iec104.stats_source(),
            dnp3.stats_source(),
            iec61850.stats_source(),
        ]);
        Ok(Field {
            modbus,
            iec104,
            dnp3,
            iec61850,
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
        self.iec104.shutdown().await;
        self.dnp3.shutdown().await;
        self.iec61850.shutdown().await;
    }
}

/// A device's notices into the event log, with the device as the source,
/// until the protocol's tasks end.
async fn record_notices(
    mut notices: mpsc::Receiver<DeviceNotice>,
    events: mpsc::Sender<NewEvent>,
    clock: Arc<dyn Clock>,
) {
    while let Some(n) = notices.recv().await {
        let event = crate::sinks::system_event(clock.as_ref(), "device", &n.device, n.message);
        if events.send(event).await.is_err() {
            return;
        }
    }
}
