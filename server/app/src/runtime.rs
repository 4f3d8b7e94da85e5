//! Wiring: opens the store, builds the tag database, starts the simulators
//! (demo), the field I/O, the control loops and the HTTP server, and stops
//! them in reverse order on Ctrl-C. What the web layer reads from the
//! running stack (the devices screen, `/metrics`) is in `runtime/sources.rs`.

use std::future::Future;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{anyhow, Context};
use gridscada_config::Plant;
use gridscada_control::dispatch::{self, DispatchStatus};
use gridscada_control::fault_isolation::{self, PanelNotice, PanelStatus};
use gridscada_store::{NewEvent, Store};
use gridscada_tagdb::{Clock, SystemClock, TagDb, TagMeta};
use gridscada_web::api::panels::PanelHandle;
use tokio::sync::{mpsc, watch};
use tokio::task::JoinSet;

use crate::data::open_store;
use crate::settings::diagnostics;
use crate::{demo_plant, settings, sinks, users};

#[cfg(test)]
mod audit_tests;
mod field;
mod memory;
pub mod northbound;
pub(crate) mod opcua;
#[cfg(test)]
mod shutdown_tests;
mod sources;
mod sparkplug_host;
mod training;

use sources::{StackDevices, StackMetrics};

pub fn block_on(fut: impl Future<Output = ExitCode>) -> ExitCode {
    match tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
    {
        Ok(rt) => rt.block_on(fut),
        Err(e) => {
            eprintln!("error: cannot start the async runtime: {e}");
            ExitCode::FAILURE
        }
    }
}

pub fn report(result: anyhow::Result<()>) -> ExitCode {
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// How the server runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Mode {
    /// Embedded plant, simulators on loopback, generated credentials.
    Demo,
    /// A real plant.
    Serve,
}

impl Mode {
    fn label(self) -> &'static str {
        match self {
            Mode::Demo => "demo",
            Mode::Serve => "serve",
        }
    }
}

/// Something that drives a running demo: a scenario replayed live. It gives
/// the plant and the clock the stack starts with, then starts once the stack
/// runs. (Defined here and implemented by `replay`, so the wiring does not
/// depend on the replay runner, which depends on the wiring.)
pub trait LiveDriver: Send {
    fn plant(&self) -> &Plant;
    fn clock(&self) -> Arc<dyn Clock>;
    fn start(self: Box<Self>, stack: &Stack);
}

/// `gridscada demo`: the embedded plant, on loopback; with a scenario, the
/// scenario's plant driven by its timeline on a compressed clock.
#[allow(clippy::too_many_arguments)]
pub async fn demo(
    http: String,
    data: PathBuf,
    config: Option<PathBuf>,
    scenario: Option<Box<dyn LiveDriver>>,
    mqtt: Option<northbound::DemoMqtt>,
    opcua_port: Option<u16>,
    real_devices: Vec<String>,
) -> ExitCode {
    report(
        async {
            let mut plant = match (&scenario, &config) {
                (Some(live), _) => live.plant().clone(),
                (None, Some(c)) => gridscada_config::load_path(c)
                    .map_err(|d| diagnostics("the configuration", d))?,
                (None, None) => {
                    demo_plant::load().map_err(|d| diagnostics("the embedded demo plant", d))?
                }
            };
            let addr = settings::listen_addr(&http, "--http")?;
            if !addr.ip().is_loopback() {
                return Err(anyhow!(
                    "the demo prints its passwords and serves a simulated plant, so it only binds loopback addresses; --http {addr} is not one"
                ));
            }
            if let Some(m) = &mqtt {
                northbound::enable_demo(&mut plant, m)?;
            }
            // The demo serves OPC UA only when asked (`--opcua PORT`).
            plant.opcua = opcua_port.map(opcua::demo_config);
            for name in &real_devices {
                if !plant.devices.iter().any(|d| d.name.get_ref() == name) {
                    let known: Vec<&str> =
                        plant.devices.iter().map(|d| d.name.get_ref().as_str()).collect();
                    return Err(anyhow!(
                        "--real-device {name}: the plant has no such device (it has: {})",
                        known.join(", ")
                    ));
                }
            }
            run(plant, addr, &data, Mode::Demo, scenario, real_devices).await
        }
        .await,
    )
}

/// `gridscada serve`: a real plant configuration, with the `GRIDSCADA_*`
/// environment and the `--http`/`--data` flags over it. Refuses to start on
/// any configuration problem.
pub async fn serve(config: PathBuf, http: Option<String>, data: Option<PathBuf>) -> ExitCode {
    report(
        async {
            let mut plant = settings::load_for_server(&config)?;
            settings::apply_flags(&mut plant, http, data)?;
            let addr = settings::listen_addr(plant.server.http.get_ref(), "[server] http")?;
            let data = plant.data_dir.clone();
            run(plant, addr, &data, Mode::Serve, None, Vec::new()).await
        }
        .await,
    )
}

