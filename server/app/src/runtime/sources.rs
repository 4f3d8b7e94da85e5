//! What the web layer reads from the running stack: the devices screen's
//! figures (`StackDevices`, the poller's stats behind `DeviceSource`) and the
//! `/metrics` source (`StackMetrics`).

use std::sync::Arc;

use gridscada_config::Plant;
use gridscada_tagdb::TagDb;

/// The poller's figures per device and link, for the devices screen.
pub(super) struct StackDevices {
    pub(super) plant: Arc<Plant>,
    pub(super) db: Arc<TagDb>,
    pub(super) poll: gridscada_field::StatsHandle,
    /// Per device: when its scans were last counted, the count, and the
    /// rate measured then, so the achieved rate covers the last seconds.
    pub(super) rates:
        std::sync::Mutex<std::collections::HashMap<String, (std::time::Instant, u64, f64)>>,
}

impl StackDevices {
    fn achieved_rate(&self, device: &str, scans: u64) -> f64 {
        let now = std::time::Instant::now();
        let mut rates = self.rates.lock().unwrap_or_else(|p| p.into_inner());
        let entry = rates
            .entry(device.to_string())
            .or_insert((now, scans, f64::NAN));
        let secs = now.duration_since(entry.0).as_secs_f64();
        let rate = scans.saturating_sub(entry.1) as f64 / secs;
        if secs >= 2.0 {
            *entry = (now, scans, rate);
        } else if entry.2.is_nan() && secs >= 0.5 {
            // No full window yet: what the time since the first look shows.
            return rate;
        }
        entry.2
    }
}

impl gridscada_web::api::devices::DeviceSource for StackDevices {
    fn devices(&self) -> gridscada_web::api::devices::DevicesView {
        use gridscada_web::api::devices::{DeviceView, DevicesView, LinkView, TelecontrolView};
        let now_ms = gridscada_tagdb::Timestamp::now_utc().as_millis();
        let poll = self.poll.stats();
        let last_error = |device: &str| {
            self.db
                .id(&format!("{device}.Comm.LastError"))
                .and_then(|id| self.db.get(id))
                .map(|s| match s.value {
                    gridscada_tagdb::Value::Str(e) => e.to_string(),
                    _ => String::new(),
                })
                .unwrap_or_default()
        };
        let protocol = |d: &gridscada_config::DeviceConfig| d.protocol.label().to_string();
        let devices: Vec<DeviceView> = poll
            .devices
            .iter()
            .map(|st| {
                let cfg = self.plant.device(&st.device);
                let scan_ms = self
                    .plant
                    .tags
                    .iter()
                    .filter(|t| t.device.get_ref() == &st.device)
                    .filter_map(|t| cfg.map(|d| t.scan_ms(d)))
                    .min()
                    .or(cfg.map(|d| *d.scan_ms.get_ref()))
                    .unwrap_or_default();
                DeviceView {
                    name: st.device.clone(),
                    description: cfg.map(|d| d.description.clone()).unwrap_or_default(),
                    link: st.link.clone(),
                    protocol: cfg.map(protocol).unwrap_or_default(),
                    address: cfg
                        .map(|d| match (&d.address, &d.serial) {
                            (Some(a), _) => a.get_ref().clone(),
                            (None, Some(s)) => s.port.get_ref().clone(),
                            (None, None) => String::new(),
                        })
                        .unwrap_or_default(),
                    unit_id: cfg.map(|d| *d.unit_id.get_ref()).unwrap_or_default(),
                    scan_ms,
                    achieved_scans_per_s: self.achieved_rate(&st.device, st.scans),
                    response_ms: st.last_response_ms,
                    requests: st.requests,
                    errors: st.errors,
                    timeouts: st.timeouts,
                    exceptions: st.exceptions,
                    writes: st.writes,
                    late_scans: st.late_scans,
                    overruns: st.overruns,
                    connected: st.connected,
                    backing_off: !st.connected && st.requests > 0,
                    last_error: last_error(&st.device),
                    telecontrol: cfg
                        .filter(|d| !d.protocol.is_modbus())
                        .map(|_| TelecontrolView {
                            state: st.state.clone(),
                            events: st.events,
                            interrogations: st.interrogations,
                            interrogation_age_s: st
                                .last_interrogation_ms
                                .map(|at| (now_ms - at).max(0) as f64 / 1000.0),
                            commands: st.writes,
                            commands_failed: st.writes_failed,
                            clock_offset_ms: st.clock_offset_ms,
                            overflows: st.overflows,
                        }),
                }
            })
            .collect();
        let links = poll
            .links
            .iter()
            .map(|l| {
                let on: Vec<&DeviceView> = devices.iter().filter(|d| d.link == l.link).collect();
                LinkView {
                    link: l.link.clone(),
                    protocol: on.first().map(|d| d.protocol.clone()).unwrap_or_default(),
                    devices: on.iter().map(|d| d.name.clone()).collect(),
                    connected: on.iter().all(|d| d.connected),
                    connects: l.connects,
                    disconnects: l.disconnects,
                    late_replies: l.late_replies,
                    garbage_bytes: l.garbage_bytes,
                    last_error: l.last_error.clone(),
                }
            })
            .collect();
        // The rate is NaN until two readings are 2 s apart; JSON has no NaN.
        let devices = devices
            .into_iter()
            .map(|mut d| {
                if !d.achieved_scans_per_s.is_finite() {
                    d.achieved_scans_per_s = 0.0;
                }
                d
            })
            .collect();
        DevicesView { devices, links }
    }
}

