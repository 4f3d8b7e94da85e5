//! Store behaviour on both backends.

use crate::common;

use std::collections::HashMap;
use std::sync::Arc;
use std::time::Duration;

use common::TestDb;
use gridscada_config::Role;
use gridscada_store::*;
use gridscada_tagdb::{QualityCode, Timestamp};

fn ts(ms: i64) -> Timestamp {
    Timestamp::from_millis(ms)
}

fn sample(tag: &str, ms: i64, v: Option<f64>, q: QualityCode) -> HistorySample {
    HistorySample {
        tag: Arc::from(tag),
        ts: ts(ms),
        value: v,
        exact: None,
        quality: q,
    }
}

async fn migrations_are_idempotent(mut db: TestDb) {
    db.store.migrate().await.unwrap();
    db.store.migrate().await.unwrap();
    db.store
        .insert_samples(&[sample("T", 1, Some(1.0), QualityCode::Good)])
        .await
        .unwrap();
    db.reopen().await; // open runs the migrations again
    db.store.migrate().await.unwrap();
    let rows = db
        .store
        .raw_samples(&["T"], ts(0), ts(10), 10)
        .await
        .unwrap();
    assert_eq!(rows.len(), 1, "data survives re-running migrations");
    db.cleanup().await;
}
both_backends!(migrations, migrations_are_idempotent);

async fn trend_buckets_are_exact(db: TestDb) {
    let s = &db.store;
    let t0 = 1_700_000_000_000i64;
    // A: 100 samples, 1 s apart, value = i. 10 buckets of 10 samples each.
    let a: Vec<_> = (0..100)
        .map(|i| {
            sample(
                "SS1.Zone1.V",
                t0 + i * 1000,
                Some(i as f64),
                QualityCode::Good,
            )
        })
        .collect();
    // B: a gap (buckets 2..=7 empty), a sample without value, a bad last sample.
    let mut b: Vec<_> = (0..20)
        .map(|i| {
            sample(
                "SS1.Zone1.I",
                t0 + i * 1000,
                Some(-(i as f64)),
                QualityCode::Good,
            )
        })
        .collect();
    b.push(sample("SS1.Zone1.I", t0 + 85_000, None, QualityCode::Good));
    b.push(sample(
        "SS1.Zone1.I",
        t0 + 86_000,
        Some(7.5),
        QualityCode::Bad,
    ));
    // C: 2,500 rows in one call (several statements on SQLite).
    let c: Vec<_> = (0..2500)
        .map(|i| sample("C", t0 + i * 40, Some(1.0), QualityCode::Good))
        .collect();
    assert_eq!(s.insert_samples(&a).await.unwrap(), 100);
    s.insert_samples(&b).await.unwrap();
    assert_eq!(s.insert_samples(&c).await.unwrap(), 2500);
    // A duplicate (tag, ts) replaces the earlier row, within and across batches.
    s.insert_samples(&[
        sample("SS1.Zone1.V", t0 + 99_000, Some(500.0), QualityCode::Good),
        sample("SS1.Zone1.V", t0 + 99_000, Some(99.0), QualityCode::Good),
    ])
    .await
    .unwrap();

    let trends = s
        .trend(
            &["SS1.Zone1.V", "SS1.Zone1.I", "nope", "C"],
            ts(t0),
            ts(t0 + 100_000),
            10,
        )
        .await
        .unwrap();
    assert_eq!(trends.len(), 4);
    let va = &trends[0];
    assert_eq!(va.tag, "SS1.Zone1.V");
    assert_eq!(va.buckets.len(), 10);
    for (k, bk) in va.buckets.iter().enumerate() {
        let k = k as i64;
        assert_eq!(bk.index, k as u32);
        assert_eq!(bk.start, ts(t0 + k * 10_000));
        assert_eq!(bk.end, ts(t0 + (k + 1) * 10_000));
        assert_eq!(bk.count, 10);
        assert_eq!(bk.min, Some((10 * k) as f64));
        assert_eq!(bk.max, Some((10 * k + 9) as f64));
        assert_eq!(bk.avg, Some(10.0 * k as f64 + 4.5));
        assert_eq!(bk.last, Some((10 * k + 9) as f64));
        assert_eq!(bk.last_ts, ts(t0 + (10 * k + 9) * 1000));
        assert_eq!(bk.last_quality, QualityCode::Good);
    }
    let ib = &trends[1];
    let idx: Vec<u32> = ib.buckets.iter().map(|b| b.index).collect();
    assert_eq!(idx, vec![0, 1, 8], "empty buckets are not returned");
    assert_eq!(ib.buckets[0].min, Some(-9.0));
    assert_eq!(ib.buckets[0].max, Some(0.0));
    assert_eq!(ib.buckets[0].avg, Some(-4.5));
    let last = &ib.buckets[2];
    assert_eq!(last.count, 2, "a sample without value still counts");
    assert_eq!(
        (last.min, last.max, last.avg),
        (Some(7.5), Some(7.5), Some(7.5))
    );
    assert_eq!(last.last, Some(7.5));
    assert_eq!(last.last_quality, QualityCode::Bad);
    assert!(trends[2].buckets.is_empty(), "unknown tag has no data");
    let cc = &trends[3];
    assert_eq!(cc.buckets.iter().map(|b| b.count).sum::<u64>(), 2500);

    // Range bounds: from inclusive, to exclusive; uneven bucket widths are fine.
    let t = s
        .trend(&["SS1.Zone1.V"], ts(t0 + 5_000), ts(t0 + 12_000), 3)
        .await
        .unwrap();
    let counts: Vec<u64> = t[0].buckets.iter().map(|b| b.count).collect();
    assert_eq!(counts.iter().sum::<u64>(), 7); // 5..=11
    assert_eq!(t[0].buckets[0].min, Some(5.0));
    assert_eq!(t[0].buckets.last().unwrap().last, Some(11.0));

    assert!(matches!(
        s.trend(&["SS1.Zone1.V"], ts(t0), ts(t0), 10).await,
        Err(StoreError::Invalid(_))
    ));
    assert!(matches!(
        s.trend(&["SS1.Zone1.V"], ts(t0), ts(t0 + 1), 0).await,
        Err(StoreError::Invalid(_))
    ));
    assert!(matches!(
        s.insert_samples(&[sample("", 0, None, QualityCode::Good)])
            .await,
        Err(StoreError::Invalid(_))
    ));
    db.cleanup().await;
}
both_backends!(trend, trend_buckets_are_exact);

