//! The RTU poller over a pseudo-terminal pair, against tokio-modbus's RTU
//! server on the other end. Skipped (with a note) where no pty can be opened.

use crate::common;

use std::sync::Arc;
use std::time::Duration;

use common::*;
use gridscada_modbus::FieldIo;
use gridscada_tagdb::{SystemClock, Value};
use tokio_serial::SerialPort;

#[tokio::test]
async fn rtu_reads_and_writes_over_a_pty() {
    let (master, mut slave) = match tokio_serial::SerialStream::pair() {
        Ok(p) => p,
        Err(e) => {
            eprintln!("skipped: no pseudo-terminal available: {e}");
            return;
        }
    };
    let Some(path) = slave.name() else {
        eprintln!("skipped: the pseudo-terminal has no name");
        return;
    };
    // Let the poller open the slave end by its path.
    let _ = slave.set_exclusive(false);
    drop(slave);

    let bank = Bank::with_units(&[7]);
    bank.unit(7, |u| {
        u.holding[10] = 1234;
        u.input[0] = 0x4366; // 230.0 as f32
        u.input[1] = 0;
    });
    let server = tokio_modbus::server::rtu::Server::new(master);
    let svc = Svc(Arc::clone(&bank));
    let _server = tokio::spawn(async move { server.serve_forever(svc).await });

    let text = format!(
        "[[device]]\nname = \"M\"\nprotocol = \"rtu\"\nunit_id = 7\nscan_ms = 100\ntimeout_ms = 300\n\
         [device.serial]\nport = \"{path}\"\nbaud = 115200\n\n\
         [[tag]]\nname = \"M.Setpoint\"\ndevice = \"M\"\nkind = \"holding_register\"\naddress = 10\n\
         writable = true\nwrite_role = \"operator\"\n\n\
         [[tag]]\nname = \"M.V\"\ndevice = \"M\"\nkind = \"input_register\"\naddress = 0\ntype = \"f32\"\n"
    );
    let plant = plant(&text);
    let db = tagdb(&plant);
    let io = FieldIo::start(&plant, Arc::clone(&db), Arc::new(SystemClock)).unwrap();
    let good = |name: &str| {
        db.get_by_name(name)
            .filter(|s| s.quality.is_good())
            .map(|s| s.value)
    };
    eventually("rtu values", Duration::from_secs(10), || {
        good("M.Setpoint") == Some(Value::Int(1234)) && good("M.V") == Some(Value::Float(230.0))
    })
    .await;
    let s = io
        .writer()
        .write("M.Setpoint", Value::Int(4321))
        .await
        .unwrap();
    assert_eq!(s.value, Value::Int(4321));
    assert_eq!(bank.unit(7, |u| u.holding[10]), 4321);
    io.shutdown().await;
}
