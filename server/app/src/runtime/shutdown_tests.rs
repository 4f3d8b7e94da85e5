//! An orderly shutdown of the stack loses no historian sample and reports no
//! false overflow, even while tag changes keep coming (issue 14: the feed
//! used to outlive the historian's writer and offer samples to a stopped
//! writer: "overflow … dropped=1 why=writer stopped" while the figure said 0).

use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use gridscada_config::Plant;
use gridscada_tagdb::{Clock, Sample, SystemClock, Timestamp};

use super::{Stack, StackOptions};
use crate::data::open_store;

/// One simulated device with one logged tag `T` (every change logged),
/// read once at start (a long scan), so the test's own writes are its
/// only changes afterwards.
fn plant() -> Plant {
    let main = "tag_files = [\"t.toml\"]\n";
    let tags = r#"
[[device]]
name = "D"
protocol = "tcp"
address = "127.0.0.1:1502"
scan_ms = 3600000
timeout_ms = 500

[[tag]]
name = "T"
device = "D"
kind = "holding_register"
address = 0
type = "f32"
history = { deadband = 0.0 }
"#;
    gridscada_config::load_with(Path::new("/plant/gridscada.toml"), &|p: &Path| {
        Ok(if p.ends_with("gridscada.toml") {
            main.to_string()
        } else {
            tags.to_string()
        })
    })
    .unwrap_or_else(|d| panic!("test plant does not load: {d:?}"))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn orderly_shutdown_writes_every_sample_offered_and_drops_none() {
    let dir = tempfile::tempdir().unwrap();
    let plant = plant();
    let store = open_store(&plant, dir.path()).await.unwrap();
    let clock: Arc<dyn Clock> = Arc::new(SystemClock);
    let stack = Stack::start(
        plant.clone(),
        store,
        StackOptions {
            clock: clock.clone(),
            simulate: true,
            real_devices: Vec::new(),
            simulator_pipes: false,
            dispatch_policy: Default::default(),
            restore_panels: false,
            data_dir: dir.path().to_path_buf(),
            notify: false,
        },
    )
    .await
    .unwrap();
    let db = stack.db.clone();
    let id = db.id("T").unwrap();
    // The poller's first read of T, then only ours.
    let deadline = std::time::Instant::now() + Duration::from_secs(20);
    while !db.get(id).is_some_and(|s| s.quality.is_good()) {
        assert!(std::time::Instant::now() < deadline, "T never read");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    // A producer that keeps changing T through the shutdown and after it.
    let published = Arc::new(AtomicU64::new(0));
    let producer = {
        let (db, published, clock) = (db.clone(), published.clone(), clock.clone());
        // One millisecond apart each (the historian keeps one row per tag
        // and time stamp).
        let start = clock.now();
        tokio::spawn(async move {
            for v in 1u64.. {
                let ts = start.add(Duration::from_millis(v));
                db.apply([(id, Sample::good(v as f64, ts))]);
                published.store(v, Ordering::SeqCst);
                tokio::time::sleep(Duration::from_millis(2)).await;
            }
        })
    };
    tokio::time::sleep(Duration::from_millis(400)).await;
    let before = published.load(Ordering::SeqCst);
    let m = stack.shutdown().await;
    let after = published.load(Ordering::SeqCst);
    producer.abort();
    assert_eq!(m.dropped, 0, "{m:?}");
    assert!(!m.overflow, "{m:?}");
    assert!(after > before, "the producer ran through the shutdown");

    // Every value up to the moment the feed stopped is in the store, in
    // order, without a gap, and nothing else was written.
    let store = open_store(&plant, dir.path()).await.unwrap();
    let rows = store
        .raw_samples(
            &["T"],
            Timestamp::from_millis(0),
            clock.now().add(Duration::from_secs(3600)),
            1_000_000,
        )
        .await
        .unwrap();
    store.close().await;
    assert_eq!(rows.len() as u64, m.samples_written, "{m:?}");
    let ours: Vec<u64> = rows
        .iter()
        .filter_map(|r| r.value)
        .filter(|v| *v >= 1.0)
        .map(|v| v as u64)
        .collect();
    let k = ours.len() as u64;
    assert!(
        k >= before,
        "{k} written, {before} published before the shutdown"
    );
    assert_eq!(
        ours,
        (1..=k).collect::<Vec<_>>(),
        "a gap in what was written"
    );
}