/// `gridscada sim`: the simulated plant alone on its configured addresses.
pub async fn sim(config: Option<PathBuf>) -> ExitCode {
    report(
        async {
            let plant = match config {
                Some(c) => gridscada_config::load_path(&c)
                    .map_err(|d| diagnostics("the configuration", d))?,
                None => {
                    demo_plant::load().map_err(|d| diagnostics("the embedded demo plant", d))?
                }
            };
            gridscada_sim::run_standalone(&plant)
                .await
                .context("running the simulated plant")
        }
        .await,
    )
}

/// Checks the plant's `screens/*.json` against its tags (derived ones
/// included) and panels, without starting anything; every problem names its
/// file, and the element and field.
pub fn check_screens(plant: &Plant) -> Vec<String> {
    struct View<'a> {
        plant: &'a Plant,
        tags: std::collections::HashMap<String, gridscada_tagdb::ValueKind>,
    }
    impl gridscada_config::screen::PlantView for View<'_> {
        fn tag(&self, name: &str) -> Option<(gridscada_tagdb::ValueKind, bool)> {
            let kind = *self.tags.get(name)?;
            let writable = self
                .plant
                .tag(name)
                .is_some_and(|t| *t.writable.get_ref() && t.write_role.is_some());
            Some((kind, writable))
        }
        fn has_panel(&self, id: &str) -> bool {
            self.plant.panels.iter().any(|p| p.id.get_ref() == id)
        }
    }
    let view = View {
        plant,
        tags: all_tags(plant)
            .into_iter()
            .map(|m| (m.name.to_string(), m.kind))
            .collect(),
    };
    let dir = gridscada_config::screen::folder_of(&plant.main_path);
    let (files, mut problems) = gridscada_config::screen::read_folder(&dir);
    for (path, screen) in files {
        problems.extend(
            screen
                .validate(&view)
                .into_iter()
                .map(|e| format!("{}: {e}", path.display())),
        );
    }
    problems
}

/// Every tag the database holds: the plant's, plus the derived ones.
pub(crate) fn all_tags(plant: &Plant) -> Vec<TagMeta> {
    let mut tags: Vec<TagMeta> = plant.tag_metas().collect();
    tags.extend(gridscada_field::device_status_tags(plant));
    for panel in &plant.panels {
        tags.extend(fault_isolation::panel_tags(panel));
    }
    if plant.microgrid.is_some() {
        tags.extend(dispatch::tags::dispatch_tags());
    }
    if let Some(Ok(net)) = gridscada_network::Network::from_plant(plant) {
        tags.extend(gridscada_network::network_tags(&net));
    }
    tags
}

/// The simulator's fault injection, as the web layer reaches it.
struct SimAdapter(gridscada_sim::SimHandle);

impl gridscada_web::api::sim::SimControl for SimAdapter {
    fn inject_fault(
        &self,
        panel: &str,
        zone: u8,
        kind: gridscada_web::api::sim::FaultKind,
    ) -> Result<(), String> {
        let kind = match kind {
            gridscada_web::api::sim::FaultKind::Permanent => gridscada_sim::FaultKind::Permanent,
            gridscada_web::api::sim::FaultKind::Transient => gridscada_sim::FaultKind::Transient,
        };
        self.0
            .inject_zone_fault(panel, zone, kind)
            .map_err(|e| e.to_string())
    }
    fn repair(&self, panel: &str, zone: u8) -> Result<(), String> {
        self.0.repair_zone(panel, zone).map_err(|e| e.to_string())
    }
    fn set_offline(&self, device: &str, offline: bool) -> Result<(), String> {
        self.0
            .set_device_offline(device, offline)
            .map_err(|e| e.to_string())
    }
    fn inject_timed_fault(
        &self,
        panel: &str,
        zone: u8,
        clears_after: std::time::Duration,
    ) -> Result<(), String> {
        training::inject_timed_fault(&self.0, panel, zone, clears_after)
    }
    fn set_link(
        &self,
        device: &str,
        link: &gridscada_web::api::sim::LinkFaults,
    ) -> Result<(), String> {
        training::set_link(&self.0, device, link)
    }
    fn set_input(
        &self,
        input: gridscada_web::api::sim::PlantInput,
        profile: &gridscada_web::api::sim::InputProfile,
    ) -> Result<(), String> {
        training::set_input(&self.0, input, profile)
    }
    fn set_zone_load(&self, panel: &str, zone: u8, kw: f64, pf: f64) -> Result<(), String> {
        training::set_zone_load(&self.0, panel, zone, kw, pf)
    }
    fn state(&self) -> gridscada_web::api::sim::SimState {
        training::state(&self.0)
    }
}

