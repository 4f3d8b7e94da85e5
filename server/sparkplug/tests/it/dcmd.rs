//! DCMDs through a real broker (Debian's mosquitto) to a running edge node:
//! what each refusal is on record as, and how it is counted. A write the
//! server refuses before it reaches the device (outside the node's area,
//! above its role, outside the tag's engineering limits) is `write_refused`
//! and counted `refused`; only what the device or link failed is
//! `write_failed` (issue 36 #5 and #11). Skipped (with a note) where
//! mosquitto is not installed; `scripts/test-all.sh` installs it.

use std::future::Future;
use std::path::{Path, PathBuf};
use std::pin::Pin;
use std::sync::Arc;
use std::time::{Duration, Instant};

use gridscada_sparkplug::edge::{EdgeContext, EdgeMetrics, EdgeNode};
use gridscada_sparkplug::proto::{Metric, MetricValue, Payload};
use gridscada_store::command::CommandAudit;
use gridscada_store::NewEvent;
use gridscada_tagdb::{
    Sample, SystemClock, TagDb, TagWriter, Timestamp, Value, WriteError, WriteFuture,
};
use parking_lot::Mutex;
use prost::Message;
use rumqttc::{AsyncClient, MqttOptions, QoS};

fn mosquitto() -> Option<PathBuf> {
    ["/usr/sbin/mosquitto", "/usr/bin/mosquitto"]
        .into_iter()
        .map(PathBuf::from)
        .find(|p| p.exists())
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// One device, a setpoint the node may command (0 to 100), a coil it may
/// not (not in `commands`), a supervisor's setpoint above its operator role.
fn plant(dir: &Path, port: u16) -> gridscada_config::Plant {
    let main = format!(
        r#"tag_files = ["t.toml"]
[mqtt]
broker = "mqtt://127.0.0.1:{port}"
group = "G"
keep_alive_s = 5
[mqtt.edge]
node = "n1"
batch_ms = 20
commands = ["D1.Setpoint", "D1.Limit"]
command_role = "operator"
"#
    );
    let tags = r#"
[[device]]
name = "D1"
protocol = "tcp"
address = "127.0.0.1:1502"

[[tag]]
name = "D1.Setpoint"
device = "D1"
kind = "holding_register"
address = 0
type = "f32"
writable = true
write_role = "operator"
min = 0.0
max = 100.0

[[tag]]
name = "D1.Trip"
device = "D1"
kind = "coil"
address = 0
writable = true
write_role = "operator"

[[tag]]
name = "D1.Limit"
device = "D1"
kind = "holding_register"
address = 2
type = "f32"
writable = true
write_role = "supervisor"
"#;
    std::fs::write(dir.join("gridscada.toml"), main).unwrap();
    std::fs::write(dir.join("t.toml"), tags).unwrap();
    gridscada_config::load_path(dir).unwrap_or_else(|d| panic!("{d:?}"))
}

/// Refuses a value outside 0..100 before the "device", as the field writer
/// does with engineering limits; fails a write of 66 as a device would;
/// confirms the rest.
#[derive(Default)]
struct Writer {
    reached: Mutex<Vec<(String, Value)>>,
}

impl TagWriter for Writer {
    fn write<'a>(&'a self, name: &'a str, value: Value) -> WriteFuture<'a> {
        Box::pin(async move {
            let v = value.as_f64().unwrap_or_default();
            if !(0.0..=100.0).contains(&v) {
                return Err(WriteError::OutOfLimits {
                    tag: name.into(),
                    value: value.to_string(),
                    limits: "0 to 100".into(),
                });
            }
            self.reached.lock().push((name.to_string(), value.clone()));
            if v == 66.0 {
                return Err(WriteError::Device {
                    device: "D1".into(),
                    reason: "illegal data value".into(),
                });
            }
            Ok(Sample::good(value, Timestamp::now_utc()))
        })
    }
}

#[derive(Default)]
struct Audit(Mutex<Vec<NewEvent>>);

impl CommandAudit for Audit {
    fn durable(
        &self,
        event: NewEvent,
    ) -> Pin<Box<dyn Future<Output = Result<(), String>> + Send + '_>> {
        self.0.lock().push(event);
        Box::pin(async { Ok(()) })
    }
}

