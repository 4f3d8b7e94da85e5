//! Test peers: an in-process tokio-modbus server with scriptable faults, and
//! plant configurations built from TOML text.
#![allow(dead_code)]

use std::collections::HashMap;
use std::future::Future;
use std::net::SocketAddr;
use std::path::Path;
use std::pin::Pin;
use std::sync::Arc;
use std::time::Duration;

use gridscada_config::Plant;
use gridscada_tagdb::{TagDb, TagMeta};
use parking_lot::Mutex;
use tokio::net::TcpListener;
use tokio::task::JoinHandle;
use tokio_modbus::server::tcp::{accept_tcp_connection, Server};
use tokio_modbus::server::Service;
use tokio_modbus::{ExceptionCode, Request, Response, SlaveRequest};

/// The four tables of one simulated unit.
pub struct Unit {
    pub coils: Vec<bool>,
    pub discrete: Vec<bool>,
    pub holding: Vec<u16>,
    pub input: Vec<u16>,
    /// Never answer.
    pub silent: bool,
    /// Answer after this long.
    pub delay: Duration,
    /// Delay only reads starting at this address (with `delay`), once.
    pub delay_once_at: Option<u16>,
    /// Reads touching addresses at or above this answer "illegal data address".
    pub readable_below: u16,
    /// Acknowledge writes without storing them.
    pub ignore_writes: bool,
}

impl Default for Unit {
    fn default() -> Self {
        Unit {
            coils: vec![false; 65536],
            discrete: vec![false; 65536],
            holding: vec![0; 65536],
            input: vec![0; 65536],
            silent: false,
            delay: Duration::ZERO,
            delay_once_at: None,
            readable_below: u16::MAX,
            ignore_writes: false,
        }
    }
}

/// Units by id, shared between the test and the server.
#[derive(Default)]
pub struct Bank {
    pub units: Mutex<HashMap<u8, Unit>>,
    /// Every request received: (unit, function code, address).
    pub log: Mutex<Vec<(u8, u8, u16)>>,
}

impl Bank {
    pub fn with_units(ids: &[u8]) -> Arc<Bank> {
        let bank = Bank::default();
        for id in ids {
            bank.units.lock().insert(*id, Unit::default());
        }
        Arc::new(bank)
    }

    pub fn unit<R>(&self, id: u8, f: impl FnOnce(&mut Unit) -> R) -> R {
        f(self.units.lock().get_mut(&id).expect("unit"))
    }

    fn answer(&self, slave: u8, req: &Request<'_>) -> Result<Option<Response>, ExceptionCode> {
        let mut units = self.units.lock();
        let Some(u) = units.get_mut(&slave) else {
            return Ok(None);
        };
        let range = |a: u16, n: u16| {
            let end = usize::from(a) + usize::from(n);
            if end > usize::from(u.readable_below) || end > 65536 {
                Err(ExceptionCode::IllegalDataAddress)
            } else {
                Ok(usize::from(a)..end)
            }
        };
        Ok(Some(match req {
            Request::ReadCoils(a, n) => Response::ReadCoils(u.coils[range(*a, *n)?].to_vec()),
            Request::ReadDiscreteInputs(a, n) => {
                Response::ReadDiscreteInputs(u.discrete[range(*a, *n)?].to_vec())
            }
            Request::ReadHoldingRegisters(a, n) => {
                Response::ReadHoldingRegisters(u.holding[range(*a, *n)?].to_vec())
            }
            Request::ReadInputRegisters(a, n) => {
                Response::ReadInputRegisters(u.input[range(*a, *n)?].to_vec())
            }
            Request::WriteSingleCoil(a, v) => {
                if !u.ignore_writes {
                    u.coils[usize::from(*a)] = *v;
                }
                Response::WriteSingleCoil(*a, *v)
            }
            Request::WriteSingleRegister(a, v) => {
                if !u.ignore_writes {
                    u.holding[usize::from(*a)] = *v;
                }
                Response::WriteSingleRegister(*a, *v)
            }
            Request::WriteMultipleRegisters(a, w) => {
                let r = range(*a, w.len() as u16)?;
                if !u.ignore_writes {
                    u.holding[r].copy_from_slice(w);
                }
                Response::WriteMultipleRegisters(*a, w.len() as u16)
            }
            _ => return Err(ExceptionCode::IllegalFunction),
        }))
    }

