//! # gridscada-sim: simulated field devices
//!
//! **Owns:** Modbus TCP servers on loopback that behave like the plant's
//! devices, built from the plant configuration: substation panels (ELCB,
//! main MCCB, zone MCBs behind an I/O gateway, and a power analyzer) and
//! microgrid units (PV, wind, storage, diesel with their inner-loop
//! controllers, and the load meter); and the IEC 104 stations and DNP3
//! outstations of `protocol = "iec104"` and `"dnp3"` devices, whose points
//! the same models drive (`station.rs`). A [`SimHandle`] injects faults (zone faults, unit
//! trips, communication faults of Modbus devices) and sets plant inputs; it
//! is the interface the HTTP admin routes and scenario replay use.
//!
//! **Must not touch:** the server's tag database, the poller or the control
//! loops. The simulator is only reachable over Modbus, IEC 104 or DNP3 and
//! through its handle.
//! Register maps: `docs/REGISTER_MAPS.md`.

mod codec;
mod handle;
mod image;
mod map;
mod microgrid;
mod network;
mod panel;
mod plant;
mod profile;
pub mod scenario;
mod server;
mod station;

use std::collections::HashMap;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use gridscada_config::Plant;
use gridscada_tagdb::{Clock, SystemClock};
use parking_lot::{Mutex, RwLock};
use serde_spanned::Spanned;
use tokio::net::TcpListener;
use tokio::sync::watch;
use tokio::task::JoinHandle;

pub use handle::SimHandle;
pub use microgrid::{BalanceCounters, MicrogridParams, UnitCounters, UnitState};
pub use panel::{AnalyzerReading, FaultKind, TripRecord, ZoneLoad};
pub use plant::{
    BreakerSnapshot, DeviceSnapshot, MicrogridSnapshot, PanelSnapshot, SimSnapshot, UnitSnapshot,
    ZoneSnapshot,
};
pub use profile::Profile;
/// Modbus exception codes, for [`SimHandle::set_exception`].
pub use tokio_modbus::ExceptionCode;

use server::{CommFaults, Gateway, Shared};

/// Errors of the simulator, each naming what and where.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The plant configuration cannot be simulated as it is.
    #[error("simulator configuration: {0}")]
    Config(String),
    /// A gateway address could not be resolved or bound.
    #[error("simulator cannot listen on {address}: {source}")]
    Bind {
        address: String,
        #[source]
        source: std::io::Error,
    },
    /// A control-interface call named a panel, zone, unit or device that the
    /// simulator does not have.
    #[error("{0}")]
    NotFound(String),
    /// A control-interface call gave a value out of range.
    #[error("bad value: {0}")]
    BadValue(String),
    #[error("simulator I/O: {0}")]
    Io(#[from] std::io::Error),
}

/// Where the gateways listen.
#[derive(Debug, Clone)]
pub enum BindMode {
    /// The addresses in the device configuration (`gridscada sim`).
    Configured,
    /// `127.0.0.1:0` per gateway, so nothing collides (`gridscada demo`,
    /// tests); see [`Simulator::addresses`].
    Ephemeral,
    /// The Modbus gateways answer in-process pipes on their configured
    /// addresses, reachable only by a poller given the same switchboard
    /// (a scenario replay); telecontrol stations listen as with `Ephemeral`.
    InProcess(Arc<gridscada_field::Switchboard>),
}

/// Simulator settings that are not part of the plant configuration.
#[derive(Debug, Clone)]
pub struct SimOptions {
    /// Plant time for a breaker contact (and its status input) to follow its
    /// command, and for the ELCB to reclose after a reset pulse.
    pub breaker_delay: Duration,
    /// Plant-time period of the background step (the models are also
    /// advanced on every request, so this only bounds integration lag).
    pub tick: Duration,
    /// Panels start with the MCCB and every zone MCB closed (commands on);
    /// otherwise everything starts open. The ELCB starts closed.
    pub panels_start_closed: bool,
    pub microgrid: MicrogridParams,
}

impl Default for SimOptions {
    fn default() -> Self {
        SimOptions {
            breaker_delay: Duration::from_millis(50),
            tick: Duration::from_millis(200),
            panels_start_closed: true,
            microgrid: MicrogridParams::default(),
        }
    }
}