async fn until<T>(what: &str, mut check: impl FnMut() -> Option<T>) -> T {
    let start = Instant::now();
    loop {
        if let Some(t) = check() {
            return t;
        }
        assert!(
            start.elapsed() < Duration::from_secs(10),
            "{what}: not within 10 s"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

fn dcmd(name: &str, value: MetricValue, datatype: u32) -> Vec<u8> {
    Payload {
        timestamp: Some(1),
        metrics: vec![Metric {
            name: Some(name.into()),
            datatype: Some(datatype),
            value: Some(value),
            ..Default::default()
        }],
        seq: Some(0),
        ..Default::default()
    }
    .encode_to_vec()
}

/// Sparkplug B data type codes.
const FLOAT: u32 = 9;
const BOOLEAN: u32 = 11;

#[tokio::test]
async fn refused_dcmds_are_on_record_as_refused_and_failed_ones_as_failed() {
    let Some(bin) = mosquitto() else {
        eprintln!("mosquitto not installed: DCMD test skipped");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let port = free_port();
    let conf = dir.path().join("mosquitto.conf");
    std::fs::write(
        &conf,
        format!("listener {port} 127.0.0.1\nallow_anonymous true\n"),
    )
    .unwrap();
    // The broker goes with the test, also when an assertion fails.
    struct Kill(std::process::Child);
    impl Drop for Kill {
        fn drop(&mut self) {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
    let _broker = Kill(
        std::process::Command::new(bin)
            .arg("-c")
            .arg(&conf)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap(),
    );
    for _ in 0..100 {
        if std::net::TcpStream::connect(("127.0.0.1", port)).is_ok() {
            break;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }

    let plant = Arc::new(plant(dir.path(), port));
    let db = Arc::new(TagDb::new(plant.tag_metas()).unwrap());
    let writer = Arc::new(Writer::default());
    let audit = Arc::new(Audit::default());
    let (events, _events_rx) = tokio::sync::mpsc::channel(64);
    let node = EdgeNode::start(
        EdgeContext {
            plant: plant.clone(),
            db,
            writer: writer.clone(),
            audit: audit.clone(),
            events,
            clock: Arc::new(SystemClock),
        },
        plant.mqtt.as_ref().unwrap(),
        dir.path(),
        dir.path(),
    )
    .unwrap();
    let metrics = node.metrics();
    // Subscribed to its commands before its births go out.
    until("the edge's births", || {
        (EdgeMetrics::get(&metrics.messages_sent) > 0).then_some(())
    })
    .await;

    let (client, mut eventloop) =
        AsyncClient::new(MqttOptions::new("dcmd-test", "127.0.0.1", port), 10);
    tokio::spawn(async move { while eventloop.poll().await.is_ok() {} });
    let topic = "spBv1.0/G/DCMD/n1/D1";
    let send = |payload: Vec<u8>| {
        let client = client.clone();
        async move {
            client
                .publish(topic, QoS::AtLeastOnce, false, payload)
                .await
                .unwrap()
        }
    };
    let records = |kind: &str, tag: &str| -> Vec<String> {
        audit
            .0
            .lock()
            .iter()
            .filter(|e| e.kind == kind && e.source == tag)
            .map(|e| e.message.clone())
            .collect()
    };

    // Outside the node's area: [mqtt.edge] commands does not name it.
    send(dcmd("D1.Trip", MetricValue::Boolean(true), BOOLEAN)).await;
    let m = until("the refused Trip on record", || {
        records("write_refused", "D1.Trip").pop()
    })
    .await;
    assert!(
        m.contains("outside the node's area") && !m.contains("role"),
        "{m}"
    );
    // Within the area, above the node's role.
    send(dcmd("D1.Limit", MetricValue::Float(5.0), FLOAT)).await;
    let m = until("the refused Limit on record", || {
        records("write_refused", "D1.Limit").pop()
    })
    .await;
    assert!(m.contains("role") && !m.contains("area"), "{m}");
    // Outside the setpoint's engineering limits: refused, not failed.
    send(dcmd("D1.Setpoint", MetricValue::Float(250.0), FLOAT)).await;
    let m = until("the out-of-limits Setpoint on record", || {
        records("write_refused", "D1.Setpoint").pop()
    })
    .await;
    assert!(m.contains("engineering limits"), "{m}");
    until("three refusals counted", || {
        (EdgeMetrics::get(&metrics.commands_refused) == 3).then_some(())
    })
    .await;
    // The device fails a write: that one is failed.
    send(dcmd("D1.Setpoint", MetricValue::Float(66.0), FLOAT)).await;
    let m = until("the failed Setpoint on record", || {
        records("write_failed", "D1.Setpoint").pop()
    })
    .await;
    assert!(m.contains("illegal data value"), "{m}");
    // And a good one is written.
    send(dcmd("D1.Setpoint", MetricValue::Float(40.0), FLOAT)).await;
    until("the written Setpoint on record", || {
        records("write", "D1.Setpoint").pop()
    })
    .await;

    assert_eq!(EdgeMetrics::get(&metrics.commands_refused), 3);
    assert_eq!(EdgeMetrics::get(&metrics.commands_failed), 1);
    assert_eq!(EdgeMetrics::get(&metrics.commands_written), 1);
    assert!(records("write_failed", "D1.Trip").is_empty());
    assert_eq!(
        *writer.reached.lock(),
        [
            ("D1.Setpoint".to_string(), Value::Float(66.0)),
            ("D1.Setpoint".to_string(), Value::Float(40.0))
        ]
    );
    node.shutdown().await;
}
