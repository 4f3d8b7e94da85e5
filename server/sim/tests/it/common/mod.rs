#![allow(dead_code)]

use std::net::SocketAddr;
use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use gridscada_config::{load_path, Plant, RegisterKind};
use gridscada_sim::{BindMode, Simulator};
use gridscada_tagdb::{Clock, ScaledClock, Timestamp};
use tokio_modbus::client::{tcp, Context, Reader, Writer};
use tokio_modbus::Slave;

pub fn demo_plant() -> Plant {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tags");
    load_path(&dir).unwrap_or_else(|d| panic!("demo plant does not load: {d:?}"))
}

/// Noon UTC on 2024-06-01, so the built-in sun is up.
pub const NOON: i64 = 1_717_243_200_000;

pub struct Rig {
    pub plant: Plant,
    pub sim: Simulator,
    pub clock: Arc<ScaledClock>,
}

pub async fn rig(speed: f64) -> Rig {
    let plant = demo_plant();
    rig_with(plant, speed).await
}

pub async fn rig_with(plant: Plant, speed: f64) -> Rig {
    let clock = Arc::new(ScaledClock::new(Timestamp::from_millis(NOON), speed));
    // These tests check each unit's own controller against its setpoint, so
    // the battery does not also form the grid here (that has its own test).
    let options = gridscada_sim::SimOptions {
        microgrid: gridscada_sim::MicrogridParams {
            storage_grid_forming: false,
            ..Default::default()
        },
        ..Default::default()
    };
    let sim = gridscada_sim::start_with(&plant, clock.clone(), BindMode::Ephemeral, options)
        .await
        .expect("simulator starts");
    Rig { plant, sim, clock }
}

impl Rig {
    pub fn addr_of(&self, device: &str) -> (SocketAddr, u8) {
        let d = self.plant.device(device).expect("device");
        let configured = d.address.as_ref().unwrap().get_ref();
        (self.sim.addresses()[configured], *d.unit_id.get_ref())
    }

    pub async fn client(&self, device: &str) -> Context {
        let (addr, unit) = self.addr_of(device);
        tcp::connect_slave(addr, Slave(unit))
            .await
            .expect("connect")
    }

    /// Waits `d` of plant time.
    pub async fn wait(&self, d: Duration) {
        self.clock.sleep(d).await;
    }

    pub async fn read_bool(&self, tag: &str) -> bool {
        let t = self.plant.tag(tag).expect("tag");
        let mut c = self.client(t.device.get_ref()).await;
        let a = t.register().unwrap().1 as u16;
        let r = match &t.register().unwrap().0 {
            RegisterKind::Coil => c.read_coils(a, 1).await,
            RegisterKind::DiscreteInput => c.read_discrete_inputs(a, 1).await,
            k => panic!("{tag} is on {k:?}"),
        };
        r.expect("transport").expect("no exception")[0]
    }

    pub async fn read_f32(&self, tag: &str) -> f64 {
        let t = self.plant.tag(tag).expect("tag");
        let mut c = self.client(t.device.get_ref()).await;
        let a = t.register().unwrap().1 as u16;
        let w = match &t.register().unwrap().0 {
            RegisterKind::InputRegister => c.read_input_registers(a, 2).await,
            RegisterKind::HoldingRegister => c.read_holding_registers(a, 2).await,
            k => panic!("{tag} is on {k:?}"),
        }
        .expect("transport")
        .expect("no exception");
        f32_of(&w) as f64
    }

    pub async fn read_u16(&self, tag: &str) -> u16 {
        let t = self.plant.tag(tag).expect("tag");
        let mut c = self.client(t.device.get_ref()).await;
        let a = t.register().unwrap().1 as u16;
        c.read_input_registers(a, 1).await.unwrap().unwrap()[0]
    }

    pub async fn write_coil(&self, tag: &str, v: bool) {
        let t = self.plant.tag(tag).expect("tag");
        let mut c = self.client(t.device.get_ref()).await;
        c.write_single_coil(t.register().unwrap().1 as u16, v)
            .await
            .expect("transport")
            .expect("no exception");
    }

    pub async fn write_f32(&self, tag: &str, v: f32) {
        let t = self.plant.tag(tag).expect("tag");
        let mut c = self.client(t.device.get_ref()).await;
        let b = v.to_bits();
        c.write_multiple_registers(
            t.register().unwrap().1 as u16,
            &[(b >> 16) as u16, b as u16],
        )
        .await
        .expect("transport")
        .expect("no exception");
    }

    /// Pulses a coil on then off, as the controller does with ELCB reset.
    pub async fn pulse(&self, tag: &str) {
        self.write_coil(tag, true).await;
        self.wait(Duration::from_millis(100)).await;
        self.write_coil(tag, false).await;
    }
}

pub fn f32_of(w: &[u16]) -> f32 {
    f32::from_bits((u32::from(w[0]) << 16) | u32::from(w[1]))
}

/// Polls `f` (plant time) until it holds, for at most `limit` of plant time.
pub async fn eventually<F, Fut>(rig: &Rig, limit: Duration, mut f: F) -> bool
where
    F: FnMut() -> Fut,
    Fut: std::future::Future<Output = bool>,
{
    let end = rig.clock.now().add(limit);
    loop {
        if f().await {
            return true;
        }
        if rig.clock.now() > end {
            return false;
        }
        rig.wait(Duration::from_millis(50)).await;
    }
}