/// A running simulator. Dropping it stops the servers.
pub struct Simulator {
    handle: SimHandle,
    addresses: HashMap<String, SocketAddr>,
    shutdown: watch::Sender<bool>,
    tasks: Vec<JoinHandle<()>>,
    stations: Vec<station::Station>,
}

impl std::fmt::Debug for Simulator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Simulator")
            .field("addresses", &self.addresses)
            .finish()
    }
}

impl Simulator {
    /// The control interface.
    pub fn handle(&self) -> SimHandle {
        self.handle.clone()
    }

    /// Configured gateway address (`host:port` as written in the device
    /// configuration) -> the address actually listening.
    pub fn addresses(&self) -> &HashMap<String, SocketAddr> {
        &self.addresses
    }

    /// Points every simulated device of `plant` at the address its gateway
    /// actually listens on (for [`BindMode::Ephemeral`]).
    pub fn patch_plant(&self, plant: &mut Plant) {
        let patch = |addr: &mut Spanned<String>| {
            if let Some(actual) = self.addresses.get(addr.get_ref()) {
                let span = addr.span();
                *addr = Spanned::new(span, actual.to_string());
            }
        };
        for d in &mut plant.devices {
            if let Some(addr) = &mut d.address {
                patch(addr);
            }
            if let Some(link) = &mut d.iec104 {
                link.redundant_addresses.iter_mut().for_each(patch);
            }
        }
    }

    /// Stops the servers and the plant step, and waits for them.
    pub async fn shutdown(mut self) {
        let _ = self.shutdown.send(true);
        for t in self.tasks.drain(..) {
            let _ = t.await;
        }
        for s in self.stations.drain(..) {
            s.shutdown().await;
        }
    }
}

impl Drop for Simulator {
    fn drop(&mut self) {
        let _ = self.shutdown.send(true);
    }
}

/// Starts the simulator with default options.
pub async fn start(
    plant: &Plant,
    clock: Arc<dyn Clock>,
    bind: BindMode,
) -> Result<Simulator, Error> {
    start_with(plant, clock, bind, SimOptions::default()).await
}

/// Starts the simulator: builds the devices from `plant`, binds one listener
/// per gateway address and starts the plant step on `clock`.
pub async fn start_with(
    plant: &Plant,
    clock: Arc<dyn Clock>,
    bind: BindMode,
    options: SimOptions,
) -> Result<Simulator, Error> {
    let sim = plant::PlantSim::new(plant, &options, clock.now())?;
    for s in &sim.unserved {
        tracing::warn!("simulator: not simulated: {s}");
    }
    if !sim.unmodelled.is_empty() {
        tracing::info!(
            tags = %sim.unmodelled.join(", "),
            "simulator: tags without a simulated meaning (they read 0)"
        );
    }
    let gateways = sim.gateways.clone();
    let station_specs = sim.stations.clone();
    let device_count = sim.devices.len();
    let shared = Arc::new(Shared {
        plant: Mutex::new(sim),
        comm: RwLock::new(vec![CommFaults::default(); device_count]),
        clock: clock.clone(),
    });

    // Bind everything before serving anything, so a failure leaves nothing behind.
    let mut wires = vec![];
    let mut addresses = HashMap::new();
    for g in &gateways {
        wires.push(match &bind {
            BindMode::InProcess(board) => server::Wire::Pipes(board.listen(&g.address)),
            _ => {
                let listener = bind_one(&bind, &g.address).await?;
                addresses.insert(g.address.clone(), listener.local_addr()?);
                server::Wire::Socket(listener)
            }
        });
    }
    let mut station_listeners = vec![];
    for s in &station_specs {
        let mut ls = vec![];
        for address in std::iter::once(&s.address).chain(&s.redundant) {
            let listener = bind_one(&bind, address).await?;
            addresses.insert(address.clone(), listener.local_addr()?);
            ls.push(listener);
        }
        station_listeners.push(ls);
    }

    let (tx, rx) = watch::channel(false);
    let mut tasks = vec![];
    for (g, wire) in gateways.iter().zip(wires) {
        let gw = Arc::new(Gateway {
            label: g.address.clone(),
            units: g.units.clone(),
        });
        let (shared, rx) = (shared.clone(), rx.clone());
        tasks.push(match wire {
            server::Wire::Socket(listener) => tokio::spawn(server::serve(listener, shared, gw, rx)),
            server::Wire::Pipes(incoming) => {
                tokio::spawn(server::serve_pipes(incoming, shared, gw, rx))
            }
        });
    }
    let mut stations = vec![];
    for (i, (spec, ls)) in station_specs.iter().zip(station_listeners).enumerate() {
        stations.push(station::Station::start(
            shared.clone(),
            i,
            plant,
            &spec.name,
            ls,
            STATION_REPORT_PERIOD,
            rx.clone(),
        )?);
    }
    tasks.push(tokio::spawn(step_loop(shared.clone(), options.tick, rx)));

    Ok(Simulator {
        handle: SimHandle { shared },
        addresses,
        shutdown: tx,
        tasks,
        stations,
    })
}

