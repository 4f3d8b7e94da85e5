//! Communication faults and protocol robustness, seen by a Modbus client.

use crate::common;

use std::time::Duration;

use common::*;
use gridscada_sim::ExceptionCode;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;
use tokio::time::timeout;
use tokio_modbus::client::{Reader, Writer};
use tokio_modbus::slave::SlaveContext;
use tokio_modbus::Slave;

const WALL_TIMEOUT: Duration = Duration::from_millis(300);

#[tokio::test]
async fn offline_unit_times_out_while_the_others_on_its_gateway_answer() {
    let rig = rig(1.0).await;
    let h = rig.sim.handle();
    h.set_device_offline("SS1.IO2", true).unwrap();
    // One connection to the gateway, switching unit ids as a poller does.
    let mut c = rig.client("SS1.IO1").await;
    c.set_slave(Slave(2));
    assert!(timeout(WALL_TIMEOUT, c.read_discrete_inputs(0, 4))
        .await
        .is_err());
    let mut c = rig.client("SS1.IO1").await;
    for unit in [1u8, 3, 4] {
        c.set_slave(Slave(unit));
        let r = timeout(WALL_TIMEOUT, c.read_coils(0, 1)).await;
        let r = if unit == 4 {
            timeout(WALL_TIMEOUT, c.read_input_registers(0, 2))
                .await
                .map(|r| r.map(|_| ()))
        } else {
            r.map(|r| r.map(|_| ()))
        };
        assert!(matches!(r, Ok(Ok(()))), "unit {unit}: {r:?}");
    }
    assert!(h
        .snapshot()
        .devices
        .iter()
        .any(|d| d.name == "SS1.IO2" && d.offline));
    h.set_device_offline("SS1.IO2", false).unwrap();
    let mut c = rig.client("SS1.IO2").await;
    assert!(c.read_discrete_inputs(0, 4).await.unwrap().is_ok());
    // Unknown targets are named in the error.
    let e = h.set_device_offline("SS7.IO1", true).unwrap_err();
    assert!(e.to_string().contains("SS7.IO1"));
}

#[tokio::test]
async fn injected_exception_answers_every_request() {
    let rig = rig(1.0).await;
    let h = rig.sim.handle();
    h.set_exception("SS1.PA", Some(ExceptionCode::ServerDeviceBusy))
        .unwrap();
    let mut c = rig.client("SS1.PA").await;
    assert_eq!(
        c.read_input_registers(0, 2).await.unwrap(),
        Err(ExceptionCode::ServerDeviceBusy)
    );
    // Other devices on the gateway are unaffected.
    c.set_slave(Slave(1));
    assert!(c.read_coils(0, 2).await.unwrap().is_ok());
    h.set_exception("SS1.PA", None).unwrap();
    c.set_slave(Slave(4));
    assert!(c.read_input_registers(0, 2).await.unwrap().is_ok());
}

#[tokio::test]
async fn corrupted_frames_are_rejected_by_the_client() {
    let rig = rig(1.0).await;
    let h = rig.sim.handle();
    h.set_corrupt_frames("MG.PV1", true).unwrap();
    for _ in 0..3 {
        let mut c = rig.client("MG.PV1").await;
        let r = timeout(WALL_TIMEOUT, c.read_input_registers(0, 2)).await;
        assert!(
            matches!(r, Ok(Err(_))),
            "expected a protocol error, got {r:?}"
        );
    }
    h.set_corrupt_frames("MG.PV1", false).unwrap();
    let mut c = rig.client("MG.PV1").await;
    assert!(c.read_input_registers(0, 2).await.unwrap().is_ok());
}

#[tokio::test]
async fn slow_replies_arrive_late() {
    let rig = rig(1.0).await;
    let h = rig.sim.handle();
    h.set_slow_replies("MG.Load", Some(Duration::from_millis(400)))
        .unwrap();
    let mut c = rig.client("MG.Load").await;
    assert!(
        timeout(Duration::from_millis(150), c.read_input_registers(0, 2))
            .await
            .is_err()
    );
    let mut c = rig.client("MG.Load").await;
    assert!(
        timeout(Duration::from_secs(5), c.read_input_registers(0, 2))
            .await
            .is_ok()
    );
}