async fn csv_export_and_raw(db: TestDb) {
    let s = &db.store;
    s.insert_samples(&[
        sample("P1,kW", 1000, Some(1.5), QualityCode::Good),
        sample("Q", 1000, None, QualityCode::Bad),
        sample("P1,kW", 2000, Some(-2.0), QualityCode::Uncertain),
        sample("P1,kW", 3000, Some(9.0), QualityCode::Good), // outside the range
    ])
    .await
    .unwrap();
    let mut out = Vec::new();
    let n = s
        .export_csv(&["P1,kW", "Q"], ts(0), ts(3000), &mut out)
        .await
        .unwrap();
    assert_eq!(n, 3);
    assert_eq!(
        String::from_utf8(out).unwrap(),
        "time_utc,ts_ms,tag,value,quality\n\
         1970-01-01T00:00:01.000Z,1000,\"P1,kW\",1.5,good\n\
         1970-01-01T00:00:01.000Z,1000,Q,,bad\n\
         1970-01-01T00:00:02.000Z,2000,\"P1,kW\",-2,uncertain\n"
    );
    // Paged export: more rows than one page, in time order, none lost.
    let rows: Vec<_> = (0..6_003)
        .flat_map(|i| {
            [
                sample("A", 10_000 + i, Some(i as f64), QualityCode::Good),
                sample("B", 10_000 + i, Some(i as f64), QualityCode::Good),
            ]
        })
        .collect();
    s.insert_samples(&rows).await.unwrap();
    let mut out = Vec::new();
    let n = s
        .export_csv(&["A", "B"], ts(10_000), ts(20_000), &mut out)
        .await
        .unwrap();
    assert_eq!(n, 12_006);
    let text = String::from_utf8(out).unwrap();
    let ts_col: Vec<i64> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(1).unwrap().parse().unwrap())
        .collect();
    assert_eq!(ts_col.len(), 12_006);
    assert!(ts_col.windows(2).all(|w| w[0] <= w[1]));
    // Bounded raw read.
    let raw = s
        .raw_samples(&["A"], ts(10_000), ts(20_000), 7_000)
        .await
        .unwrap();
    assert_eq!(raw.len(), 6_003);
    assert_eq!(raw[6_002].value, Some(6_002.0));
    let raw = s
        .raw_samples(&["A", "B"], ts(10_000), ts(20_000), 5)
        .await
        .unwrap();
    assert_eq!(raw.len(), 5);
    db.cleanup().await;
}
both_backends!(csv_export, csv_export_and_raw);

/// An integer outside ±2^53 comes back exactly from raw reads and the CSV.
async fn wide_integers_are_exact(db: TestDb) {
    let s = &db.store;
    let big = 12_345_678_901_234_567_891i128;
    s.insert_samples(&[
        HistorySample {
            exact: Some(big),
            ..sample("Meter.Energy", 1000, Some(big as f64), QualityCode::Good)
        },
        HistorySample {
            exact: Some(-9_007_199_254_740_993),
            ..sample(
                "Meter.Energy",
                2000,
                Some(-9.007199254740993e15),
                QualityCode::Good,
            )
        },
    ])
    .await
    .unwrap();
    let raw = s
        .raw_samples(&["Meter.Energy"], ts(0), ts(3000), 10)
        .await
        .unwrap();
    assert_eq!(raw[0].exact, Some(big));
    assert_eq!(raw[1].exact, Some(-9_007_199_254_740_993));
    let json = serde_json::to_value(&raw[0]).unwrap();
    assert_eq!(json["exact"], "12345678901234567891");
    let mut out = Vec::new();
    s.export_csv(&["Meter.Energy"], ts(0), ts(3000), &mut out)
        .await
        .unwrap();
    let text = String::from_utf8(out).unwrap();
    assert!(
        text.contains(",Meter.Energy,12345678901234567891,good\n"),
        "{text}"
    );
    assert!(
        text.contains(",Meter.Energy,-9007199254740993,good\n"),
        "{text}"
    );
    // A repeated sample replaces the digits too: none clears them, new
    // ones replace them.
    s.insert_samples(&[
        sample("Meter.Energy", 1000, Some(5.0), QualityCode::Good),
        HistorySample {
            exact: Some(42),
            ..sample("Meter.Energy", 2000, Some(42.0), QualityCode::Good)
        },
    ])
    .await
    .unwrap();
    let raw = s
        .raw_samples(&["Meter.Energy"], ts(0), ts(3000), 10)
        .await
        .unwrap();
    assert_eq!((raw[0].value, raw[0].exact), (Some(5.0), None));
    assert_eq!((raw[1].value, raw[1].exact), (Some(42.0), Some(42)));
    db.cleanup().await;
}
both_backends!(wide_integers, wide_integers_are_exact);

async fn retention_deletes_old_rows(db: TestDb) {
    let s = &db.store;
    const DAY: i64 = 86_400_000;
    let now = 100 * DAY;
    let mut rows = Vec::new();
    for tag in ["keep_long", "global", "forever"] {
        for d in [1, 10, 40, 99] {
            rows.push(sample(
                tag,
                now - d * DAY,
                Some(d as f64),
                QualityCode::Good,
            ));
        }
    }
    s.insert_samples(&rows).await.unwrap();
    let policy = RetentionPolicy {
        default_days: Some(30),
        per_tag_days: HashMap::from([("keep_long".to_string(), 50), ("forever".to_string(), 365)]),
        ..Default::default()
    };
    let deleted = s.apply_retention(&policy, ts(now)).await.unwrap();
    assert_eq!(deleted, 1 + 2); // keep_long: the 99-day row; global: 40 and 99
    let count = |tag: &'static str| async move {
        s.raw_samples(&[tag], ts(0), ts(now + 1), 100)
            .await
            .unwrap()
            .len()
    };
    assert_eq!(count("keep_long").await, 3);
    assert_eq!(count("global").await, 2);
    assert_eq!(count("forever").await, 4);
    assert_eq!(
        s.delete_samples_before(Some("forever"), ts(now - 5 * DAY))
            .await
            .unwrap(),
        3
    );
    assert_eq!(
        s.delete_samples_before(None, ts(now)).await.unwrap(),
        1 + 3 + 2
    );
    assert_eq!(
        s.historian_tags().await.unwrap(),
        vec!["forever", "global", "keep_long"]
    );
    db.cleanup().await;
}
both_backends!(retention, retention_deletes_old_rows);