/// How often (plant time) a simulated telecontrol station looks for
/// changed values to report spontaneously: an RTU reports a breaker's move
/// within milliseconds, not at a scan.
const STATION_REPORT_PERIOD: Duration = Duration::from_millis(20);

/// One listener: on its configured address, or on an ephemeral port of
/// loopback.
async fn bind_one(bind: &BindMode, address: &str) -> Result<TcpListener, Error> {
    match bind {
        BindMode::Configured => bind_configured(address).await,
        BindMode::Ephemeral | BindMode::InProcess(_) => TcpListener::bind(("127.0.0.1", 0))
            .await
            .map_err(|source| Error::Bind {
                address: "127.0.0.1:0".into(),
                source,
            }),
    }
}

async fn bind_configured(address: &str) -> Result<TcpListener, Error> {
    let bind_err = |source| Error::Bind {
        address: address.to_string(),
        source,
    };
    let mut addrs = tokio::net::lookup_host(address).await.map_err(bind_err)?;
    let first = addrs.next().ok_or_else(|| Error::Bind {
        address: address.to_string(),
        source: std::io::Error::new(std::io::ErrorKind::NotFound, "address resolves to nothing"),
    })?;
    TcpListener::bind(first).await.map_err(bind_err)
}

/// Advances the plant on the clock even when nobody polls, so energy
/// counters and state of charge integrate in plant time.
async fn step_loop(shared: Arc<Shared>, tick: Duration, mut shutdown: watch::Receiver<bool>) {
    let tick = tick.max(Duration::from_millis(10));
    loop {
        tokio::select! {
            _ = shared.clock.sleep(tick) => {}
            _ = shutdown.wait_for(|s| *s) => return,
        }
        shared.with_plant(|_| ());
    }
}

/// `gridscada sim`: serves the plant's devices on their configured addresses
/// with the system clock until Ctrl-C.
/// One line of the standalone simulator's fault-injection input.
fn control_line(handle: &SimHandle, line: &str) -> Result<(), String> {
    let words: Vec<&str> = line.split_whitespace().collect();
    let zone = |w: &str| {
        w.parse::<u8>()
            .map_err(|_| format!("'{w}' is not a zone number"))
    };
    match words.as_slice() {
        ["fault", panel, z, kind] => {
            let kind = match *kind {
                "permanent" => FaultKind::Permanent,
                "transient" => FaultKind::Transient,
                other => return Err(format!("unknown fault kind '{other}'")),
            };
            handle
                .inject_zone_fault(panel, zone(z)?, kind)
                .map_err(|e| e.to_string())
        }
        ["transient", panel, z, secs] => {
            let secs: u64 = secs
                .parse()
                .map_err(|_| format!("'{secs}' is not a number of seconds"))?;
            handle
                .inject_timed_fault(panel, zone(z)?, Duration::from_secs(secs))
                .map_err(|e| e.to_string())
        }
        ["slow", device, ms] => {
            let ms: u64 = ms
                .parse()
                .map_err(|_| format!("'{ms}' is not a number of milliseconds"))?;
            let delay = (ms > 0).then(|| Duration::from_millis(ms));
            handle
                .set_slow_replies(device, delay)
                .map_err(|e| e.to_string())
        }
        ["corrupt", device, on] => handle
            .set_corrupt_frames(device, on_off(on)?)
            .map_err(|e| e.to_string()),
        ["exception", device, on] => handle
            .set_exception(
                device,
                on_off(on)?.then_some(ExceptionCode::ServerDeviceFailure),
            )
            .map_err(|e| e.to_string()),
        ["repair", panel, z] => handle
            .repair_zone(panel, zone(z)?)
            .map_err(|e| e.to_string()),
        ["offline", device] => handle
            .set_device_offline(device, true)
            .map_err(|e| e.to_string()),
        ["online", device] => handle
            .set_device_offline(device, false)
            .map_err(|e| e.to_string()),
        [] => Ok(()),
        _ => Err(format!(
            "unknown command '{line}'; expected fault PANEL ZONE permanent|transient, transient PANEL ZONE SECONDS, repair PANEL ZONE, offline DEVICE, online DEVICE, slow DEVICE MS, corrupt DEVICE on|off or exception DEVICE on|off"
        )),
    }
}