#[tokio::test]
async fn protocol_errors_get_exceptions_not_panics() {
    let rig = rig(1.0).await;
    let mut c = rig.client("SS1.PA").await;
    // Out of range, zero and oversized quantities, unknown unit, bad function.
    assert_eq!(
        c.read_input_registers(20, 4).await.unwrap(),
        Err(ExceptionCode::IllegalDataAddress)
    );
    assert_eq!(
        c.read_holding_registers(0, 1).await.unwrap(),
        Err(ExceptionCode::IllegalDataAddress)
    );
    assert_eq!(
        c.read_input_registers(0, 0).await.unwrap(),
        Err(ExceptionCode::IllegalDataValue)
    );
    assert_eq!(
        c.read_input_registers(0, 126).await.unwrap(),
        Err(ExceptionCode::IllegalDataValue)
    );
    assert_eq!(
        c.write_single_register(0, 1).await.unwrap(),
        Err(ExceptionCode::IllegalDataAddress)
    );
    c.set_slave(Slave(9));
    assert_eq!(
        c.read_coils(0, 1).await.unwrap(),
        Err(ExceptionCode::GatewayTargetDevice)
    );
    // Holding registers that carry no writable tag refuse writes.
    let mut pv = rig.client("MG.PV1").await;
    assert_eq!(
        pv.write_multiple_registers(0, &[0x7fc0, 0]).await.unwrap(),
        Err(ExceptionCode::IllegalDataValue),
        "NaN setpoint"
    );
    assert_eq!(
        pv.write_single_register(2, 1).await.unwrap(),
        Err(ExceptionCode::IllegalDataAddress)
    );

    // Raw frames the decoder would choke on: write multiple registers with
    // quantity 0x8000, and write single coil with value 0x1234.
    let (addr, _) = rig.addr_of("SS1.IO3");
    let mut s = TcpStream::connect(addr).await.unwrap();
    for (req, fc) in [
        (vec![0, 1, 0, 0, 0, 8, 3, 0x10, 0, 0, 0x80, 0, 0, 0], 0x90u8),
        (vec![0, 2, 0, 0, 0, 6, 3, 0x05, 0, 0, 0x12, 0x34], 0x85),
    ] {
        s.write_all(&req).await.unwrap();
        let mut resp = [0u8; 9];
        timeout(Duration::from_secs(2), s.read_exact(&mut resp))
            .await
            .unwrap()
            .unwrap();
        assert_eq!(resp[..2], req[..2]);
        assert_eq!((resp[7], resp[8]), (fc, 0x03));
    }
    // The connection still serves a good request afterwards.
    s.write_all(&[0, 3, 0, 0, 0, 6, 3, 0x01, 0, 0, 0, 13])
        .await
        .unwrap();
    let mut resp = [0u8; 11];
    timeout(Duration::from_secs(2), s.read_exact(&mut resp))
        .await
        .unwrap()
        .unwrap();
    assert_eq!((resp[7], resp[8]), (0x01, 2));

    // Garbage that is not Modbus TCP closes the connection; the server lives on.
    let mut g = TcpStream::connect(addr).await.unwrap();
    g.write_all(&[0xff; 32]).await.unwrap();
    let mut buf = [0u8; 8];
    let n = timeout(Duration::from_secs(2), g.read(&mut buf))
        .await
        .unwrap();
    assert!(matches!(n, Ok(0) | Err(_)));
    let mut c = rig.client("SS1.IO3").await;
    assert!(c.read_coils(0, 4).await.unwrap().is_ok());
}