fn ev(ms: i64, user: Option<&str>, source: &str, kind: &str, message: &str) -> NewEvent {
    NewEvent {
        ts: ts(ms),
        user: user.map(str::to_string),
        source: source.into(),
        kind: kind.into(),
        message: message.into(),
    }
}

async fn events_filter(db: TestDb) {
    let s = &db.store;
    let ids = s
        .insert_events(&[
            ev(
                1000,
                Some("alice"),
                "SS1.Panel",
                "command",
                "Close breaker Q1",
            ),
            ev(
                2000,
                None,
                "SS1.Panel",
                "sequence",
                "OLUC step 3: zone 2 isolated",
            ),
            ev(3000, Some("bob"), "web", "login", "Login from 127.0.0.1"),
            ev(
                4000,
                Some("alice"),
                "web",
                "ack",
                "Acknowledged 100% of BREAKER alarms",
            ),
        ])
        .await
        .unwrap();
    assert_eq!(ids.len(), 4);
    let id5 = s
        .insert_event(&ev(5000, None, "dispatch", "dispatch", "Dispatch optimal"))
        .await
        .unwrap();
    assert!(id5 > ids[3]);
    let q = |f: EventFilter| async move {
        s.events(&EventFilter { limit: 100, ..f })
            .await
            .unwrap()
            .into_iter()
            .map(|e| e.ts.as_millis())
            .collect::<Vec<_>>()
    };
    assert_eq!(
        q(EventFilter::default()).await,
        vec![5000, 4000, 3000, 2000, 1000]
    );
    // "Today" is a range the caller passes.
    let today = EventFilter {
        from: Some(ts(2000)),
        to: Some(ts(4000)),
        ..Default::default()
    };
    assert_eq!(q(today).await, vec![3000, 2000]);
    assert_eq!(
        q(EventFilter {
            kind: Some("login".into()),
            ..Default::default()
        })
        .await,
        vec![3000]
    );
    assert_eq!(
        q(EventFilter {
            user: Some("alice".into()),
            ..Default::default()
        })
        .await,
        vec![4000, 1000]
    );
    assert_eq!(
        q(EventFilter {
            source: Some("web".into()),
            ..Default::default()
        })
        .await,
        vec![4000, 3000]
    );
    assert_eq!(
        q(EventFilter {
            text: Some("breaker".into()),
            ..Default::default()
        })
        .await,
        vec![4000, 1000]
    );
    // LIKE wildcards in the search text are literal.
    assert_eq!(
        q(EventFilter {
            text: Some("100%".into()),
            ..Default::default()
        })
        .await,
        vec![4000]
    );
    assert_eq!(
        q(EventFilter {
            text: Some("1_0".into()),
            ..Default::default()
        })
        .await,
        Vec::<i64>::new()
    );
    let page = s
        .events(&EventFilter {
            limit: 2,
            offset: 1,
            ..Default::default()
        })
        .await
        .unwrap();
    assert_eq!(
        page.iter().map(|e| e.ts.as_millis()).collect::<Vec<_>>(),
        vec![4000, 3000]
    );
    assert_eq!(page[0].user.as_deref(), Some("alice"));
    assert_eq!(page[0].kind, "ack");
    let sys = s
        .events(&EventFilter {
            kind: Some("sequence".into()),
            limit: 1,
            ..Default::default()
        })
        .await
        .unwrap();
    assert_eq!(sys[0].user, None);
    assert_eq!(sys[0].source, "SS1.Panel");
    assert_eq!(sys[0].message, "OLUC step 3: zone 2 isolated");
    db.cleanup().await;
}
both_backends!(events, events_filter);

fn alarm_state(key: &str) -> AlarmStateRecord {
    use gridscada_alarms::{AlarmKind, AlarmState};
    AlarmStateRecord {
        key: key.into(),
        kind: AlarmKind::Hi,
        state: AlarmState::UnackActive,
        active: true,
        acked: false,
        active_since: Some(ts(1000)),
        last_change: ts(1000),
        message: "SS1.Zone1.I high: 412.5 A (limit 400 A)".into(),
        priority: 600,
        selection: "SS1".into(),
        shelved_by: None,
        shelved_at: None,
        shelved_until: None,
        shelve_reason: None,
        out_of_service: false,
        out_of_service_by: None,
        out_of_service_since: None,
        out_of_service_reason: None,
        out_of_service_until: None,
        activation_value: Some(gridscada_tagdb::Value::Float(412.5)),
    }
}

