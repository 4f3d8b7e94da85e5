//! ISA-18.2 metrics on crafted histories.

use std::time::Duration;

use gridscada_alarms::metrics::{activations, compute, Activation, MetricsOptions};
use gridscada_alarms::{AlarmKind, AlarmState, AlarmStateRecord};
use gridscada_tagdb::Timestamp;

const MIN: i64 = 60_000;

fn act(ms: i64, key: &str, priority: u32) -> Activation {
    Activation {
        time: Timestamp::from_millis(ms),
        key: key.into(),
        priority,
    }
}

fn t(ms: i64) -> Timestamp {
    Timestamp::from_millis(ms)
}

#[test]
fn flood_boundary_is_more_than_ten_in_ten_minutes() {
    // Interval 0: exactly 10 (not a flood); interval 1: 11 (flood);
    // interval 2: 12 (flood, merges with 1); interval 3: 0.
    let mut a = Vec::new();
    for i in 0..10 {
        a.push(act(i * 1000, &format!("A{i}"), 500));
    }
    for i in 0..11 {
        a.push(act(10 * MIN + i * 1000, &format!("B{i}"), 500));
    }
    for i in 0..12 {
        a.push(act(20 * MIN + i * 1000, &format!("C{i}"), 500));
    }
    let m = compute(&a, &[], t(0), t(40 * MIN), &MetricsOptions::default());
    assert_eq!(m.total_activations, 33);
    let counts: Vec<u32> = m.per_interval.iter().map(|c| c.count).collect();
    assert_eq!(counts, vec![10, 11, 12, 0]);
    assert_eq!(m.floods.len(), 1);
    assert_eq!(m.floods[0].start, t(10 * MIN));
    assert_eq!(m.floods[0].end, t(30 * MIN));
    assert_eq!(m.floods[0].count, 23);
    assert!((m.percent_time_in_flood - 50.0).abs() < 1e-9);
    assert!((m.max_per_interval_per_operator - 12.0).abs() < 1e-9);
    assert!((m.average_per_interval_per_operator - 33.0 / 4.0).abs() < 1e-9);

    // Two operators share the load: 12 per interval is 6 each, no flood.
    let two = MetricsOptions {
        operators: 2,
        ..Default::default()
    };
    let m = compute(&a, &[], t(0), t(40 * MIN), &two);
    assert!(m.floods.is_empty());
    assert!((m.max_per_interval_per_operator - 6.0).abs() < 1e-9);
}

#[test]
fn separate_floods_do_not_merge_and_range_is_half_open() {
    let mut a = Vec::new();
    for i in 0..11 {
        a.push(act(i * 1000, "X", 500));
        a.push(act(20 * MIN + i * 1000, "Y", 500));
    }
    a.push(act(30 * MIN, "outside", 500)); // at `to`: excluded
    a.push(act(-1, "before", 500)); // before `from`: excluded
    let m = compute(&a, &[], t(0), t(30 * MIN), &MetricsOptions::default());
    assert_eq!(m.total_activations, 22);
    assert_eq!(m.floods.len(), 2);
}

#[test]
fn top_ten_ordering_by_count_then_key() {
    let mut a = Vec::new();
    // K00 once, K01 twice... K11 twelve times, spread so nothing chatters.
    for k in 0..12 {
        for n in 0..=k {
            a.push(act((k * 100 + n) * 2 * MIN, &format!("K{k:02}"), 500));
        }
    }
    a.push(act(1, "AA", 500));
    a.push(act(5 * MIN, "AA", 500)); // AA ties with K01 (2 each)
    let m = compute(&a, &[], t(0), t(10_000 * MIN), &MetricsOptions::default());
    let keys: Vec<&str> = m.top.iter().map(|f| f.key.as_str()).collect();
    assert_eq!(
        keys,
        vec!["K11", "K10", "K09", "K08", "K07", "K06", "K05", "K04", "K03", "K02"]
    );
    assert_eq!(m.top[0].count, 12);
    let total = m.total_activations as f64;
    assert!((m.top[0].percent - 1200.0 / total).abs() < 1e-9);
    assert!(m.chattering.is_empty());
}

