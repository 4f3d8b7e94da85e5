//! An outstation whose analog inputs change at a fixed rate: the event
//! source of the DNP3 event benchmark (`scripts/bench-telecontrol.py`), so
//! gridscada's master and a peer master are fed the same stream, from a
//! source that is not the bottleneck. Not part of gridscada's runtime.
//!
//! cargo run --release -p gridscada-dnp3 --example dnp3_event_source -- PORT \
//!     [--points 1000] [--rate 2000] [--outstation 10]
//!
//! Prints `LISTENING` once it listens, then `GENERATED N` (changes made so
//! far) every second; each change is one analog event (no deadband).

use std::sync::Arc;
use std::time::Duration;

use gridscada_dnp3::objects::MeasurementKind;
use gridscada_dnp3::outstation::{OutstationConfig, Point};
use gridscada_dnp3::server::{Dnp3Outstation, ServedDatabase, ServedPoint};
use gridscada_tagdb::{
    Sample, TagDb, TagMeta, TagWriter, Timestamp, Value, ValueKind, WriteError, WriteFuture,
};

/// The source has no controls.
struct NoControls;

impl TagWriter for NoControls {
    fn write<'a>(&'a self, name: &'a str, _value: Value) -> WriteFuture<'a> {
        Box::pin(async move {
            Err(WriteError::Device {
                device: "event source".into(),
                reason: format!("{name} has no control"),
            })
        })
    }
}

#[tokio::main(flavor = "current_thread")]
async fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let port: u16 = args
        .first()
        .and_then(|p| p.parse().ok())
        .expect("usage: dnp3_event_source PORT [--points N] [--rate R] [--outstation A]");
    let num = |name: &str, default: u64| {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1))
            .map_or(default, |v| v.parse().expect("a number"))
    };
    let points = num("--points", 1000) as usize;
    let rate = num("--rate", 2000);
    let db = Arc::new(
        TagDb::new((0..points).map(|i| TagMeta::new(format!("A{i}"), ValueKind::Float)))
            .expect("distinct names"),
    );
    let served = ServedDatabase {
        points: (0..points)
            .map(|i| ServedPoint {
                id: db.id(&format!("A{i}")).expect("registered"),
                point: Point {
                    kind: MeasurementKind::Analog,
                    index: i as u16,
                    integer: false,
                },
            })
            .collect(),
        ..ServedDatabase::default()
    };
    let ids: Vec<_> = served.points.iter().map(|p| p.id).collect();
    db.apply(
        ids.iter()
            .map(|&id| (id, Sample::good(0.0, Timestamp::now_utc()))),
    );
    let listener = tokio::net::TcpListener::bind(("127.0.0.1", port))
        .await
        .expect("the port is free");
    let _outstation = Dnp3Outstation::start_on(
        listener,
        OutstationConfig {
            address: num("--outstation", 10) as u16,
            ..OutstationConfig::default()
        },
        served,
        Arc::clone(&db),
        Arc::new(NoControls),
    );
    println!("LISTENING");
    // Changes in 10-ms batches, round-robin over the points, each value new.
    let start = tokio::time::Instant::now();
    let mut tick = tokio::time::interval(Duration::from_millis(10));
    let mut made: u64 = 0;
    let mut next_report = 1u64;
    loop {
        tick.tick().await;
        let elapsed = start.elapsed();
        let due = (elapsed.as_secs_f64() * rate as f64) as u64;
        let now = Timestamp::now_utc();
        let batch: Vec<_> = (made..due)
            .map(|n| {
                (
                    ids[(n as usize) % points],
                    Sample::good(n as f64 + 1.0, now),
                )
            })
            .collect();
        db.apply(batch);
        made = due;
        if elapsed.as_secs() >= next_report {
            next_report = elapsed.as_secs() + 1;
            println!("GENERATED {made}");
        }
    }
}