async fn alarm_states_survive_restart(mut db: TestDb) {
    use gridscada_alarms::AlarmState;
    let a = alarm_state("SS1.Zone1.I:hi");
    let b = alarm_state("SS1.Zone2.I:hi");
    db.store
        .upsert_alarm_states(&[a.clone(), b.clone()])
        .await
        .unwrap();
    let mut a2 = a.clone();
    a2.state = AlarmState::AckActive;
    a2.acked = true;
    a2.last_change = ts(2000);
    let mut b2 = b.clone();
    b2.state = AlarmState::Shelved;
    b2.shelved_at = Some(ts(2000));
    b2.shelved_until = Some(ts(9_000_000));
    b2.shelved_by = Some("sup".into());
    b2.shelve_reason = Some("sensor replaced".into());
    b2.out_of_service = true;
    b2.out_of_service_by = Some("sup".into());
    b2.out_of_service_since = Some(ts(2500));
    b2.out_of_service_reason = Some("under repair".into());
    b2.out_of_service_until = Some(ts(9_000_000));
    // The value at activation keeps its type, an integer beyond 2^53 exactly.
    b2.activation_value = Some(gridscada_tagdb::Value::Int(9_007_199_254_740_993));
    let mut c = alarm_state("SS1.Zone3.I:hi");
    c.activation_value = None;
    db.store
        .upsert_alarm_states(&[a2.clone(), b2.clone(), c.clone()])
        .await
        .unwrap();
    // A late writer with an older record never rolls the state back.
    db.store
        .upsert_alarm_states(std::slice::from_ref(&a))
        .await
        .unwrap();
    db.reopen().await;
    assert_eq!(
        db.store.alarm_states().await.unwrap(),
        vec![a2.clone(), b2, c.clone()]
    );
    assert!(db.store.delete_alarm_state("SS1.Zone2.I:hi").await.unwrap());
    assert!(!db.store.delete_alarm_state("SS1.Zone2.I:hi").await.unwrap());
    assert_eq!(db.store.alarm_states().await.unwrap(), vec![a2, c]);
    db.cleanup().await;
}
both_backends!(alarm_states, alarm_states_survive_restart);

fn tr(
    ms: i64,
    key: &str,
    from: &str,
    to: &str,
    activation: bool,
    prio: i32,
    sel: &str,
) -> AlarmTransition {
    AlarmTransition {
        ts: ts(ms),
        alarm_key: key.into(),
        tag: key.split(':').next().unwrap().into(),
        kind: key.split(':').nth(1).unwrap().into(),
        from_state: from.into(),
        to_state: to.into(),
        cause: Some(if activation { "activate" } else { "ack" }.into()),
        activation,
        value: Some(ms as f64),
        limit: Some(400.0),
        user: (!activation).then(|| "alice".to_string()),
        message: format!("{key} {to}"),
        priority: prio,
        selection: sel.into(),
    }
}

async fn alarm_history_queries(db: TestDb) {
    let s = &db.store;
    let ids = s
        .insert_alarm_transitions(&[
            tr(1000, "Q1.I:hi", "normal", "unack", true, 500, "SS1"),
            tr(2000, "Q1.I:hi", "unack", "acked", false, 500, "SS1"),
            tr(3000, "Q2.Comm:comm", "normal", "unack", true, 900, "SS2"),
            tr(4000, "Q1.I:hi", "normal", "unack", true, 500, "SS1"),
            tr(5000, "Q3.V:lo", "normal", "unack", true, 100, "SS2"),
        ])
        .await
        .unwrap();
    assert_eq!(ids.len(), 5);
    let q = |f: AlarmHistoryFilter| async move {
        s.alarm_history(&AlarmHistoryFilter { limit: 100, ..f })
            .await
            .unwrap()
            .into_iter()
            .map(|r| r.transition.ts.as_millis())
            .collect::<Vec<_>>()
    };
    assert_eq!(
        q(Default::default()).await,
        vec![5000, 4000, 3000, 2000, 1000]
    );
    assert_eq!(
        q(AlarmHistoryFilter {
            oldest_first: true,
            ..Default::default()
        })
        .await,
        vec![1000, 2000, 3000, 4000, 5000]
    );
    assert_eq!(
        q(AlarmHistoryFilter {
            from: Some(ts(2000)),
            to: Some(ts(5000)),
            ..Default::default()
        })
        .await,
        vec![4000, 3000, 2000]
    );
    assert_eq!(
        q(AlarmHistoryFilter {
            alarm_key: Some("Q1.I:hi".into()),
            ..Default::default()
        })
        .await,
        vec![4000, 2000, 1000]
    );
    assert_eq!(
        q(AlarmHistoryFilter {
            tag: Some("Q3.V".into()),
            ..Default::default()
        })
        .await,
        vec![5000]
    );
    assert_eq!(
        q(AlarmHistoryFilter {
            kind: Some("comm".into()),
            ..Default::default()
        })
        .await,
        vec![3000]
    );
    assert_eq!(
        q(AlarmHistoryFilter {
            selection: Some("SS2".into()),
            ..Default::default()
        })
        .await,
        vec![5000, 3000]
    );
    assert_eq!(
        q(AlarmHistoryFilter {
            min_priority: Some(500),
            ..Default::default()
        })
        .await,
        vec![4000, 3000, 2000, 1000]
    );
    assert_eq!(
        q(AlarmHistoryFilter {
            activations_only: true,
            ..Default::default()
        })
        .await,
        vec![5000, 4000, 3000, 1000]
    );
    assert_eq!(
        q(AlarmHistoryFilter {
            text: Some("ACKED".into()),
            ..Default::default()
        })
        .await,
        vec![2000]
    );
    let page = s
        .alarm_history(&AlarmHistoryFilter {
            limit: 2,
            offset: 1,
            ..Default::default()
        })
        .await
        .unwrap();
    assert_eq!(
        page.iter()
            .map(|r| r.transition.ts.as_millis())
            .collect::<Vec<_>>(),
        vec![4000, 3000]
    );

    let full = s
        .alarm_history(&AlarmHistoryFilter {
            limit: 1,
            offset: 3,
            ..Default::default()
        })
        .await
        .unwrap();
    assert_eq!(
        full[0].transition,
        tr(2000, "Q1.I:hi", "unack", "acked", false, 500, "SS1")
    );
    assert_eq!(full[0].id, ids[1]);

    let acts = s.alarm_activations(ts(0), ts(4500)).await.unwrap();
    assert_eq!(
        acts.iter()
            .map(|a| a.transition.ts.as_millis())
            .collect::<Vec<_>>(),
        vec![1000, 3000, 4000]
    );
    let counts = s.alarm_activation_counts(ts(0), ts(10_000)).await.unwrap();
    assert_eq!(
        counts,
        vec![
            ActivationCount {
                alarm_key: "Q1.I:hi".into(),
                count: 2
            },
            ActivationCount {
                alarm_key: "Q2.Comm:comm".into(),
                count: 1
            },
            ActivationCount {
                alarm_key: "Q3.V:lo".into(),
                count: 1
            },
        ]
    );
    db.cleanup().await;
}
both_backends!(alarm_history, alarm_history_queries);