/// A replay's pipes answer with the very frames the TCP server sends:
/// the same requests (reads, a write, a malformed one, an unknown unit, a
/// corrupted reply, an offline device) to two simulators of the same plant
/// on frozen clocks, one over loopback TCP, one over the switchboard.
#[tokio::test]
async fn in_process_pipes_answer_with_the_same_frames_as_tcp() {
    use gridscada_sim::BindMode;
    use gridscada_tagdb::{ScaledClock, Timestamp};
    use std::sync::Arc;

    let plant = demo_plant();
    let frozen = || Arc::new(ScaledClock::new(Timestamp::from_millis(NOON), 1e-9));
    let tcp_sim = gridscada_sim::start(&plant, frozen(), BindMode::Ephemeral)
        .await
        .unwrap();
    let board = Arc::new(gridscada_field::Switchboard::new());
    let pipe_sim = gridscada_sim::start(&plant, frozen(), BindMode::InProcess(board.clone()))
        .await
        .unwrap();
    // The pipe simulator binds no Modbus socket.
    assert!(pipe_sim.addresses().len() < tcp_sim.addresses().len());
    for sim in [&tcp_sim, &pipe_sim] {
        let h = sim.handle();
        h.set_corrupt_frames("SS1.IO3", true).unwrap();
        h.set_device_offline("SS1.IO2", true).unwrap();
    }

    let gateway = plant
        .device("SS1.IO1")
        .unwrap()
        .address
        .as_ref()
        .unwrap()
        .get_ref()
        .clone();
    let analyzer = plant.device("SS1.PA").map(|d| *d.unit_id.get_ref());
    let mut requests: Vec<(u8, Vec<u8>)> = vec![
        (1, vec![0x01, 0, 0, 0, 9]),       // read coils
        (1, vec![0x02, 0, 0, 0, 8]),       // read discrete inputs
        (1, vec![0x05, 0, 1, 0xFF, 0]),    // write single coil
        (1, vec![0x01, 0, 0, 0, 9]),       // and read it back
        (1, vec![0x05, 0, 0, 0x12, 0x34]), // malformed: answered by the link
        (42, vec![0x03, 0, 0, 0, 1]),      // a unit the gateway does not have
        (3, vec![0x01, 0, 0, 0, 4]),       // a corrupted reply
        (3, vec![0x01, 0, 0, 0, 4]),       // and the next kind of corruption
        (1, vec![0x2B, 0x0E, 1, 0]),       // a function the devices lack
    ];
    if let Some(unit) = analyzer {
        requests.push((unit, vec![0x04, 0, 0, 0, 10]));
    }

    let mut over_tcp = TcpStream::connect(tcp_sim.addresses()[&gateway])
        .await
        .unwrap();
    let mut over_pipe = board.dial(&gateway).expect("served in process").unwrap();
    for (tid, (unit, pdu)) in requests.iter().enumerate() {
        let mut adu = vec![0, tid as u8, 0, 0, 0, pdu.len() as u8 + 1, *unit];
        adu.extend_from_slice(pdu);
        over_tcp.write_all(&adu).await.unwrap();
        over_pipe.write_all(&adu).await.unwrap();
        let a = read_adu(&mut over_tcp).await;
        let b = read_adu(&mut over_pipe).await;
        assert_eq!(a, b, "request {adu:02x?}");
    }
    // An offline device answers neither way.
    let adu = [0, 99, 0, 0, 0, 6, 2, 0x02, 0, 0, 0, 4];
    over_tcp.write_all(&adu).await.unwrap();
    over_pipe.write_all(&adu).await.unwrap();
    let mut buf = [0u8; 16];
    assert!(timeout(WALL_TIMEOUT, over_tcp.read(&mut buf))
        .await
        .is_err());
    assert!(timeout(WALL_TIMEOUT, over_pipe.read(&mut buf))
        .await
        .is_err());
    // After the simulator stops, a dial is refused.
    pipe_sim.shutdown().await;
    drop(over_pipe);
    assert!(board.dial(&gateway).unwrap().is_err());
}

/// One Modbus TCP frame, whole.
async fn read_adu<S: tokio::io::AsyncRead + Unpin>(s: &mut S) -> Vec<u8> {
    let mut head = [0u8; 6];
    timeout(Duration::from_secs(5), s.read_exact(&mut head))
        .await
        .expect("an answer")
        .unwrap();
    let len = usize::from(u16::from_be_bytes([head[4], head[5]]));
    let mut rest = vec![0u8; len];
    s.read_exact(&mut rest).await.unwrap();
    let mut all = head.to_vec();
    all.extend(rest);
    all
}
