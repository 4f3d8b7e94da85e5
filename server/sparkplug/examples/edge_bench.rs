//! The edge node under load: TAGS float tags on DEVICES devices, every tag
//! changing once a second (applied in ten batches per second, as a poller
//! with many devices would), published through a real broker. Each sample's
//! timestamp is the wall time of its change, so a host measures
//! change-to-receipt latency from the metrics' own timestamps
//! (`scripts/bench-sparkplug.sh` runs it with mosquitto and a Python host).
//!
//! Usage: edge_bench BROKER_URL TAGS DEVICES SECONDS
//! Prints the process's CPU time and peak RSS at the end.

use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant};

#[path = "../tests/it/common/mod.rs"]
mod common;

use common::{NoAudit, NoWrites};
use gridscada_sparkplug::edge::{EdgeContext, EdgeNode};
use gridscada_tagdb::{Quality, Sample, SystemClock, TagDb, TagMeta, Timestamp, ValueKind};

fn proc_figures() -> (f64, u64) {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let fields: Vec<&str> = stat
        .rsplit(')')
        .next()
        .unwrap_or("")
        .split_whitespace()
        .collect();
    let ticks = |i: usize| {
        fields
            .get(i)
            .and_then(|f| f.parse::<f64>().ok())
            .unwrap_or(0.0)
    };
    let cpu = (ticks(11) + ticks(12)) / 100.0;
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    let rss = status
        .lines()
        .find(|l| l.starts_with("VmHWM:"))
        .and_then(|l| l.split_whitespace().nth(1))
        .and_then(|k| k.parse::<u64>().ok())
        .unwrap_or(0);
    (cpu, rss)
}

#[tokio::main]
async fn main() {
    let args: Vec<String> = std::env::args().collect();
    let broker = args
        .get(1)
        .cloned()
        .unwrap_or_else(|| "mqtt://127.0.0.1:1883".into());
    let tags: usize = args.get(2).and_then(|a| a.parse().ok()).unwrap_or(100_000);
    let devices: usize = args.get(3).and_then(|a| a.parse().ok()).unwrap_or(100);
    let seconds: u64 = args.get(4).and_then(|a| a.parse().ok()).unwrap_or(30);
    let per_device = tags / devices;

    let mut tag_file = String::new();
    for d in 0..devices {
        tag_file.push_str(&format!(
            "[[device]]\nname = \"D{d}\"\nprotocol = \"tcp\"\naddress = \"127.0.0.1:{}\"\n\n",
            10_000 + d
        ));
        for t in 0..per_device {
            tag_file.push_str(&format!(
                "[[tag]]\nname = \"D{d}.T{t}\"\ndevice = \"D{d}\"\nkind = \"input_register\"\naddress = {}\ntype = \"f32\"\nunits = \"kW\"\n\n",
                t * 2
            ));
        }
    }
    let main = format!(
        "tag_files = [\"tags.toml\"]\n[mqtt]\nbroker = \"{broker}\"\ngroup = \"bench\"\n[mqtt.edge]\nnode = \"edge1\"\nbuffer_samples = 10000000\n"
    );
    let plant = gridscada_config::load_with(Path::new("/bench/gridscada.toml"), &|p: &Path| {
        Ok(if p.ends_with("tags.toml") {
            tag_file.clone()
        } else {
            main.clone()
        })
    })
    .unwrap_or_else(|d| panic!("{d:?}"));
    let mut metas: Vec<TagMeta> = plant.tag_metas().collect();
    for d in 0..devices {
        metas.push(TagMeta::new(
            format!("D{d}.Comm.Connected"),
            ValueKind::Bool,
        ));
    }
    let db = Arc::new(TagDb::new(metas).unwrap());
    let now = Timestamp::now_utc();
    for d in 0..devices {
        db.set(
            db.id(&format!("D{d}.Comm.Connected")).unwrap(),
            true,
            Quality::GOOD,
            now,
        );
    }
    let ids: Vec<_> = (0..devices * per_device)
        .map(|i| gridscada_tagdb::TagId(i as u32))
        .collect();
    db.apply(ids.iter().map(|id| (*id, Sample::good(0.0, now))));

    let data = tempfile::tempdir().unwrap();
    let (events, mut events_rx) = tokio::sync::mpsc::channel(1024);
    tokio::spawn(async move { while events_rx.recv().await.is_some() {} });
    let mqtt = plant.mqtt.clone().unwrap();
    let ctx = EdgeContext {
        plant: Arc::new(plant),
        db: db.clone(),
        writer: Arc::new(NoWrites),
        audit: Arc::new(NoAudit),
        events,
        clock: Arc::new(SystemClock),
    };
    let edge = EdgeNode::start(ctx, &mqtt, Path::new("/"), data.path()).unwrap();
    let metrics = edge.metrics();

    // Ten batches a second, each a tenth of the tags, each value new.
    let batch = ids.len().div_ceil(10);
    let start = Instant::now();
    let (cpu0, _) = proc_figures();
    let mut round = 0u64;
    let mut tick = tokio::time::interval(Duration::from_millis(100));
    while start.elapsed() < Duration::from_secs(seconds) {
        tick.tick().await;
        let part = (round % 10) as usize;
        let ts = Timestamp::now_utc();
        let value = (round / 10) as f64 + 0.5;
        db.apply(
            ids.iter()
                .skip(part * batch)
                .take(batch)
                .map(|id| (*id, Sample::good(value, ts))),
        );
        round += 1;
    }
    let elapsed = start.elapsed().as_secs_f64();
    let (cpu1, rss) = proc_figures();
    use gridscada_sparkplug::edge::EdgeMetrics as M;
    println!(
        "tags {} devices {devices} seconds {elapsed:.1}: cpu {:.1} % of one core, peak RSS {} MiB, messages {}, bytes {}, dropped {}",
        ids.len(),
        (cpu1 - cpu0) / elapsed * 100.0,
        rss / 1024,
        M::get(&metrics.messages_sent),
        M::get(&metrics.bytes_sent),
        M::get(&metrics.dropped),
    );
    edge.shutdown().await;
}