/// Each history row keeps why it happened: an activation and a return while
/// suppressed both read "suppressed → suppressed", and only the cause tells
/// them apart. A row without a cause (recorded before causes were kept)
/// reads back without one.
async fn alarm_history_keeps_the_cause(db: TestDb) {
    use gridscada_alarms::{AlarmId, AlarmKind, AlarmState, TransitionCause};
    use gridscada_tagdb::Value;
    let engine = |ms: i64, cause: TransitionCause, active: bool, v: f64| {
        let t = gridscada_alarms::AlarmTransition {
            time: ts(ms),
            id: AlarmId(3),
            key: "P1.PA.V_L1:lo".into(),
            tag: Some("P1.PA.V_L1".into()),
            kind: AlarmKind::Lo,
            cause,
            from: AlarmState::Suppressed,
            to: AlarmState::Suppressed,
            active,
            annunciated: false,
            value: Some(Value::Float(v)),
            limit: Some(Value::Float(207.0)),
            user: None,
            priority: 500,
            selection: "P1".into(),
            message: "P1.PA.V_L1 low: 0 V".into(),
        };
        AlarmTransition::from(&t)
    };
    let activated = engine(1000, TransitionCause::Activate, true, 0.0);
    let returned = engine(2000, TransitionCause::Return, false, 231.0);
    assert_eq!(returned.cause.as_deref(), Some("return"));
    assert!(
        !activated.activation,
        "a suppressed activation is not annunciated"
    );
    let mut legacy = tr(
        500,
        "P1.PA.V_L1:lo",
        "suppressed",
        "suppressed",
        false,
        500,
        "P1",
    );
    legacy.cause = None;
    let s = &db.store;
    s.insert_alarm_transitions(&[legacy.clone(), activated.clone(), returned.clone()])
        .await
        .unwrap();
    let rows = s
        .alarm_history(&AlarmHistoryFilter {
            limit: 10,
            oldest_first: true,
            ..Default::default()
        })
        .await
        .unwrap();
    let got: Vec<_> = rows.iter().map(|r| r.transition.clone()).collect();
    assert_eq!(got, vec![legacy, activated, returned]);
    let causes: Vec<_> = rows
        .iter()
        .map(|r| {
            (
                r.transition.to_state.as_str(),
                r.transition.cause.as_deref(),
            )
        })
        .collect();
    assert_eq!(
        causes,
        vec![
            ("suppressed", None),
            ("suppressed", Some("activate")),
            ("suppressed", Some("return")),
        ]
    );
    // The API's JSON carries it beside the states.
    let json = serde_json::to_value(&rows[2]).unwrap();
    assert_eq!(json["cause"], "return");
    assert_eq!(json["from_state"], "suppressed");
    assert_eq!(
        serde_json::to_value(&rows[0]).unwrap()["cause"],
        serde_json::Value::Null
    );
    // Every cause the engine has fits the column.
    for c in TransitionCause::ALL {
        let mut t = engine(3000, c, false, 1.0);
        t.alarm_key = format!("cause:{c}");
        s.insert_alarm_transitions(&[t]).await.unwrap();
    }
    let all = s
        .alarm_history(&AlarmHistoryFilter {
            from: Some(ts(3000)),
            limit: 100,
            oldest_first: true,
            ..Default::default()
        })
        .await
        .unwrap();
    let names: Vec<_> = all
        .iter()
        .map(|r| r.transition.cause.clone().unwrap())
        .collect();
    let want: Vec<_> = TransitionCause::ALL.iter().map(|c| c.to_string()).collect();
    assert_eq!(names, want);
    db.cleanup().await;
}
both_backends!(alarm_history_cause, alarm_history_keeps_the_cause);

async fn users_crud(db: TestDb) {
    let s = &db.store;
    let new = NewUser {
        name: "alice".into(),
        role: Role::Operator,
        password_hash: "$argon2id$v=19$m=19456,t=2,p=1$abc$def".into(),
        group: "operators".into(),
        created_at: ts(1000),
    };
    let u = s.create_user(&new).await.unwrap();
    assert_eq!(
        (u.name.as_str(), u.role, u.blocked),
        ("alice", Role::Operator, false)
    );
    assert_eq!(u.password_changed_at, ts(1000));
    assert!(matches!(
        s.create_user(&new).await,
        Err(StoreError::Conflict(_))
    ));
    s.create_user(&NewUser {
        name: "root".into(),
        role: Role::Administrator,
        group: "admins".into(),
        ..new.clone()
    })
    .await
    .unwrap();
    s.set_user_blocked("alice", true).await.unwrap();
    s.set_user_role("alice", Role::Supervisor).await.unwrap();
    s.set_user_group("alice", "supervisors").await.unwrap();
    s.set_password_hash("alice", "$argon2id$new", ts(5000), None)
        .await
        .unwrap();
    let a = s.user("alice").await.unwrap().unwrap();
    assert!(a.blocked);
    assert_eq!(a.role, Role::Supervisor);
    assert_eq!(a.group, "supervisors");
    assert_eq!(a.password_hash, "$argon2id$new");
    assert_eq!(a.password_changed_at, ts(5000));
    assert_eq!(a.created_at, ts(1000));
    assert!(matches!(
        s.set_user_blocked("ghost", true).await,
        Err(StoreError::NotFound(_))
    ));
    assert!(matches!(
        s.create_user(&NewUser {
            name: " ".into(),
            ..new.clone()
        })
        .await,
        Err(StoreError::Invalid(_))
    ));
    assert_eq!(
        s.users()
            .await
            .unwrap()
            .iter()
            .map(|u| u.name.as_str())
            .collect::<Vec<_>>(),
        vec!["alice", "root"]
    );
    assert!(s.delete_user("root").await.unwrap());
    assert!(!s.delete_user("root").await.unwrap());
    assert!(s.user("root").await.unwrap().is_none());

    s.set_group_screens(
        "operators",
        &["main".into(), "alarms".into(), "main".into()],
    )
    .await
    .unwrap();
    s.set_group_screens("guests", &["main".into()])
        .await
        .unwrap();
    assert_eq!(
        s.group_screens("operators").await.unwrap(),
        vec!["alarms", "main"]
    );
    s.set_group_screens("operators", &["trends".into()])
        .await
        .unwrap();
    assert_eq!(
        s.all_group_screens().await.unwrap(),
        vec![
            ("guests".to_string(), vec!["main".to_string()]),
            ("operators".to_string(), vec!["trends".to_string()])
        ]
    );
    db.cleanup().await;
}
both_backends!(users, users_crud);