/// Everything that runs for a plant, started in dependency order: store,
/// simulators (optional), tag database, alarm engine, historian, field I/O,
/// fault-isolation sequences and the microgrid outer loop. `demo`, `serve`
/// and scenario replay all run this same stack.
pub struct Stack {
    pub plant: Arc<Plant>,
    pub clock: Arc<dyn Clock>,
    pub store: Store,
    pub db: Arc<TagDb>,
    pub alarms: Arc<gridscada_alarms::AlarmEngine>,
    pub writer: Arc<dyn gridscada_tagdb::TagWriter>,
    pub panels: Vec<PanelHandle>,
    pub dispatch: Option<watch::Receiver<DispatchStatus>>,
    /// The switching network (`[network]`) and its live topology.
    pub network: Option<gridscada_web::NetworkView>,
    pub simulator: Option<gridscada_sim::Simulator>,
    pub events: mpsc::Sender<NewEvent>,
    /// This server's part in a redundant pair (`[redundancy]`), if any.
    pub pair: Option<crate::pair::PairHandle>,
    /// The lease keeper's stop signal and task: stopped first, so the
    /// standby takes over at once.
    pair_keeper: Option<(watch::Sender<bool>, tokio::task::JoinHandle<()>)>,
    /// The MQTT Sparkplug B edge node (`[mqtt.edge]`), once started.
    pub mqtt_edge: Option<gridscada_sparkplug::edge::EdgeNode>,
    /// The alarm notifier's figures, if `[[notify]]` routes run.
    pub notify: Option<gridscada_notify::NotifyHandle>,
    /// The IEC 104 server's figures (`[iec104_server]`), zero without one.
    pub(crate) iec104_server_counters: Arc<gridscada_iec104::ServerCounters>,
    field: field::Field,
    /// The central Sparkplug B host (`[mqtt.host]`), if configured.
    sparkplug_host: Option<gridscada_sparkplug::host::Host>,
    historian: gridscada_store::Historian,
    /// Events and alarm transitions on their way to the store (or spool).
    audit: gridscada_store::AuditTrail,
    /// The task feeding tag changes to the historian, and its stop signal.
    historian_feed: (watch::Sender<bool>, tokio::task::JoinHandle<()>),
    /// The control loops (panel sequences, dispatch): producers of tag
    /// changes, stopped before the historian feed.
    loops: JoinSet<()>,
    /// The sinks, stopped last.
    tasks: JoinSet<()>,
}

/// How to start a [`Stack`].
pub struct StackOptions {
    pub clock: Arc<dyn Clock>,
    /// Start the simulated plant on ephemeral loopback ports and poll it.
    pub simulate: bool,
    /// With `simulate`: devices left out of the simulation, reached on
    /// their configured addresses (a real RTU beside simulated panels).
    pub real_devices: Vec<String>,
    /// With `simulate`: the poller reaches the simulated Modbus devices over
    /// in-process pipes instead of loopback TCP, with the same frames
    /// (replay: nothing outside the process needs them, and the kernel's
    /// loopback was a third of its time).
    pub simulator_pipes: bool,
    /// How the microgrid's outer loop makes setpoints (replay's rule-based
    /// baseline forces the rule).
    pub dispatch_policy: dispatch::DispatchPolicy,
    /// Take over each panel sequence's saved state (mode, faulty zones,
    /// lockout) from the store. Off for replay: a scenario starts from its
    /// own initial state, whatever an earlier run left in the data folder.
    pub restore_panels: bool,
    /// The data folder in use: the audit spool lives in it.
    pub data_dir: PathBuf,
    /// Send alarm notifications (`[[notify]]`); off for replay, whose
    /// alarms are not the plant's.
    pub notify: bool,
}