fn on_off(w: &str) -> Result<bool, String> {
    match w {
        "on" => Ok(true),
        "off" => Ok(false),
        other => Err(format!("'{other}': expected on or off")),
    }
}

pub async fn run_standalone(plant: &Plant) -> Result<(), Error> {
    let sim = start(plant, Arc::new(SystemClock), BindMode::Configured).await?;
    let snapshot = sim.handle().snapshot();
    let mut by_address: Vec<(&String, &SocketAddr)> = sim.addresses().iter().collect();
    by_address.sort();
    for (configured, actual) in by_address {
        let units: Vec<String> = snapshot
            .devices
            .iter()
            .filter(|d| &d.address == configured)
            .map(|d| format!("unit {} = {}", d.unit_id, d.name))
            .collect();
        tracing::info!(address = %actual, "simulator: serving {}", units.join(", "));
    }
    // Fault injection from standard input, one command a line (a test or
    // an engineer at the terminal drives the plant like the demo's
    // simulator API): `fault PANEL ZONE permanent|transient`, `transient
    // PANEL ZONE SECONDS` (clears after that time), `repair PANEL ZONE`,
    // `offline DEVICE`, `online DEVICE`, `slow DEVICE MS` (0: no delay),
    // `corrupt DEVICE on|off`, `exception DEVICE on|off`. Each answers `ok`
    // or `error: ...` on standard output.
    let handle = sim.handle();
    std::thread::spawn(move || {
        use std::io::BufRead;
        for line in std::io::stdin().lock().lines().map_while(Result::ok) {
            match control_line(&handle, &line) {
                Ok(()) => println!("ok"),
                Err(e) => println!("error: {e}"),
            }
        }
    });
    tokio::signal::ctrl_c().await?;
    tracing::info!("simulator: stopping");
    sim.shutdown().await;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn control_lines_drive_the_training_faults() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tags");
        let plant = gridscada_config::load_path(&dir).unwrap_or_else(|d| panic!("{d:?}"));
        let sim = start(&plant, Arc::new(SystemClock), BindMode::Ephemeral)
            .await
            .unwrap();
        let h = sim.handle();
        let device = |name: &str| {
            h.snapshot()
                .devices
                .into_iter()
                .find(|d| d.name == name)
                .unwrap()
        };
        control_line(&h, "slow MG.PV1 1500").unwrap();
        control_line(&h, "corrupt MG.PV1 on").unwrap();
        control_line(&h, "exception MG.WT1 on").unwrap();
        let pv = device("MG.PV1");
        assert_eq!((pv.slow_reply_ms, pv.corrupt_frames), (Some(1500), true));
        assert_eq!(device("MG.WT1").exception, Some(4));
        control_line(&h, "slow MG.PV1 0").unwrap();
        control_line(&h, "corrupt MG.PV1 off").unwrap();
        control_line(&h, "exception MG.WT1 off").unwrap();
        let pv = device("MG.PV1");
        assert_eq!((pv.slow_reply_ms, pv.corrupt_frames), (None, false));
        assert_eq!(device("MG.WT1").exception, None);
        control_line(&h, "transient ss1 2 30").unwrap();
        let snap = h.snapshot();
        let z2 = &snap.panel("ss1").unwrap().zones[1];
        assert_eq!(z2.fault, Some(FaultKind::Transient));
        assert!(z2.fault_clears_at.is_some());
        for bad in [
            "slow MG.PV1 soon",
            "corrupt MG.PV1 maybe",
            "transient ss1 2 0",
            "slow nobody 10",
            "dance",
        ] {
            assert!(control_line(&h, bad).is_err(), "{bad}");
        }
        sim.shutdown().await;
    }
}