async fn dispatch_records(db: TestDb) {
    let s = &db.store;
    assert!(s.latest_dispatch().await.unwrap().is_none());
    let d = |ms: i64, status: &str| NewDispatch {
        ts: ts(ms),
        status: status.into(),
        mode: "auto".into(),
        objective: Some(12.5),
        solve_ms: 3.25,
        inputs: serde_json::json!({"load_kw": [10.0, 12.0], "soc_kwh": 40.0}),
        setpoints: serde_json::json!({"BESS1": -5.0, "PV1": 20.0}),
        reason: None,
    };
    s.insert_dispatch(&d(1000, "optimal")).await.unwrap();
    let id = s.insert_dispatch(&d(2000, "fallback")).await.unwrap();
    let latest = s.latest_dispatch().await.unwrap().unwrap();
    assert_eq!(latest.id, id);
    assert_eq!(latest.status, "fallback");
    assert_eq!(latest.inputs["soc_kwh"], 40.0);
    assert_eq!(latest.setpoints["BESS1"], -5.0);
    assert_eq!(latest.objective, Some(12.5));
    let h = s.dispatch_history(ts(0), ts(10_000), 10).await.unwrap();
    assert_eq!(
        h.iter().map(|d| d.ts.as_millis()).collect::<Vec<_>>(),
        vec![2000, 1000]
    );
    assert_eq!(
        s.dispatch_history(ts(0), ts(1500), 10).await.unwrap().len(),
        1
    );
    db.cleanup().await;
}
both_backends!(dispatch, dispatch_records);

async fn panel_states_survive(db: TestDb) {
    let s = &db.store;
    assert!(s.panel_states().await.unwrap().is_empty());
    let a = serde_json::json!({"mode": "auto", "faulty": [2], "lockout": false});
    let b = serde_json::json!({"mode": "manual", "faulty": [], "lockout": true});
    s.save_panel_state("ss1", &a, ts(1000)).await.unwrap();
    s.save_panel_state("css1", &b, ts(1000)).await.unwrap();
    // A later save replaces the earlier one.
    let a2 = serde_json::json!({"mode": "auto", "faulty": [], "lockout": false});
    s.save_panel_state("ss1", &a2, ts(2000)).await.unwrap();
    assert_eq!(
        s.panel_states().await.unwrap(),
        vec![("css1".to_string(), b), ("ss1".to_string(), a2)]
    );
    db.cleanup().await;
}
both_backends!(panel_states, panel_states_survive);

/// Screens: a save names the version it started from; a stale save or a
/// second "new" screen with a taken id is refused and changes nothing; a
/// delete also removes the screen from every group's access.
async fn user_screens_versions(db: TestDb) {
    let s = &db.store;
    assert!(s.screens().await.unwrap().is_empty());
    let body = serde_json::json!({"id": "feeder-a", "name": "Feeder A", "elements": []});
    let v1 = s
        .save_screen("feeder-a", "Feeder A", &body, 0, "alice", ts(1000))
        .await
        .unwrap();
    assert_eq!(v1.version, 1);
    assert_eq!(v1.body["version"], 1);
    // A second "new" screen with the same id is a conflict.
    let err = s
        .save_screen("feeder-a", "Other", &body, 0, "bob", ts(1500))
        .await
        .unwrap_err();
    assert!(matches!(err, StoreError::Conflict(_)), "{err}");
    let v2 = s
        .save_screen("feeder-a", "Feeder A2", &body, 1, "bob", ts(2000))
        .await
        .unwrap();
    assert_eq!(v2.version, 2);
    // Saving from version 1 again is stale.
    let err = s
        .save_screen("feeder-a", "Stale", &body, 1, "alice", ts(3000))
        .await
        .unwrap_err();
    assert!(err.to_string().contains("version 2"), "{err}");
    let got = s.screen("feeder-a").await.unwrap().unwrap();
    assert_eq!(
        (got.name.as_str(), got.version, got.updated_by.as_str()),
        ("Feeder A2", 2, "bob")
    );
    assert_eq!(got.updated_at, ts(2000));
    s.set_group_screens("operator", &["main".into(), "custom:feeder-a".into()])
        .await
        .unwrap();
    assert!(s
        .delete_screen("feeder-a", "custom:feeder-a")
        .await
        .unwrap());
    assert!(!s
        .delete_screen("feeder-a", "custom:feeder-a")
        .await
        .unwrap());
    assert!(s.screen("feeder-a").await.unwrap().is_none());
    assert_eq!(s.group_screens("operator").await.unwrap(), vec!["main"]);
    db.cleanup().await;
}
both_backends!(user_screens, user_screens_versions);

/// Text from outside can never forge a second line in the event log.
async fn events_escape_control_characters(db: TestDb) {
    let s = &db.store;
    let forged = "failed login as 'x' from 10.9.9.9: ok\nadmin logged in\u{1b}[2J";
    s.insert_event(&ev(1000, Some("eve\r\n"), "web", "login_failed", forged))
        .await
        .unwrap();
    let got = s
        .events(&EventFilter {
            limit: 10,
            ..Default::default()
        })
        .await
        .unwrap();
    let e = got.iter().find(|e| e.kind == "login_failed").unwrap();
    assert!(!e.message.chars().any(char::is_control), "{:?}", e.message);
    assert!(
        e.message.contains("ok\\nadmin logged in"),
        "{:?}",
        e.message
    );
    assert_eq!(e.user.as_deref(), Some("eve\\r\\n"));
    db.cleanup().await;
}
both_backends!(event_escaping, events_escape_control_characters);