/// The poller's, the historian's and the audit trail's figures for `/metrics`.
pub(super) struct StackMetrics {
    pub(super) poll: gridscada_field::StatsHandle,
    pub(super) historian: gridscada_store::HistorianHandle,
    pub(super) audit: gridscada_store::AuditHandle,
    /// A redundant pair's role, epoch and health.
    pub(super) pair: Option<crate::pair::PairHandle>,
    /// The central Sparkplug host's figures, if one runs.
    pub(super) sparkplug_host: Option<super::sparkplug_host::HostStatsSource>,
    /// The Sparkplug B edge node's figures, when it runs.
    pub(super) mqtt: Option<Arc<gridscada_sparkplug::edge::EdgeMetrics>>,
    pub(super) notify: Option<gridscada_notify::NotifyHandle>,
    /// The IEC 104 server's figures (counted from the stack's start).
    pub(super) iec104_server: Arc<gridscada_iec104::ServerCounters>,
}

impl StackMetrics {
    /// The IEC 104 stations (one per device), the DNP3 outstations and the
    /// IEC 104 server.
    fn render_telecontrol(
        &self,
        out: &mut gridscada_web::metrics::Prom,
        poll: &gridscada_field::PollStats,
    ) {
        let now_ms = gridscada_tagdb::Timestamp::now_utc().as_millis();
        // DNP3 outstations: connected or disconnected.
        for d in poll
            .devices
            .iter()
            .filter(|d| matches!(d.state.as_str(), "connected" | "disconnected"))
        {
            let l = [("device", d.device.as_str())];
            for (name, help, v) in [
                (
                    "gridscada_dnp3_requests_total",
                    "Link frames sent to the outstation (requests and confirmations).",
                    d.requests,
                ),
                (
                    "gridscada_dnp3_events_total",
                    "Event objects received (polled or unsolicited).",
                    d.events,
                ),
                ("gridscada_dnp3_commands_total", "Commands sent.", d.writes),
                (
                    "gridscada_dnp3_integrity_polls_total",
                    "Integrity polls completed.",
                    d.interrogations,
                ),
                (
                    "gridscada_dnp3_commands_failed_total",
                    "Commands refused by the outstation (status named) or not answered.",
                    d.writes_failed,
                ),
                (
                    "gridscada_dnp3_overflows_total",
                    "Event buffer overflows the outstation reported (IIN2.3).",
                    d.overflows,
                ),
                (
                    "gridscada_dnp3_timeouts_total",
                    "Requests without a response within the response timeout.",
                    d.timeouts,
                ),
            ] {
                out.counter(name, help, &l, v as f64);
            }
            if let Some(at) = d.last_interrogation_ms {
                out.gauge(
                    "gridscada_dnp3_integrity_poll_age_seconds",
                    "Time since the last integrity poll completed.",
                    &l,
                    (now_ms - at).max(0) as f64 / 1000.0,
                );
            }
        }
        for d in poll
            .devices
            .iter()
            .filter(|d| matches!(d.state.as_str(), "started" | "tested" | "stopped"))
        {
            let l = [("device", d.device.as_str())];
            for state in ["started", "tested", "stopped"] {
                out.gauge(
                    "gridscada_iec104_station_state",
                    "1 for the station's connection state: started (data transfer), tested (standby), stopped.",
                    &[("device", d.device.as_str()), ("state", state)],
                    f64::from(u8::from(d.state == state)),
                );
            }
            for (name, help, v) in [
                (
                    "gridscada_iec104_frames_sent_total",
                    "I-frames sent to the station.",
                    d.requests,
                ),
                (
                    "gridscada_iec104_events_total",
                    "Spontaneous data received (objects).",
                    d.events,
                ),
                (
                    "gridscada_iec104_interrogations_total",
                    "General interrogations completed.",
                    d.interrogations,
                ),
                (
                    "gridscada_iec104_commands_total",
                    "Commands sent.",
                    d.writes,
                ),
                (
                    "gridscada_iec104_commands_failed_total",
                    "Commands refused by the station or not confirmed.",
                    d.writes_failed,
                ),
                (
                    "gridscada_iec104_overflows_total",
                    "Events the station reported lost.",
                    d.overflows,
                ),
                (
                    "gridscada_iec104_timeouts_total",
                    "Connections closed by t1 expiry.",
                    d.timeouts,
                ),
            ] {
                out.counter(name, help, &l, v as f64);
            }
            if let Some(at) = d.last_interrogation_ms {
                out.gauge(
                    "gridscada_iec104_interrogation_age_seconds",
                    "Time since the last general interrogation completed.",
                    &l,
                    (now_ms - at).max(0) as f64 / 1000.0,
                );
            }
            if let Some(offset) = d.clock_offset_ms {
                out.gauge(
                    "gridscada_iec104_clock_offset_seconds",
                    "The station's clock minus the server's at the last clock synchronisation.",
                    &l,
                    offset / 1000.0,
                );
            }
        }
        let c = &self.iec104_server;
        for (name, help, v) in [
            (
                "gridscada_iec104_server_connections_total",
                "Control centre connections accepted.",
                &c.connections,
            ),
            (
                "gridscada_iec104_server_refused_connections_total",
                "Connections refused: not in allowed_clients, or max_connections reached.",
                &c.refused_connections,
            ),
            (
                "gridscada_iec104_server_interrogations_total",
                "General interrogations answered.",
                &c.interrogations,
            ),
            (
                "gridscada_iec104_server_spontaneous_total",
                "Spontaneous objects sent.",
                &c.spontaneous,
            ),
            (
                "gridscada_iec104_server_commands_total",
                "Commands executed for the control centre.",
                &c.commands,
            ),
            (
                "gridscada_iec104_server_commands_refused_total",
                "Commands refused (not the point's, not selected, outside the limits).",
                &c.commands_refused,
            ),
            (
                "gridscada_iec104_server_commands_failed_total",
                "Commands the device did not take or confirm.",
                &c.commands_failed,
            ),
            (
                "gridscada_iec104_server_malformed_total",
                "Connections closed for a malformed frame or ASDU.",
                &c.malformed,
            ),
        ] {
            out.counter(
                name,
                help,
                &[],
                v.load(std::sync::atomic::Ordering::Relaxed) as f64,
            );
        }
    }