impl Stack {
    pub async fn start(
        mut plant: Plant,
        store: Store,
        opts: StackOptions,
    ) -> anyhow::Result<Stack> {
        let clock = opts.clock;
        let mut tasks = JoinSet::new();

        // One of a redundant pair: the lease on the shared PostgreSQL
        // database decides whether this server commands (`pair.rs`).
        let site = plant.server.site().to_string();
        let (leadership, lease) = match &plant.redundancy {
            Some(r) => {
                let name = r.name.get_ref();
                let lease = store.lease(&site, name).with_context(|| {
                    format!("[redundancy]: server '{name}' cannot keep a lease in this store")
                })?;
                (gridscada_tagdb::Leadership::standby(name), Some(lease))
            }
            None => (gridscada_tagdb::Leadership::sole(), None),
        };

        // Events and alarm transitions go through the audit trail into the
        // store, or into its spool while the store is away (replaying a
        // spool an earlier run left first).
        let audit = gridscada_store::AuditTrail::start(
            store.clone(),
            gridscada_store::AuditConfig::new(&opts.data_dir),
        )
        .await
        .context("starting the audit trail (its spool is in the data folder)")?;
        tasks.spawn(sinks::audit_retention(
            store.clone(),
            plant.storage.retention.clone(),
            clock.clone(),
        ));
        // Events from every part go through one sink into the audit trail.
        let (events_tx, events_rx) = mpsc::channel::<NewEvent>(4096);
        tasks.spawn(sinks::events(audit.handle(), events_rx));

        // Simulators first, so the poller finds its devices.
        let pipes = (opts.simulate && opts.simulator_pipes)
            .then(|| Arc::new(gridscada_field::Switchboard::new()));
        let simulator = if opts.simulate {
            let mut simulated = plant.clone();
            simulated
                .devices
                .retain(|d| !opts.real_devices.contains(d.name.get_ref()));
            simulated
                .tags
                .retain(|t| !opts.real_devices.contains(t.device.get_ref()));
            let bind = match &pipes {
                Some(board) => gridscada_sim::BindMode::InProcess(board.clone()),
                None => gridscada_sim::BindMode::Ephemeral,
            };
            let sim = gridscada_sim::start(&simulated, clock.clone(), bind)
                .await
                .context("starting the simulated plant")?;
            sim.patch_plant(&mut plant);
            Some(sim)
        } else {
            None
        };
        let plant = Arc::new(plant);

        // With room for the remote tags of a central Sparkplug host.
        let db = Arc::new(
            TagDb::with_room(all_tags(&plant), sparkplug_host::room(&plant))
                .context("building the tag database")?,
        );
        tracing::info!(
            tags = db.len(),
            devices = plant.devices.len(),
            "tag database ready"
        );
        // The alarm engine, restored from the store.
        let restore = store.alarm_states().await.context("loading alarm states")?;
        let (transitions_tx, transitions_rx) = mpsc::channel(4096);
        let (alarm_events_tx, alarm_events_rx) = mpsc::channel(1024);
        let (states_tx, states_rx) = mpsc::channel(4096);
        // On a standby the engine runs warm; the active server records.
        let transitions_rx = crate::pair::gate(transitions_rx, &leadership);
        let alarm_events_rx = crate::pair::gate(alarm_events_rx, &leadership);
        let states_rx = crate::pair::gate(states_rx, &leadership);
        // A copy of each transition for the notifier, if it runs.
        let (notify_tx, notify_rx) = if opts.notify && !plant.notify.is_empty() {
            let (tx, rx) = mpsc::channel(4096);
            (Some(tx), Some(rx))
        } else {
            (None, None)
        };
        tasks.spawn(sinks::alarm_transitions(
            audit.handle(),
            transitions_rx,
            notify_tx,
        ));
        tasks.spawn(sinks::alarm_events(alarm_events_rx, events_tx.clone()));
        tasks.spawn(sinks::alarm_states(store.clone(), states_rx));
        let alarms = gridscada_alarms::AlarmEngine::new(
            &plant,
            db.clone(),
            clock.clone(),
            gridscada_alarms::AlarmChannels {
                transitions: transitions_tx,
                events: alarm_events_tx,
                states: Some(states_tx),
            },
            &restore,
            Default::default(),
        )
        .map_err(|e| anyhow!("starting the alarm engine: {e}"))?;
        // System alarms belong to the parts that raise them (panel sequences,
        // dispatch, historian), which start afresh: clear the restored ones
        // and let their owners raise again whatever still holds. Except the
        // faulty-zone and lockout alarms of panels that take over their saved
        // state: those still hold, and stay standing (acknowledged or not).
        let mut retained = if opts.restore_panels {
            sinks::load_panel_retained(&store).await
        } else {
            Default::default()
        };
        let standing: std::collections::HashSet<String> = plant
            .panels
            .iter()
            .filter_map(|p| Some((p, retained.get(p.id.get_ref())?)))
            .flat_map(|(p, r)| {
                r.alarm_keys(*p.zones.get_ref())
                    .into_iter()
                    .map(|k| sinks::panel_alarm_key(p.id.get_ref(), &k))
            })
            .collect();
        for r in restore.iter().filter(|r| {
            r.kind == gridscada_alarms::AlarmKind::System && r.active && !standing.contains(&r.key)
        }) {
            if let Err(e) = alarms.clear(&r.key) {
                tracing::warn!(key = %r.key, error = %e, "clearing a restored system alarm");
            }
        }
        tasks.spawn(alarms.clone().run());
        tasks.spawn(sinks::audit_spool_alarm(audit.handle(), alarms.clone()));
        let notify = match notify_rx {
            Some(rx) => {
                let (notifier, handle) = gridscada_notify::Notifier::new(
                    &plant,
                    store.clone(),
                    alarms.clone(),
                    clock.clone(),
                    events_tx.clone(),
                    rx,
                    &|name| std::env::var(name).ok(),
                )
                .map_err(|e| anyhow!("starting alarm notification: {e}"))?;
                tasks.spawn(notifier.run());
                Some(handle)
            }
            None => None,
        };

        // The historian.
        // Room for every tag's first row and half as many more: a large
        // plant's first scan brings them all within a second or two.
        let defaults = gridscada_store::HistorianConfig::default();
        let historian = gridscada_store::Historian::spawn(
            store.clone(),
            gridscada_store::HistorianConfig {
                capacity: defaults.capacity.max(db.len() + db.len() / 2),
                ..defaults
            },
        );
        let (feed_stop, feed_stop_rx) = watch::channel(false);
        let historian_feed = tokio::spawn(sinks::historian_feed(
            plant.clone(),
            db.clone(),
            historian.handle(),
            store.clone(),
            alarms.clone(),
            clock.clone(),
            feed_stop_rx,
            leadership.clone(),
        ));
        let mut loops = JoinSet::new();

        // The standing safety tags, read before any command (the guard
        // refuses every switching operation until they are), and before
        // the field I/O starts: between the first scans and the control
        // loops' start nothing may wait on the store's thread, or a replay
        // at --max starts its loops before or after the first readings as
        // that thread is quick or slow, and two runs part.
        let safety = gridscada_network::SafetyTags::default();
        let safety_loaded = match plant.network {
            Some(_) => sinks::load_safety_tags(&store, &safety).await,
            None => true,
        };

        let field = field::Field::start(
            &plant,
            db.clone(),
            clock.clone(),
            leadership.clone(),
            events_tx.clone(),
            pipes,
        )
        .context("starting field I/O")?;

        // The lease keeper and the announcements of role changes.
        let (pair, pair_keeper) = match (lease, &plant.redundancy) {
            (Some(lease), Some(cfg)) => {
                let (view_tx, view_rx) = watch::channel(Default::default());
                let role_changes = Arc::new(std::sync::atomic::AtomicU64::new(0));
                let (stop_tx, stop_rx) = watch::channel(false);
                let keeper = tokio::spawn(crate::pair::keep_lease(
                    lease,
                    cfg.clone(),
                    site.clone(),
                    leadership.clone(),
                    view_tx,
                    role_changes.clone(),
                    stop_rx,
                ));
                tasks.spawn(crate::pair::announce(
                    leadership.clone(),
                    view_rx.clone(),
                    store.clone(),
                    alarms.clone(),
                    events_tx.clone(),
                    clock.clone(),
                    role_changes.clone(),
                ));
                let handle = crate::pair::PairHandle {
                    leadership: leadership.clone(),
                    view: view_rx,
                    role_changes,
                };
                (Some(handle), Some((stop_tx, keeper)))
            }
            _ => (None, None),
        };
        // The topology processor: section states from the devices'
        // positions, on every server of a pair (it only derives tags).
        let network = match gridscada_network::Network::from_plant(&plant) {
            None => None,
            Some(Err(e)) => return Err(anyhow!("the switching network: {e}")),
            Some(Ok(net)) => {
                let net = Arc::new(net);
                // One of a pair reads the safety tags again every 2 s, so
                // that tags placed on the other server hold here too (a
                // server alone places and removes them itself).
                if plant.redundancy.is_some() || !safety_loaded {
                    tasks.spawn(sinks::reload_safety_tags(store.clone(), safety.clone()));
                }
                let mut driver =
                    gridscada_network::TopologyDriver::new(net.clone(), db.clone(), safety.clone());
                let (live_tx, live_rx) = watch::channel(Arc::new(driver.update(clock.now())));
                loops.spawn(driver.run(clock.clone(), live_tx));
                tasks.spawn(sinks::network_alarms(
                    net.clone(),
                    live_rx.clone(),
                    alarms.clone(),
                ));
                let selections = gridscada_network::Selections::new(net.select_timeout);
                Some(gridscada_web::NetworkView {
                    network: net,
                    live: live_rx,
                    tags: safety,
                    selections,
                })
            }
        };
        let mut writer = field.writer();
        // A central Sparkplug host takes the writes of remote tags.
        let sparkplug_host = match sparkplug_host::start(
            &plant,
            db.clone(),
            clock.clone(),
            writer.clone(),
            events_tx.clone(),
            alarms.clone(),
            historian.handle(),
            &mut tasks,
        )? {
            Some((host, routed)) => {
                writer = routed;
                Some(host)
            }
            None => None,
        };

        // Every command of every path (HTTP, OPC UA, DCMD, the IEC 104
        // server, the panel sequences, the dispatch) passes the switching
        // guard: safety tags and interlocks.
        if let Some(view) = &network {
            writer = Arc::new(gridscada_network::SwitchingGuard::new(
                view.network.clone(),
                writer,
                view.tags.clone(),
                view.selections.clone(),
                view.live.clone(),
                clock.clone(),
            ));
        }

        // One fault-isolation sequence per panel.
        let (panel_notices_tx, panel_notices_rx) = mpsc::channel::<PanelNotice>(1024);
        let selections = plant
            .panels
            .iter()
            .map(|p| (p.id.get_ref().clone(), p.prefix.get_ref().clone()))
            .collect();
        tasks.spawn(sinks::panel_notices(
            panel_notices_rx,
            events_tx.clone(),
            alarms.clone(),
            selections,
            sinks::panels_annunciating_trips(&plant),
            clock.clone(),
        ));
        let mut panels = Vec::new();
        for panel in &plant.panels {
            let (cmd_tx, cmd_rx) = mpsc::channel(16);
            let (status_tx, status_rx) = watch::channel(PanelStatus::initial(panel));
            let id = panel.id.get_ref().clone();
            if pair.is_some() {
                // Runs only while this server is active, restored from the
                // store at each activation.
                loops.spawn(crate::pair::panel_host(
                    crate::pair::PanelHost {
                        panel: panel.clone(),
                        db: db.clone(),
                        writer: writer.clone(),
                        clock: clock.clone(),
                        store: store.clone(),
                        site: site.clone(),
                        leadership: leadership.clone(),
                        notices: panel_notices_tx.clone(),
                    },
                    cmd_rx,
                    status_tx,
                ));
                panels.push(PanelHandle {
                    id,
                    status: status_rx,
                    commands: cmd_tx,
                });
                continue;
            }
            let driver = fault_isolation::run_panel(
                panel.clone(),
                db.clone(),
                writer.clone(),
                clock.clone(),
                cmd_rx,
                status_tx,
                panel_notices_tx.clone(),
                retained
                    .remove(&id)
                    .map(|r| (r, fault_isolation::Takeover::Restart)),
            );
            tasks.spawn(sinks::panel_retained(
                store.clone(),
                id.clone(),
                status_rx.clone(),
                clock.clone(),
                None,
            ));
            let label = id.clone();
            loops.spawn(async move {
                if let Err(e) = driver.await {
                    tracing::error!(panel = %label, error = %e, "fault-isolation sequence stopped");
                }
            });
            panels.push(PanelHandle {
                id,
                status: status_rx,
                commands: cmd_tx,
            });
        }

        // The microgrid's outer loop.
        let dispatch_rx = match &plant.microgrid {
            Some(mg) => {
                let (status_tx, status_rx) = watch::channel(DispatchStatus::default());
                let (notices_tx, notices_rx) = mpsc::channel(256);
                if pair.is_some() {
                    loops.spawn(crate::pair::dispatch_host(
                        mg.clone(),
                        db.clone(),
                        writer.clone(),
                        clock.clone(),
                        status_tx,
                        notices_tx,
                        opts.dispatch_policy,
                        leadership.clone(),
                    ));
                } else {
                    loops.spawn(dispatch::run_dispatch_with(
                        mg.clone(),
                        db.clone(),
                        writer.clone(),
                        clock.clone(),
                        status_tx,
                        notices_tx,
                        opts.dispatch_policy,
                    ));
                }
                tasks.spawn(sinks::dispatch_notices(
                    notices_rx,
                    events_tx.clone(),
                    alarms.clone(),
                ));
                tasks.spawn(sinks::dispatch_results(
                    store.clone(),
                    db.clone(),
                    status_rx.clone(),
                    clock.clone(),
                ));
                Some(status_rx)
            }
            None => None,
        };

        // Detached, not in `tasks`: it must never hold up a shutdown.
        tokio::spawn(memory::trim_after_start_up());
        Ok(Stack {
            plant,
            clock,
            store,
            db,
            alarms,
            writer,
            panels,
            dispatch: dispatch_rx,
            network,
            simulator,
            events: events_tx,
            pair,
            pair_keeper,
            mqtt_edge: None,
            notify,
            iec104_server_counters: Default::default(),
            field,
            sparkplug_host,
            historian,
            audit,
            historian_feed: (feed_stop, historian_feed),
            loops,
            tasks,
        })
    }

