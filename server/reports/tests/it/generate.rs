//! A month's report from a real store (SQLite): the value in force before
//! the period is read, the days are added up, an interruption across
//! midnight is one interruption, and days after the last sample are unknown
//! rather than the last value held.

use std::path::Path;
use std::sync::Arc;

use gridscada_reports::{generate, Archive, Period};
use gridscada_store::{HistorySample, OpenOptions, Store};
use gridscada_tagdb::{QualityCode, Timestamp};

const MIN: i64 = 60_000;
const H: i64 = 60 * MIN;

fn at(text: &str) -> i64 {
    Timestamp::parse_utc_text(text).unwrap().as_millis()
}

#[tokio::test]
async fn a_month_joins_days_and_an_interruption_across_midnight() {
    let dir = tempfile::tempdir().unwrap();
    let store = Store::open("sqlite://test.db", &OpenOptions::new(dir.path()))
        .await
        .unwrap();
    a_month(store, dir.path()).await;
}

/// The same on PostgreSQL (`GRIDSCADA_TEST_PG_URL`; required with
/// `GRIDSCADA_REQUIRE_PG=1`), in a schema of its own.
#[tokio::test]
async fn a_month_on_postgres() {
    let url = match std::env::var("GRIDSCADA_TEST_PG_URL") {
        Ok(u) if !u.is_empty() => u,
        _ => {
            assert_ne!(
                std::env::var("GRIDSCADA_REQUIRE_PG").as_deref(),
                Ok("1"),
                "GRIDSCADA_REQUIRE_PG=1 but GRIDSCADA_TEST_PG_URL is not set"
            );
            eprintln!("SKIPPED the PostgreSQL variant: GRIDSCADA_TEST_PG_URL is not set");
            return;
        }
    };
    let dir = tempfile::tempdir().unwrap();
    let mut opts = OpenOptions::new(dir.path());
    opts.pg_schema = Some(format!("gs_reports_{}", std::process::id()));
    let schema = opts.pg_schema.clone().unwrap();
    let store = Store::open(&url, &opts).await.unwrap();
    a_month(store, dir.path()).await;
    // With psql, the real client: this crate speaks no SQL.
    let out = std::process::Command::new("psql")
        .arg(&url)
        .args([
            "-q",
            "-c",
            &format!("DROP SCHEMA IF EXISTS {schema} CASCADE"),
        ])
        .output();
    if !out.as_ref().is_ok_and(|o| o.status.success()) {
        eprintln!("test schema {schema} not dropped: {out:?}");
    }
}

async fn a_month(store: Store, dir: &Path) {
    let plant = gridscada_config::load_path(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/plants/three-panels"),
    )
    .unwrap();
    store.migrate().await.unwrap();

    // Panel pa: 4 kW on zone 1, 6 kW on zone 2; zone 2 out from 22:00 on
    // the 1st to 02:00 on the 2nd. Logged every minute from an hour before
    // the month to 23:59 on the 2nd; nothing after.
    let start = at("2024-03-01T00:00:00Z");
    let (out_from, out_to) = (start + 22 * H, start + 26 * H);
    let last = start + 48 * H - MIN;
    let mut rows = Vec::new();
    let mut t = start - H;
    while t <= last {
        let out = (out_from..out_to).contains(&t);
        for (tag, v) in [
            ("PA.PA.P_kW", if out { 4.0 } else { 10.0 }),
            ("PA.ELCB.Closed", 1.0),
            ("PA.MCCB.Closed", 1.0),
            ("PA.Zone1.Closed", 1.0),
            ("PA.Zone2.Closed", if out { 0.0 } else { 1.0 }),
        ] {
            rows.push(HistorySample {
                tag: Arc::from(tag),
                ts: Timestamp::from_millis(t),
                value: Some(v),
                exact: None,
                quality: QualityCode::Good,
            });
        }
        t += MIN;
    }
    store.insert_samples(&rows).await.unwrap();

    let march = Period::parse("2024-03").unwrap();
    let r = generate(
        &store,
        &plant,
        march,
        Timestamp::from_millis(at("2024-04-02T00:00:00Z")),
    )
    .await
    .unwrap();
    assert_eq!((r.from, r.to), (start, at("2024-04-01T00:00:00Z")));
    let pa = &r.energy.panels[0];
    // 10 kW over the 48 h less the last minute, less 6 kW for 4 h.
    let want = 10.0 * (48.0 - 1.0 / 60.0) - 24.0;
    assert!(
        (pa.kwh.unwrap() - want).abs() < 1e-6,
        "{:?} vs {want}",
        pa.kwh
    );
    let known_share = (48.0 - 1.0 / 60.0) / (31.0 * 24.0);
    assert!((pa.coverage - known_share).abs() < 1e-9, "{}", pa.coverage);

    let ints: Vec<_> = r
        .outages
        .interruptions
        .iter()
        .filter(|i| i.panel == "pa")
        .collect();
    assert_eq!(ints.len(), 1, "{ints:#?}");
    let i = ints[0];
    assert_eq!(
        (i.zone, i.start, i.end, i.began_before),
        (2, out_from, Some(out_to), false)
    );
    assert!((i.duration_s - 4.0 * 3600.0).abs() < 1e-9);
    assert!((i.ens_kwh.unwrap() - 24.0).abs() < 1e-6, "{:?}", i.ens_kwh);
    let rel = &r.outages.panels[0];
    assert_eq!((rel.sustained, rel.momentary), (1, 0));
    assert!((rel.saifi - 0.5).abs() < 1e-12 && (rel.saidi_min - 120.0).abs() < 1e-9);
    assert!(!r.is_empty());

    // Saved and listed; its CSV and page carry the figures.
    let archive = Archive::in_data_dir(dir);
    archive.save(&r).unwrap();
    assert_eq!(archive.list().unwrap()[0].id, "2024-03");
    let csv = std::fs::read_to_string(archive.path(march, "csv")).unwrap();
    assert!(
        csv.contains("interruption,pa.zone2,duration,14400.0000,s\n"),
        "{csv}"
    );
    let html = std::fs::read_to_string(archive.path(march, "html")).unwrap();
    assert!(html.contains("<title>Monthly report 2024-03"));
    // The interruption names its panel as the reliability table does: by name, then id.
    let named = format!("<tr><td>{} (pa)</td><td class=\"n\">2</td>", rel.name);
    assert!(html.contains(&named), "{named} not in the page");

    // A day with nothing recorded is empty, and the schedule makes nothing of it.
    let later = Period::parse("2024-03-20").unwrap();
    let r = generate(
        &store,
        &plant,
        later,
        Timestamp::from_millis(at("2024-04-02T00:00:00Z")),
    )
    .await
    .unwrap();
    assert!(r.is_empty());
    store.close().await;
}