    /// The audit trail: records stored, spooled while the store was away,
    /// replayed from the spool, waiting in it, and lost.
    fn render_audit(&self, out: &mut gridscada_web::metrics::Prom) {
        let a = self.audit.metrics();
        for (name, help, value) in [
            (
                "gridscada_audit_stored_total",
                "Audit records (events, alarm transitions) stored straight away.",
                a.stored,
            ),
            (
                "gridscada_audit_spooled_total",
                "Audit records spooled while the store could not take them.",
                a.spooled,
            ),
            (
                "gridscada_audit_replayed_total",
                "Audit records replayed from the spool into the store.",
                a.replayed,
            ),
            (
                "gridscada_audit_lost_total",
                "Audit records neither stored nor spooled.",
                a.lost,
            ),
            (
                "gridscada_audit_spool_bad_lines_total",
                "Torn or unreadable audit spool lines found.",
                a.torn_lines,
            ),
        ] {
            out.counter(name, help, &[], value as f64);
        }
        out.gauge(
            "gridscada_audit_spool_pending",
            "Audit records in the spool, waiting for the store.",
            &[],
            a.pending as f64,
        );
        out.gauge(
            "gridscada_audit_spooling",
            "1 while the audit spool is in use.",
            &[],
            f64::from(u8::from(a.spooling)),
        );
    }
}