    /// The poller's counters (requests, timeouts, transport operations in flight).
    pub fn poll_stats(&self) -> gridscada_field::StatsHandle {
        self.field.stats_handle()
    }

    /// The historian's buffer and write figures.
    pub fn historian_metrics(&self) -> gridscada_store::HistorianMetrics {
        self.historian.handle().metrics()
    }

    /// Stops in reverse order: the producers first, then what records their
    /// output, so nothing committed is lost. Tag changes: field I/O and the
    /// simulators, then the control loops, then the historian feed (which
    /// offers every change published until then), then the historian's
    /// writer (which writes everything offered). Returns the historian's
    /// final figures, the ones it logs.
    pub async fn shutdown(mut self) -> gridscada_store::HistorianMetrics {
        // A pair's active server stops commanding and gives the lease up
        // first, so the standby takes over without waiting for it to expire.
        if let Some((stop, keeper)) = self.pair_keeper.take() {
            stop.send_replace(true);
            let _ = keeper.await;
        }
        // The edge node first: its NDEATH says the node is going.
        if let Some(edge) = self.mqtt_edge.take() {
            edge.shutdown().await;
        }
        self.field.shutdown().await;
        if let Some(host) = self.sparkplug_host.take() {
            host.shutdown().await;
        }
        if let Some(sim) = self.simulator.take() {
            sim.shutdown().await;
        }
        self.loops.abort_all();
        while self.loops.join_next().await.is_some() {}
        let (feed_stop, feed) = self.historian_feed;
        feed_stop.send_replace(true);
        if let Err(e) = feed.await {
            tracing::error!(error = %e, "historian feed failed");
        }
        let handle = self.historian.handle();
        self.historian.shutdown().await;
        drop(self.events);
        // Give the sinks a moment to drain their channels into the store.
        tokio::time::sleep(std::time::Duration::from_millis(300)).await;
        self.tasks.abort_all();
        while self.tasks.join_next().await.is_some() {}
        // What the sinks handed over is stored, or spooled for the next start.
        let audit = self.audit.shutdown().await;
        if audit.pending > 0 || audit.lost > 0 {
            tracing::warn!(
                pending = audit.pending,
                lost = audit.lost,
                "audit trail stopped"
            );
        }
        self.store.close().await;
        // Read last, so the figure counts any sample lost on the way.
        let written = handle.metrics();
        tracing::info!(
            samples = written.samples_written,
            dropped = written.dropped,
            "historian flushed"
        );
        written
    }
}