    fn delay_for(&self, slave: u8, req: &Request<'_>) -> Option<Duration> {
        let mut units = self.units.lock();
        let u = units.get_mut(&slave)?;
        if u.silent {
            return None;
        }
        let addr = match req {
            Request::ReadHoldingRegisters(a, _) | Request::ReadInputRegisters(a, _) => Some(*a),
            _ => None,
        };
        if u.delay_once_at.is_some() && u.delay_once_at == addr {
            u.delay_once_at = None;
            return Some(std::mem::take(&mut u.delay));
        }
        if u.delay_once_at.is_some() {
            return Some(Duration::ZERO);
        }
        Some(u.delay)
    }
}

fn address(req: &Request<'_>) -> u16 {
    match req {
        Request::ReadCoils(a, _)
        | Request::ReadDiscreteInputs(a, _)
        | Request::ReadHoldingRegisters(a, _)
        | Request::ReadInputRegisters(a, _)
        | Request::WriteSingleCoil(a, _)
        | Request::WriteSingleRegister(a, _)
        | Request::WriteMultipleRegisters(a, _) => *a,
        _ => 0,
    }
}

#[derive(Clone)]
pub struct Svc(pub Arc<Bank>);

type Fut = Pin<Box<dyn Future<Output = Result<Option<Response>, ExceptionCode>> + Send>>;

impl Service for Svc {
    type Request = SlaveRequest<'static>;
    type Response = Option<Response>;
    type Exception = ExceptionCode;
    type Future = Fut;

    fn call(&self, req: Self::Request) -> Self::Future {
        let bank = Arc::clone(&self.0);
        Box::pin(async move {
            let SlaveRequest { slave, request } = req;
            bank.log
                .lock()
                .push((slave, request.function_code().value(), address(&request)));
            let Some(delay) = bank.delay_for(slave, &request) else {
                return Ok(None);
            };
            if !delay.is_zero() {
                tokio::time::sleep(delay).await;
            }
            bank.answer(slave, &request)
        })
    }
}

/// Serves `bank` on `addr` (port 0 for any); returns the bound address.
pub async fn serve(bank: Arc<Bank>, addr: &str) -> (SocketAddr, JoinHandle<()>) {
    let listener = TcpListener::bind(addr).await.expect("bind");
    let local = listener.local_addr().unwrap();
    let server = Server::new(listener);
    let task = tokio::spawn(async move {
        let on_connected = |stream, socket_addr| {
            let svc = Svc(Arc::clone(&bank));
            async move { accept_tcp_connection(stream, socket_addr, move |_| Ok(Some(svc.clone()))) }
        };
        let _ = server.serve(&on_connected, |_err| {}).await;
    });
    (local, task)
}

/// Loads a plant from a tag file's text (and a minimal main file).
pub fn plant(tag_file: &str) -> Plant {
    let main = "tag_files = [\"tags.toml\"]\n".to_string();
    let tags = tag_file.to_string();
    let read = move |p: &Path| -> std::io::Result<String> {
        if p.ends_with("tags.toml") {
            Ok(tags.clone())
        } else {
            Ok(main.clone())
        }
    };
    match gridscada_config::load_with(Path::new("/plant/gridscada.toml"), &read) {
        Ok(p) => p,
        Err(diags) => panic!("bad test plant: {diags:#?}"),
    }
}

/// The tag database the app would build: plant tags plus status tags.
pub fn tagdb(plant: &Plant) -> Arc<TagDb> {
    let mut metas: Vec<TagMeta> = plant
        .tags
        .iter()
        .map(|t| {
            TagMeta::new(t.name.get_ref().as_str(), t.value_kind())
                .units(t.units.clone())
                .writable(*t.writable.get_ref())
        })
        .collect();
    metas.extend(gridscada_field::device_status_tags(plant));
    Arc::new(TagDb::new(metas).expect("tag db"))
}

/// A device section.
pub fn device(name: &str, addr: SocketAddr, unit: u8, scan_ms: u64, timeout_ms: u64) -> String {
    format!(
        "[[device]]\nname = \"{name}\"\nprotocol = \"tcp\"\naddress = \"{addr}\"\nunit_id = {unit}\nscan_ms = {scan_ms}\ntimeout_ms = {timeout_ms}\nretries = 1\n\n"
    )
}

/// Waits (polling) until `f` holds, or panics after `within`.
pub async fn eventually(what: &str, within: Duration, mut f: impl FnMut() -> bool) {
    let start = tokio::time::Instant::now();
    while !f() {
        if start.elapsed() > within {
            panic!("timed out after {within:?} waiting for: {what}");
        }
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
}