impl StackMetrics {
    /// The MQTT edge node: messages and bytes each way, sessions, the
    /// store-and-forward buffer, commands.
    fn render_mqtt(&self, out: &mut gridscada_web::metrics::Prom) {
        use gridscada_sparkplug::edge::EdgeMetrics as M;
        let Some(m) = &self.mqtt else { return };
        for (name, help, labels, value) in [
            (
                "gridscada_mqtt_messages_total",
                "MQTT messages published (out) and received (in).",
                [("direction", "out")],
                &m.messages_sent,
            ),
            (
                "gridscada_mqtt_messages_total",
                "MQTT messages published (out) and received (in).",
                [("direction", "in")],
                &m.messages_received,
            ),
            (
                "gridscada_mqtt_bytes_total",
                "MQTT payload bytes published (out) and received (in).",
                [("direction", "out")],
                &m.bytes_sent,
            ),
            (
                "gridscada_mqtt_bytes_total",
                "MQTT payload bytes published (out) and received (in).",
                [("direction", "in")],
                &m.bytes_received,
            ),
            (
                "gridscada_mqtt_commands_total",
                "Sparkplug DCMD writes, by outcome.",
                [("outcome", "written")],
                &m.commands_written,
            ),
            (
                "gridscada_mqtt_commands_total",
                "Sparkplug DCMD writes, by outcome.",
                [("outcome", "failed")],
                &m.commands_failed,
            ),
            (
                "gridscada_mqtt_commands_total",
                "Sparkplug DCMD writes, by outcome.",
                [("outcome", "refused")],
                &m.commands_refused,
            ),
        ] {
            out.counter(name, help, &labels, M::get(value) as f64);
        }
        for (name, help, value) in [
            ("gridscada_mqtt_reconnects_total", "MQTT sessions after the first (each one a rebirth).", &m.reconnects),
            ("gridscada_mqtt_replayed_samples_total", "Buffered samples sent as historical data after an outage.", &m.replayed),
            ("gridscada_mqtt_dropped_samples_total", "Samples lost: the buffer was full, or their device had no birth on replay.", &m.dropped),
            ("gridscada_mqtt_malformed_messages_total", "Received messages refused: oversized, not Sparkplug B, or not a command of this node.", &m.malformed),
        ] {
            out.counter(name, help, &[], M::get(value) as f64);
        }
        out.gauge(
            "gridscada_mqtt_connected",
            "1 while the edge node has a broker session.",
            &[],
            M::get(&m.connected) as f64,
        );
        out.gauge(
            "gridscada_mqtt_primary_host_online",
            "With primary_host_id: 1 while the primary host's STATE is online and the edge publishes.",
            &[],
            M::get(&m.primary_host_online) as f64,
        );
        out.gauge(
            "gridscada_mqtt_buffered_samples",
            "Samples in the store-and-forward buffer, waiting for the broker.",
            &[],
            M::get(&m.buffered) as f64,
        );
    }

    /// Alarm notification, per route: sent, failed attempts, given up,
    /// held by the flood limit, failing now; and the outbox's backlog.
    fn render_notify(&self, out: &mut gridscada_web::metrics::Prom) {
        use std::sync::atomic::Ordering::Relaxed;
        let Some(n) = &self.notify else {
            return;
        };
        let f = &n.figures;
        let failing = f.failing.lock().clone();
        for (route, c) in &f.routes {
            let l = [("route", route.as_str())];
            for (name, help, v) in [
                (
                    "gridscada_notifications_sent_total",
                    "Alarm notifications delivered.",
                    &c.sent,
                ),
                (
                    "gridscada_notifications_failed_attempts_total",
                    "Alarm notification delivery attempts that failed (retried with back-off).",
                    &c.failed_attempts,
                ),
                (
                    "gridscada_notifications_given_up_total",
                    "Alarm notifications given up after retrying.",
                    &c.given_up,
                ),
                (
                    "gridscada_notifications_held_total",
                    "Alarm notifications held by the flood limit and told in a summary.",
                    &c.held,
                ),
            ] {
                out.counter(name, help, &l, v.load(Relaxed) as f64);
            }
            out.gauge(
                "gridscada_notifications_failing",
                "1 while the route cannot deliver (its system alarm stands).",
                &l,
                f64::from(u8::from(failing.get(route).copied().unwrap_or(false))),
            );
        }
        out.gauge(
            "gridscada_notifications_pending",
            "Alarm notifications waiting in the outbox.",
            &[],
            f.pending.load(Relaxed) as f64,
        );
    }
}