async fn run(
    plant: Plant,
    http: SocketAddr,
    data: &Path,
    mode: Mode,
    scenario: Option<Box<dyn LiveDriver>>,
    real_devices: Vec<String>,
) -> anyhow::Result<()> {
    // A wrong certificate or key stops the start before anything runs.
    let https = crate::https::load(&plant)?;
    // The data folder of this run (the demo's --data): where reports go.
    let mut plant = plant;
    plant.data_dir = data.to_path_buf();
    let store = open_store(&plant, data).await?;
    let clock: Arc<dyn Clock> = match &scenario {
        Some(live) => live.clock(),
        None => Arc::new(SystemClock),
    };
    let stack = Stack::start(
        plant,
        store,
        StackOptions {
            clock,
            simulate: mode == Mode::Demo,
            real_devices,
            simulator_pipes: false,
            dispatch_policy: Default::default(),
            // A scenario starts from its own initial state.
            restore_panels: scenario.is_none(),
            data_dir: data.to_path_buf(),
            notify: true,
        },
    )
    .await?;
    let mut stack = stack;
    match northbound::start_edge(&stack, data) {
        Ok(edge) => stack.mqtt_edge = edge,
        Err(e) => {
            stack.shutdown().await;
            return Err(e);
        }
    }
    let clock = stack.clock.clone();
    let store = stack.store.clone();
    let events_tx = stack.events.clone();
    // Scheduled reports ([reports]), into the data folder.
    if let Some(schedule) = gridscada_reports::Schedule::from_config(&stack.plant.reports) {
        tokio::spawn(gridscada_reports::archive::run_schedule(
            store.clone(),
            stack.plant.clone(),
            gridscada_reports::Archive::in_data_dir(data),
            schedule,
            clock.clone(),
        ));
    }

    // Users.
    let credentials = match mode {
        Mode::Demo => Some(users::demo_credentials(&store, data, clock.as_ref()).await?),
        Mode::Serve => {
            users::warn_if_no_administrator(&store, &stack.plant.main_path).await?;
            None
        }
    };

    let mut web = web_state(&stack).await;
    // The demo serves loopback only, and its figures are no secret.
    web.auth.metrics_open = mode == Mode::Demo;
    load_screens(&web, mode).await?;
    let opcua = opcua::start(&stack.plant, data, &mut web).await?;
    let telecontrol = match &stack.plant.iec104_server {
        Some(cfg) => Some(
            gridscada_iec104::Iec104Server::start(
                cfg,
                &stack.plant,
                gridscada_iec104::ServerContext {
                    db: stack.db.clone(),
                    writer: stack.writer.clone(),
                    audit: Arc::new(stack.audit.handle()),
                    clock: stack.clock.clone(),
                    counters: stack.iec104_server_counters.clone(),
                },
            )
            .await
            .map_err(anyhow::Error::msg)?,
        ),
        None => None,
    };
    let listening = crate::https::listen(&stack.plant, http, web, https).await?;
    crate::https::reload_on_sighup(listening.https.clone(), events_tx.clone(), clock.clone());
    let (url, server) = (listening.url, listening.server);

    let _ = events_tx
        .send(sinks::system_event(
            clock.as_ref(),
            "server",
            "server",
            format!("gridscada {} started", mode.label()),
        ))
        .await;
    println!("gridscada {} is running.", mode.label());
    // Under [server] base_path when served behind a proxy's sub-path.
    let url = format!(
        "{}{}/",
        url.trim_end_matches('/'),
        stack.plant.server.base_path()
    );
    println!("  HMI and API: {url}");
    println!("  Health:      {url}healthz");
    if let Some(redirect) = listening.redirect {
        println!("  Redirect:    http://{redirect}/ -> HTTPS");
    }
    if let Some(ua) = &opcua {
        println!("  OPC UA:      {}", ua.endpoint());
    }
    if let Some(t) = &telecontrol {
        println!("  IEC 104:     {} (controlled station)", t.local_addr);
    }
    println!("  Data folder: {}", data.display());
    if let Some(creds) = &credentials {
        println!(
            "  Log in with one of these generated accounts (also in {}):",
            creds.file.display()
        );
        for (role, user, password) in &creds.accounts {
            println!("    {role:<13} user {user:<11} password {password}");
        }
    }
    if let Some(live) = scenario {
        live.start(&stack);
    }
    println!("Press Ctrl-C to stop.");

    let outcome = tokio::select! {
        r = server => r.context("HTTP server failed"),
        _ = shutdown_signal() => {
            tracing::info!("stopping");
            Ok(())
        }
    };

    let _ = events_tx
        .send(sinks::system_event(
            clock.as_ref(),
            "server",
            "server",
            format!("gridscada {} stopping", mode.label()),
        ))
        .await;
    drop(events_tx);
    if let Some(ua) = opcua {
        ua.shutdown().await;
    }
    if let Some(t) = telecontrol {
        t.shutdown().await;
    }
    stack.shutdown().await;
    outcome
}