/// Both backends end their migrations with the same tables, columns and
/// indexes.
#[tokio::test]
async fn both_backends_have_the_same_schema() {
    let lite = TestDb::new(common::Engine::Sqlite, "same_schema")
        .await
        .unwrap();
    let sqlite = lite.store.schema_summary().await.unwrap();
    assert!(
        sqlite.iter().any(|l| l.starts_with("table events:")),
        "{sqlite:?}"
    );
    assert!(sqlite.iter().any(|l| l.starts_with("index ")), "{sqlite:?}");
    lite.cleanup().await;
    let Some(pg) = TestDb::new(common::Engine::Postgres, "same_schema").await else {
        return;
    };
    let postgres = pg.store.schema_summary().await.unwrap();
    pg.cleanup().await;
    assert_eq!(sqlite, postgres);
}

async fn wait_for(what: &str, mut cond: impl FnMut() -> bool) {
    for _ in 0..1000 {
        if cond() {
            return;
        }
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    panic!("timed out waiting for {what}");
}

/// A stuck database: the buffer fills, overflow is counted and flagged, and
/// everything accepted is written once the database answers again.
async fn overflow_is_counted(db: TestDb) {
    let hist = Historian::spawn(
        db.store.clone(),
        HistorianConfig {
            capacity: 100,
            batch_max: 1000,
            linger: Duration::ZERO,
            ..Default::default()
        },
    );
    let h = hist.handle();
    let mut overflow = h.overflow();
    // Register the tag first so the writer blocks on the samples table itself.
    db.store
        .insert_samples(&[sample("T", 0, Some(0.0), QualityCode::Good)])
        .await
        .unwrap();
    let lock = db.lock_samples().await;
    assert!(h.push(sample("T", 1, Some(1.0), QualityCode::Good)));
    // The writer takes that sample and blocks on the lock.
    wait_for("the writer to take the first sample", || {
        h.metrics().buffered == 0
    })
    .await;
    tokio::time::sleep(Duration::from_millis(50)).await;
    let accepted = (2..=111)
        .filter(|&i| h.push(sample("T", i, Some(i as f64), QualityCode::Good)))
        .count();
    assert_eq!(accepted, 100);
    let m = h.metrics();
    assert_eq!(m.dropped, 10);
    assert_eq!(m.buffered, 100);
    assert!(m.overflow);
    assert!(*overflow.borrow_and_update());
    lock.release().await;
    wait_for("the buffer to drain", || h.metrics().samples_written == 101).await;
    wait_for("the overflow flag to clear", || !h.metrics().overflow).await;
    let m = hist.shutdown().await;
    assert_eq!(m.dropped, 10);
    assert!(m.batches_written >= 2);
    let rows = db
        .store
        .raw_samples(&["T"], ts(0), ts(1000), 1000)
        .await
        .unwrap();
    assert_eq!(
        rows.len(),
        102,
        "the registration row, the blocked one and the 100 buffered"
    );
    db.cleanup().await;
}
both_backends!(overflow, overflow_is_counted);

/// The linger waits for a fuller batch only until the batch is full: a
/// burst of full batches is written at once, while a lone sample still
/// waits out the linger (fewer, bigger transactions at low rates).
async fn a_full_batch_does_not_wait_out_the_linger(db: TestDb) {
    let hist = Historian::spawn(
        db.store.clone(),
        HistorianConfig {
            capacity: 1000,
            batch_max: 100,
            linger: Duration::from_secs(3600),
            ..Default::default()
        },
    );
    let h = hist.handle();
    // One sample first: the writer takes it and lingers for more.
    assert!(h.push(sample("L", 0, Some(0.0), QualityCode::Good)));
    wait_for("the writer to take the first sample", || {
        h.metrics().buffered == 0
    })
    .await;
    tokio::time::sleep(Duration::from_millis(50)).await;
    assert_eq!(h.metrics().samples_written, 0, "a lone sample lingers");
    // The burst fills the lingering batch and two more: all written long
    // before the hour's linger would end.
    assert_eq!(
        h.push_all((1..300).map(|i| sample("L", i, Some(i as f64), QualityCode::Good))),
        299
    );
    wait_for("three full batches to be written", || {
        h.metrics().samples_written == 300
    })
    .await;
    assert_eq!(h.metrics().batches_written, 3);
    hist.shutdown().await;
    let rows = db
        .store
        .raw_samples(&["L"], ts(0), ts(1000), 1000)
        .await
        .unwrap();
    assert_eq!(rows.len(), 300);
    db.cleanup().await;
}
both_backends!(linger_until_full, a_full_batch_does_not_wait_out_the_linger);

/// Pausing holds samples in the buffer; shutdown writes what is left.
async fn pause_and_shutdown_flush(db: TestDb) {
    let hist = Historian::spawn(
        db.store.clone(),
        HistorianConfig {
            capacity: 50,
            batch_max: 7,
            linger: Duration::from_millis(5),
            ..Default::default()
        },
    );
    hist.pause(true);
    let h = hist.handle();
    let accepted = h.push_all((0..60).map(|i| sample("P", i, Some(i as f64), QualityCode::Good)));
    assert_eq!(accepted, 50);
    assert_eq!(h.metrics().dropped, 10);
    let m = hist.shutdown().await;
    assert_eq!(m.samples_written, 50);
    assert_eq!(m.buffered, 0);
    assert!(
        !h.push(sample("P", 100, None, QualityCode::Bad)),
        "writer stopped"
    );
    assert_eq!(h.metrics().dropped, 11);
    let rows = db
        .store
        .raw_samples(&["P"], ts(0), ts(1000), 1000)
        .await
        .unwrap();
    assert_eq!(rows.len(), 50);
    assert_eq!(rows[49].value, Some(49.0));
    db.cleanup().await;
}
both_backends!(pause_flush, pause_and_shutdown_flush);

/// A sample offered after the writer stopped is lost and counted, but it is
/// no overflow (no flag, so no system alarm); one offered during shutdown's
/// flush is written.
async fn a_sample_after_shutdown_is_counted_but_no_overflow(db: TestDb) {
    let hist = Historian::spawn(db.store.clone(), HistorianConfig::default());
    let h = hist.handle();
    let overflow = h.overflow();
    assert!(h.push(sample("L", 1, Some(1.0), QualityCode::Good)));
    let m = hist.shutdown().await;
    assert_eq!((m.samples_written, m.dropped), (1, 0));
    assert!(!h.push(sample("L", 2, Some(2.0), QualityCode::Good)));
    assert!(!h.push(sample("L", 3, Some(3.0), QualityCode::Good)));
    let m = h.metrics();
    assert_eq!(m.dropped, 2, "counted in the figure");
    assert!(!m.overflow, "a stopped writer is not an overflow");
    assert!(!*overflow.borrow());
    db.cleanup().await;
}
both_backends!(
    after_shutdown,
    a_sample_after_shutdown_is_counted_but_no_overflow
);

#[tokio::test]
async fn bad_urls_are_refused_with_the_url_named() {
    let dir = tempfile::tempdir().unwrap();
    let o = OpenOptions::new(dir.path());
    let e = Store::open("mysql://x", &o).await.unwrap_err().to_string();
    assert!(e.contains("mysql://x"), "{e}");
    assert!(Store::open("sqlite://:memory:", &o).await.is_err());
    let e = Store::open(
        "postgres://u:secret@127.0.0.1:1/db",
        &OpenOptions {
            acquire_timeout: Duration::from_secs(2),
            ..o.clone()
        },
    )
    .await
    .unwrap_err()
    .to_string();
    assert!(!e.contains("secret"), "password leaked: {e}");
}

/// Two sites on one database: each writes its own rows under the same names
/// (two copies of one plant), reads only its own by default, reads the
/// other's through a view, and the view refuses every write.
async fn two_sites_keep_apart(db: TestDb) {
    let north = &db.store;
    assert_eq!(north.site(), DEFAULT_SITE);
    let south = Store::open(
        &db.url,
        &OpenOptions {
            site: "south".into(),
            ..db.options.clone()
        },
    )
    .await
    .unwrap();
    for (s, v) in [(north, 1.0), (&south, 2.0)] {
        s.insert_samples(&[sample("SS1.V", 1000, Some(v), QualityCode::Good)])
            .await
            .unwrap();
        s.insert_event(&ev(
            1000,
            None,
            "SS1",
            "info",
            &format!("from {}", s.site()),
        ))
        .await
        .unwrap();
        s.insert_alarm_transitions(&[tr(1000, "SS1.V:hi", "normal", "unack_alarm", true, 2, "s")])
            .await
            .unwrap();
        let mut state = alarm_state("SS1.V:hi");
        state.message = format!("at {}", s.site());
        s.upsert_alarm_states(&[state]).await.unwrap();
        s.save_panel_state("ss1", &serde_json::json!({ "site": s.site() }), ts(1000))
            .await
            .unwrap();
        s.insert_dispatch(&NewDispatch {
            ts: ts(1000),
            status: s.site().into(),
            mode: "auto".into(),
            objective: None,
            solve_ms: 1.0,
            inputs: serde_json::json!({}),
            setpoints: serde_json::json!({}),
            reason: None,
        })
        .await
        .unwrap();
    }
    let all = EventFilter {
        limit: 100,
        ..Default::default()
    };
    let history = AlarmHistoryFilter {
        limit: 100,
        ..Default::default()
    };
    for (s, v) in [(north, 1.0), (&south, 2.0)] {
        let own = s.site().to_string();
        let events = s.events(&all).await.unwrap();
        assert_eq!(events.len(), 1, "{own}: {events:?}");
        assert_eq!(events[0].message, format!("from {own}"));
        assert_eq!(s.alarm_history(&history).await.unwrap().len(), 1);
        let states = s.alarm_states().await.unwrap();
        assert_eq!(states.len(), 1);
        assert_eq!(states[0].message, format!("at {own}"));
        assert_eq!(
            s.panel_states().await.unwrap(),
            vec![("ss1".to_string(), serde_json::json!({ "site": own }))]
        );
        assert_eq!(s.latest_dispatch().await.unwrap().unwrap().status, own);
        let raw = s
            .raw_samples(&["SS1.V"], ts(0), ts(2000), 10)
            .await
            .unwrap();
        assert_eq!(raw.len(), 1);
        assert_eq!(raw[0].value, Some(v));
        assert_eq!(s.historian_tags().await.unwrap(), vec!["SS1.V".to_string()]);
    }
    // North reads south's history through a view, and cannot write to it.
    let view = north.site_reader("south").unwrap();
    assert_eq!(view.events(&all).await.unwrap()[0].message, "from south");
    assert_eq!(view.alarm_history(&history).await.unwrap().len(), 1);
    let trend = view.trend(&["SS1.V"], ts(0), ts(2000), 1).await.unwrap();
    assert_eq!(trend[0].buckets[0].last, Some(2.0), "{trend:?}");
    assert!(view
        .insert_event(&ev(2000, None, "x", "info", "no"))
        .await
        .is_err());
    assert!(view
        .insert_samples(&[sample("SS1.V", 2000, Some(9.0), QualityCode::Good)])
        .await
        .is_err());
    assert!(view.delete_alarm_state("SS1.V:hi").await.is_err());
    assert!(view
        .save_panel_state("ss1", &serde_json::json!({}), ts(2000))
        .await
        .is_err());
    assert_eq!(south.events(&all).await.unwrap().len(), 1);
    // The same site gives the store itself (writable); a bad id is refused.
    assert!(north
        .site_reader(DEFAULT_SITE)
        .unwrap()
        .insert_event(&ev(3000, None, "x", "info", "ok"))
        .await
        .is_ok());
    assert!(north.site_reader("no such/site").is_err());
    assert_eq!(
        north.sites().await.unwrap(),
        vec![DEFAULT_SITE.to_string(), "south".to_string()]
    );
    // A retention run of one site leaves the other's samples alone.
    north.delete_samples_before(None, ts(5000)).await.unwrap();
    assert_eq!(
        south
            .raw_samples(&["SS1.V"], ts(0), ts(2000), 10)
            .await
            .unwrap()
            .len(),
        1
    );
    south.close().await;
    db.cleanup().await;
}
both_backends!(two_sites, two_sites_keep_apart);