#[test]
fn chattering_is_three_within_sixty_seconds() {
    let a = vec![
        // C: 3 within 60 s exactly (0, 30 s, 60 s).
        act(0, "C", 500),
        act(30_000, "C", 500),
        act(60_000, "C", 500),
        // N: 3 spread over 61 s: not chattering.
        act(0, "N", 500),
        act(30_000, "N", 500),
        act(61_000, "N", 500),
        // D: 5 quick ones.
        act(0, "D", 500),
        act(1_000, "D", 500),
        act(2_000, "D", 500),
        act(3_000, "D", 500),
        act(4_000, "D", 500),
    ];
    let m = compute(&a, &[], t(0), t(10 * MIN), &MetricsOptions::default());
    let c: Vec<(&str, u32)> = m
        .chattering
        .iter()
        .map(|c| (c.key.as_str(), c.max_in_window))
        .collect();
    assert_eq!(c, vec![("D", 5), ("C", 3)]);
}

fn record(key: &str, active: bool, since_ms: Option<i64>) -> AlarmStateRecord {
    AlarmStateRecord {
        key: key.into(),
        kind: AlarmKind::Hi,
        state: if active {
            AlarmState::AckActive
        } else {
            AlarmState::Normal
        },
        active,
        acked: true,
        active_since: since_ms.map(Timestamp::from_millis),
        last_change: Timestamp::from_millis(0),
        message: String::new(),
        priority: 500,
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
        activation_value: None,
    }
}

#[test]
fn stale_alarms_and_priority_distribution() {
    let day = 24 * 60 * MIN;
    let now = 3 * day;
    let current = vec![
        record("old", true, Some(now - day - 1)),
        record("young", true, Some(now - day)), // exactly 24 h: not stale
        record("cleared", false, None),
    ];
    let a = vec![
        act(0, "x", 900),
        act(1, "y", 500),
        act(2, "z", 500),
        act(3, "w", 100),
    ];
    let m = compute(&a, &current, t(0), t(now), &MetricsOptions::default());
    let stale: Vec<&str> = m.stale.iter().map(|s| s.key.as_str()).collect();
    assert_eq!(stale, vec!["old"]);
    assert!(m.stale[0].hours > 24.0);
    let p: Vec<(u32, u32)> = m
        .priority_distribution
        .iter()
        .map(|p| (p.priority, p.count))
        .collect();
    assert_eq!(p, vec![(900, 1), (500, 2), (100, 1)]);
    assert!((m.priority_distribution[1].percent - 50.0).abs() < 1e-9);
    // The report serializes for the API.
    let json = serde_json::to_value(&m).unwrap();
    assert_eq!(json["total_activations"], 4);
}

#[test]
fn empty_history_and_empty_range() {
    let m = compute(&[], &[], t(0), t(0), &MetricsOptions::default());
    assert_eq!(m.total_activations, 0);
    assert!(m.per_interval.is_empty() && m.floods.is_empty());
    assert_eq!(m.average_per_interval_per_operator, 0.0);
    let zero_ops = MetricsOptions {
        operators: 0,
        interval: Duration::from_secs(600),
        ..Default::default()
    };
    let m = compute(&[act(0, "a", 1)], &[], t(0), t(MIN), &zero_ops);
    assert_eq!(m.operators, 1);
}

#[test]
fn only_annunciated_activations_count() {
    use gridscada_alarms::{AlarmId, AlarmTransition, TransitionCause};
    let base = AlarmTransition {
        time: t(5),
        id: AlarmId(0),
        key: "k".into(),
        tag: None,
        kind: AlarmKind::Hi,
        cause: TransitionCause::Activate,
        from: AlarmState::Normal,
        to: AlarmState::UnackActive,
        active: true,
        annunciated: true,
        value: None,
        limit: None,
        user: None,
        priority: 700,
        selection: "SS1".into(),
        message: String::new(),
    };
    let suppressed = AlarmTransition {
        annunciated: false,
        to: AlarmState::Suppressed,
        ..base.clone()
    };
    let ack = AlarmTransition {
        cause: TransitionCause::Ack,
        ..base.clone()
    };
    let a = activations(&[base, suppressed, ack]);
    assert_eq!(a, vec![act(5, "k", 700)]);
}