/// The `[iec104_server]` points whose tag is neither configured nor
/// derived (a panel's or the dispatch's), as `check` reports them.
pub(crate) fn check_exports(plant: &Plant) -> Vec<String> {
    let Some(server) = &plant.iec104_server else {
        return Vec::new();
    };
    let known: std::collections::HashSet<String> = all_tags(plant)
        .into_iter()
        .map(|t| t.name.to_string())
        .collect();
    server
        .points
        .iter()
        .filter(|p| !known.contains(p.tag.get_ref()))
        .map(|p| {
            format!(
                "{}: [iec104_server] point: unknown tag '{}' (neither in the tag files nor a panel's or the dispatch's)",
                plant.main_path.display(),
                p.tag.get_ref()
            )
        })
        .collect()
}

/// Takes the user-drawn screens from the store, then the plant's
/// `screens/*.json` folder (beside the main configuration file) into the
/// store. `serve` refuses to start on a broken screen file; `demo` warns.
async fn load_screens(web: &gridscada_web::WebState, mode: Mode) -> anyhow::Result<()> {
    use gridscada_web::api::screens;
    for w in screens::load_library(web)
        .await
        .context("loading the saved screens")?
    {
        tracing::warn!("{w}");
    }
    let dir = gridscada_config::screen::folder_of(&web.plant.main_path);
    match screens::sync_folder(web, &dir).await {
        Ok(taken) if !taken.is_empty() => {
            tracing::info!(screens = ?taken, folder = %dir.display(), "screens taken from files");
        }
        Ok(_) => {}
        Err(errors) if mode == Mode::Serve => {
            return Err(anyhow!(
                "the screens folder has problems:\n  {}",
                errors.join("\n  ")
            ));
        }
        Err(errors) => {
            for e in errors {
                tracing::warn!("screen not loaded: {e}");
            }
        }
    }
    Ok(())
}

