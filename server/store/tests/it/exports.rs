//! CSV exports of events, alarm history and dispatches on both backends:
//! the list filters apply, every row arrives in the lists' order, and text
//! fields are defused against formula injection.

use crate::common;

use common::TestDb;
use gridscada_store::*;
use gridscada_tagdb::Timestamp;

fn event(ts: i64, kind: &str, message: &str) -> NewEvent {
    NewEvent {
        ts: Timestamp::from_millis(ts),
        user: Some("alice".into()),
        source: "web".into(),
        kind: kind.into(),
        message: message.into(),
    }
}

/// Runs one export into memory: its row count and its lines.
macro_rules! export {
    ($store:expr, $method:ident ( $($arg:expr),* )) => {{
        let mut out = Vec::new();
        let n = $store.$method($($arg,)* &mut out).await.unwrap();
        let text = String::from_utf8(out).unwrap();
        (n, text.lines().map(str::to_owned).collect::<Vec<String>>())
    }};
}

async fn exports_filter_order_and_defuse(db: TestDb) {
    let store = &db.store;
    // More rows than one 64 KiB piece of output.
    let mut events: Vec<NewEvent> = (0..3000)
        .map(|i| event(10_000 + i, "command", &format!("breaker {i} closed")))
        .collect();
    events.push(event(20_000, "ack", "=HYPERLINK(\"http://x\",\"y\")"));
    events.push(event(20_001, "ack", "@SUM(1,2)"));
    store.insert_events(&events).await.unwrap();

    let all = EventFilter::default();
    let (n, lines) = export!(store, export_events_csv(&all));
    assert_eq!(n, 3002);
    assert_eq!(lines.len(), 3003);
    assert_eq!(lines[0], "time_utc,ts_ms,user,source,type,message");
    // Newest first, like the event screen; the formula defused.
    assert_eq!(
        lines[1],
        "1970-01-01T00:00:20.001Z,20001,alice,web,ack,\"'@SUM(1,2)\""
    );
    assert_eq!(
        lines[2],
        "1970-01-01T00:00:20.000Z,20000,alice,web,ack,\"'=HYPERLINK(\"\"http://x\"\",\"\"y\"\")\""
    );
    assert!(
        lines[3].ends_with(",command,breaker 2999 closed"),
        "{}",
        lines[3]
    );

    let acks = EventFilter {
        kind: Some("ack".into()),
        ..Default::default()
    };
    let (n, _) = export!(store, export_events_csv(&acks));
    assert_eq!(n, 2);
    let text = EventFilter {
        text: Some("BREAKER 12".into()),
        from: Some(Timestamp::from_millis(10_100)),
        ..Default::default()
    };
    let (n, lines) = export!(store, export_events_csv(&text));
    // 120..129 and 1200..1299, from ts 10 100 on (i >= 100).
    assert_eq!(n, 110, "{lines:?}");

    let t = |ts: i64, key: &str, message: &str| AlarmTransition {
        ts: Timestamp::from_millis(ts),
        alarm_key: key.into(),
        tag: key.split(':').next().unwrap().into(),
        kind: "lo".into(),
        from_state: "normal".into(),
        to_state: "unack_active".into(),
        cause: Some("activate".into()),
        activation: true,
        value: Some(12.5),
        limit: Some(20.0),
        user: None,
        message: message.into(),
        priority: 600,
        selection: "-SS1".into(),
    };
    store
        .insert_alarm_transitions(&[t(1000, "A.V:lo", "A low"), t(2000, "B.V:lo", "+B low")])
        .await
        .unwrap();
    let f = AlarmHistoryFilter {
        alarm_key: Some("B.V:lo".into()),
        ..Default::default()
    };
    let (n, lines) = export!(store, export_alarm_history_csv(&f));
    assert_eq!(n, 1);
    assert_eq!(
        lines[1],
        "1970-01-01T00:00:02.000Z,2000,B.V:lo,B.V,lo,normal,unack_active,activate,true,12.5,20,,\"'+B low\",600,\"'-SS1\""
    );

    store
        .insert_dispatch(&NewDispatch {
            ts: Timestamp::from_millis(5000),
            status: "optimal".into(),
            mode: "auto".into(),
            objective: Some(1.5),
            solve_ms: 3.0,
            inputs: serde_json::json!({}),
            setpoints: serde_json::json!({"PV": 10.0}),
            reason: None,
        })
        .await
        .unwrap();
    let (n, lines) = export!(
        store,
        export_dispatches_csv(Timestamp::from_millis(0), Timestamp::from_millis(10_000))
    );
    assert_eq!(n, 1);
    assert_eq!(
        lines[1],
        "1970-01-01T00:00:05.000Z,5000,optimal,auto,1.5,3,,\"{\"\"PV\"\":10.0}\""
    );
    db.cleanup().await;
}
both_backends!(exports, exports_filter_order_and_defuse);