impl gridscada_web::metrics::MetricsSource for StackMetrics {
    fn render(&self, out: &mut gridscada_web::metrics::Prom) {
        self.render_audit(out);
        if let Some(p) = &self.pair {
            crate::pair::render_metrics(p, out);
        }
        if let Some(host) = &self.sparkplug_host {
            super::sparkplug_host::render(&host(), out);
        }
        self.render_mqtt(out);
        self.render_notify(out);
        let poll = self.poll.stats();
        self.render_telecontrol(out, &poll);
        for d in &poll.devices {
            let l = [("device", d.device.as_str())];
            out.gauge(
                "gridscada_device_connected",
                "1 while the device answers.",
                &l,
                f64::from(u8::from(d.connected)),
            );
            // The rest are Modbus figures; a telecontrol station has its own.
            if !d.state.is_empty() {
                continue;
            }
            out.counter(
                "gridscada_poll_requests_total",
                "Modbus requests sent.",
                &l,
                d.requests as f64,
            );
            out.counter(
                "gridscada_poll_errors_total",
                "Modbus requests without a good answer.",
                &l,
                d.errors as f64,
            );
            out.counter(
                "gridscada_poll_timeouts_total",
                "Modbus requests that timed out.",
                &l,
                d.timeouts as f64,
            );
            out.counter(
                "gridscada_poll_exceptions_total",
                "Modbus exception responses.",
                &l,
                d.exceptions as f64,
            );
            out.counter(
                "gridscada_poll_writes_total",
                "Confirmed writes.",
                &l,
                d.writes as f64,
            );
            out.counter(
                "gridscada_poll_scans_total",
                "Scans completed.",
                &l,
                d.scans as f64,
            );
            out.counter(
                "gridscada_poll_late_scans_total",
                "Scans started late.",
                &l,
                d.late_scans as f64,
            );
            out.counter(
                "gridscada_poll_overruns_total",
                "Scan periods skipped by overruns.",
                &l,
                d.overruns as f64,
            );
            out.gauge(
                "gridscada_poll_response_seconds",
                "Round trip of the last answered request.",
                &l,
                d.last_response_ms / 1000.0,
            );
            let buckets: Vec<(f64, u64)> = d.round_trip.buckets().collect();
            out.histogram(
                "gridscada_poll_round_trip_seconds",
                "Round trips of answered Modbus requests (timeouts excluded).",
                &l,
                &gridscada_web::metrics::HistogramSample {
                    buckets: &buckets,
                    sum: d.round_trip.sum_s,
                },
            );
        }
        for k in &poll.links {
            let l = [("link", k.link.as_str())];
            out.counter(
                "gridscada_link_connects_total",
                "Connections made.",
                &l,
                k.connects as f64,
            );
            out.counter(
                "gridscada_link_late_replies_total",
                "Late or stray replies discarded.",
                &l,
                k.late_replies as f64,
            );
            out.counter(
                "gridscada_link_garbage_bytes_total",
                "Bytes discarded as garbage.",
                &l,
                k.garbage_bytes as f64,
            );
        }
        let h = self.historian.metrics();
        out.gauge(
            "gridscada_historian_buffered",
            "Samples waiting to be written.",
            &[],
            h.buffered as f64,
        );
        out.gauge(
            "gridscada_historian_capacity",
            "Size of the historian buffer.",
            &[],
            h.capacity as f64,
        );
        out.counter(
            "gridscada_historian_dropped_total",
            "Samples dropped because the buffer was full.",
            &[],
            h.dropped as f64,
        );
        out.counter(
            "gridscada_historian_samples_written_total",
            "Samples written.",
            &[],
            h.samples_written as f64,
        );
        out.counter(
            "gridscada_historian_batches_written_total",
            "Batches written.",
            &[],
            h.batches_written as f64,
        );
        out.counter(
            "gridscada_historian_write_errors_total",
            "Failed batch writes (each retried).",
            &[],
            h.write_errors as f64,
        );
        out.gauge(
            "gridscada_historian_last_write_seconds",
            "Duration of the last batch write.",
            &[],
            h.last_write_ms / 1000.0,
        );
    }

    fn health(&self) -> gridscada_web::metrics::StackHealth {
        use gridscada_web::metrics::{FieldIoHealth, HistorianHealth, StackHealth};
        let poll = self.poll.stats();
        let h = self.historian.metrics();
        StackHealth {
            field_io: Some(FieldIoHealth {
                total: poll.devices.len(),
                not_good: poll
                    .devices
                    .iter()
                    .filter(|d| !d.connected)
                    .map(|d| d.device.clone())
                    .collect(),
            }),
            historian: Some(HistorianHealth {
                queued: h.buffered as u64,
                capacity: h.capacity as u64,
                dropped: h.dropped,
                overflow: h.overflow,
            }),
        }
    }
}