/// The web layer's view of a running stack.
pub async fn web_state(stack: &Stack) -> gridscada_web::WebState {
    let policy = gridscada_web::auth::SessionPolicy::from_config(&stack.plant.server.sessions);
    // Sessions in the store, with their upkeep (activity, re-checks, sweep);
    // over HTTPS the session cookie is never sent in clear.
    let auth =
        gridscada_web::Auth::new(policy, stack.plant.tls.is_some(), stack.store.clone()).await;
    gridscada_web::WebState {
        db: stack.db.clone(),
        plant: stack.plant.clone(),
        store: stack.store.clone(),
        audit: Some(stack.audit.handle()),
        auth,
        clock: stack.clock.clone(),
        writer: Some(stack.writer.clone()),
        started: Instant::now(),
        components: gridscada_web::Components {
            panels: stack.panels.clone(),
            alarms: Some(stack.alarms.clone()),
            dispatch: stack.dispatch.clone(),
            pair: stack.pair.as_ref().map(|p| gridscada_web::api::pair::Pair {
                leadership: p.leadership.clone(),
                view: p.view.clone(),
            }),
            network: stack.network.clone(),
        },
        sim: stack.simulator.as_ref().map(|s| {
            Arc::new(SimAdapter(s.handle())) as Arc<dyn gridscada_web::api::sim::SimControl>
        }),
        http_metrics: Default::default(),
        metrics: Some(Arc::new(StackMetrics {
            poll: stack.field.stats_handle(),
            historian: stack.historian.handle(),
            audit: stack.audit.handle(),
            pair: stack.pair.clone(),
            sparkplug_host: stack
                .sparkplug_host
                .as_ref()
                .map(|h| Arc::new(h.stats_source()) as sparkplug_host::HostStatsSource),
            mqtt: stack.mqtt_edge.as_ref().map(|e| e.metrics()),
            notify: stack.notify.clone(),
            iec104_server: stack.iec104_server_counters.clone(),
        })),
        screens: Default::default(),
        devices: Some(Arc::new(StackDevices {
            plant: stack.plant.clone(),
            db: stack.db.clone(),
            poll: stack.field.stats_handle(),
            rates: Default::default(),
        })),
        tls: stack.plant.tls.is_some(),
        live: Default::default(),
        connections: Arc::new(connections(&stack.plant)),
    }
}

/// The listeners' connection limits (`[server.connections]`), fitted to
/// the open-file limit (raised to its hard limit first), so that the
/// server refuses or makes room before the process runs out of
/// descriptors.
fn connections(plant: &gridscada_config::Plant) -> gridscada_web::listener::Connections {
    use gridscada_web::listener::{raise_open_file_limit, ConnectionLimits, Connections};
    let configured = ConnectionLimits::from_config(&plant.server.connections);
    let limits = match raise_open_file_limit() {
        Some(descriptors) => configured.fitted_to(descriptors),
        None => configured,
    };
    if limits.max_open < configured.max_open {
        tracing::info!(
            max_open = limits.max_open,
            configured = configured.max_open,
            "[server.connections] max_open lowered to fit the open-file limit (LimitNOFILE)"
        );
    }
    Connections::new(
        limits,
        gridscada_web::proxy::TrustedProxies::of_server(&plant.server),
    )
}

/// Ctrl-C or SIGTERM (a service manager stopping us).
async fn shutdown_signal() {
    #[cfg(unix)]
    {
        let mut term =
            match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
                Ok(t) => t,
                Err(_) => {
                    let _ = tokio::signal::ctrl_c().await;
                    return;
                }
            };
        tokio::select! {
            _ = tokio::signal::ctrl_c() => {}
            _ = term.recv() => {}
        }
    }
    #[cfg(not(unix))]
    let _ = tokio::signal::ctrl_c().await;
}
