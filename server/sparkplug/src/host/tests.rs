//! The host's pure parts: births to tags, aliases, deaths and rebirths,
//! `seq` gaps, commands and their confirmation.

use std::time::Duration;

use gridscada_tagdb::{
    QualityCode, Sample, TagDb, TagMeta, Timestamp, Value, ValueKind, WriteError,
};

use super::writer::Pending;
use super::*;
use crate::datatype::DataType;
use crate::proto::{Metric, MetricValue, Payload, PropertySet, PropertyValue, PropertyValueKind};
use crate::topic::{MessageType, Topic};

const G: &str = "Grid";

fn sites() -> Sites {
    Sites::new(SitesPolicy {
        group: G.into(),
        nodes: vec![],
        device_in_name: false,
        rebirth_interval: Duration::from_secs(5),
    })
}

fn db() -> TagDb {
    TagDb::with_room([TagMeta::new("Local.A", ValueKind::Float)], 100).unwrap()
}

fn at(s: i64) -> Timestamp {
    Timestamp::from_millis(1_700_000_000_000 + s * 1000)
}

fn metric(name: &str, alias: u64, ty: DataType, v: MetricValue) -> Metric {
    Metric {
        name: Some(name.into()),
        alias: Some(alias),
        datatype: Some(ty.code()),
        value: Some(v),
        ..Default::default()
    }
}

fn by_alias(alias: u64, v: MetricValue) -> Metric {
    Metric {
        alias: Some(alias),
        value: Some(v),
        ..Default::default()
    }
}

fn msg(seq: Option<u64>, metrics: Vec<Metric>) -> Payload {
    Payload {
        timestamp: Some(1_700_000_000_000),
        seq,
        metrics,
        ..Default::default()
    }
}

fn nbirth(bd: u64) -> Payload {
    let mut volts = metric(
        "Feeder/Volts",
        1,
        DataType::Float,
        MetricValue::Float(230.5),
    );
    let mut props = PropertySet::default();
    props.push(
        "engUnit",
        PropertyValue {
            r#type: Some(DataType::String.code()),
            value: Some(PropertyValueKind::String("V".into())),
            ..Default::default()
        },
    );
    volts.properties = Some(props);
    msg(
        Some(0),
        vec![
            metric("bdSeq", 0, DataType::Int64, MetricValue::Long(bd)),
            metric(REBIRTH, 99, DataType::Boolean, MetricValue::Boolean(false)),
            volts,
        ],
    )
}

fn dbirth(seq: u64) -> Payload {
    let mut setpoint = metric("PV1/P_set", 2, DataType::Double, MetricValue::Double(10.0));
    let mut props = PropertySet::default();
    props.push(
        "writable",
        PropertyValue {
            r#type: Some(DataType::Boolean.code()),
            value: Some(PropertyValueKind::Boolean(true)),
            ..Default::default()
        },
    );
    setpoint.properties = Some(props);
    msg(
        Some(seq),
        vec![
            setpoint,
            metric(
                "PV1/Running",
                3,
                DataType::Boolean,
                MetricValue::Boolean(true),
            ),
        ],
    )
}

fn node(kind: MessageType, n: &str) -> Topic {
    Topic::node(G, kind, n)
}

fn device(kind: MessageType, n: &str) -> Topic {
    Topic::device(G, kind, n, "PV1")
}

/// Runs a message and applies its samples, as the session task does.
fn run(s: &mut Sites, db: &TagDb, topic: Topic, p: Payload, t: i64) -> Effects {
    let fx = s.handle(db, &topic, &p, at(t));
    db.apply(fx.samples.iter().cloned());
    fx
}

fn born_site(s: &mut Sites, db: &TagDb, n: &str) {
    run(s, db, node(MessageType::NBirth, n), nbirth(7), 0);
    run(s, db, device(MessageType::DBirth, n), dbirth(1), 0);
}

#[test]
fn births_become_tags_under_the_site_prefix() {
    let (mut s, db) = (sites(), db());
    let fx = run(
        &mut s,
        &db,
        node(MessageType::NBirth, "site-a"),
        nbirth(7),
        0,
    );
    assert!(fx.problems.is_empty(), "{:?}", fx.problems);
    // bdSeq and Node Control metrics are no tags.
    assert_eq!(fx.added, 1);
    let volts = db.id("site-a.Feeder.Volts").unwrap();
    let meta = db.meta(volts).unwrap();
    assert_eq!(
        (meta.kind, meta.units.as_str(), meta.writable),
        (ValueKind::Float, "V", false)
    );
    assert_eq!(db.get(volts).unwrap().value, Value::Float(230.5));
    assert!(db.get(volts).unwrap().quality.is_good());

    let fx = run(
        &mut s,
        &db,
        device(MessageType::DBirth, "site-a"),
        dbirth(1),
        0,
    );
    assert_eq!(fx.added, 2);
    let sp = db.id("site-a.PV1.P_set").unwrap();
    assert!(db.meta(sp).unwrap().writable);
    assert_eq!(
        db.meta(db.id("site-a.PV1.Running").unwrap()).unwrap().kind,
        ValueKind::Bool
    );
    assert_eq!(s.online(), 1);

    // A second site gets its own tags; a rebirth re-uses the same ones.
    born_site(&mut s, &db, "site-b");
    assert!(db.id("site-b.PV1.P_set").is_some());
    let before = db.len();
    born_site(&mut s, &db, "site-a");
    assert_eq!(db.len(), before);
    assert_eq!(s.online(), 2);
}

#[test]
fn data_by_alias_updates_the_tag_with_its_own_timestamp() {
    let (mut s, db) = (sites(), db());
    born_site(&mut s, &db, "site-a");
    let mut m = by_alias(2, MetricValue::Double(12.5));
    m.timestamp = Some(1_700_000_000_500);
    let fx = run(
        &mut s,
        &db,
        device(MessageType::DData, "site-a"),
        msg(Some(2), vec![m]),
        1,
    );
    assert!(fx.problems.is_empty() && fx.rebirth.is_none());
    let got = db.get_by_name("site-a.PV1.P_set").unwrap();
    assert_eq!(got.value, Value::Float(12.5));
    assert_eq!(got.timestamp, Timestamp::from_millis(1_700_000_000_500));
}

#[test]
fn a_seq_gap_asks_for_a_rebirth_at_most_once_per_interval() {
    let (mut s, db) = (sites(), db());
    born_site(&mut s, &db, "site-a");
    let data = |seq, v| msg(Some(seq), vec![by_alias(1, MetricValue::Float(v))]);
    assert!(run(
        &mut s,
        &db,
        node(MessageType::NData, "site-a"),
        data(2, 231.0),
        1
    )
    .rebirth
    .is_none());
    // 3 is lost.
    let fx = run(
        &mut s,
        &db,
        node(MessageType::NData, "site-a"),
        data(4, 232.0),
        2,
    );
    assert_eq!(
        fx.problems,
        [Problem::SeqGap {
            node: "site-a".into(),
            expected: 3,
            got: 4
        }]
    );
    assert_eq!(fx.rebirth.as_deref(), Some("site-a"));
    // The value is still taken, and the count follows the new seq.
    assert_eq!(
        db.get_by_name("site-a.Feeder.Volts").unwrap().value,
        Value::Float(232.0)
    );
    assert!(run(
        &mut s,
        &db,
        node(MessageType::NData, "site-a"),
        data(5, 1.0),
        3
    )
    .problems
    .is_empty());
    // Another gap within the interval: counted, no second request.
    let fx = run(
        &mut s,
        &db,
        node(MessageType::NData, "site-a"),
        data(9, 1.0),
        4,
    );
    assert_eq!(fx.problems.len(), 1);
    assert!(fx.rebirth.is_none());
    let fx = run(
        &mut s,
        &db,
        node(MessageType::NData, "site-a"),
        data(20, 1.0),
        8,
    );
    assert_eq!(fx.rebirth.as_deref(), Some("site-a"));
    // seq wraps from 255 to 0.
    run(
        &mut s,
        &db,
        node(MessageType::NData, "site-a"),
        data(255, 1.0),
        20,
    );
    assert!(run(
        &mut s,
        &db,
        node(MessageType::NData, "site-a"),
        data(0, 1.0),
        20
    )
    .problems
    .is_empty());
}

#[test]
fn an_unknown_alias_changes_nothing_and_asks_for_a_rebirth() {
    let (mut s, db) = (sites(), db());
    born_site(&mut s, &db, "site-a");
    let seq_before = db.seq();
    let fx = run(
        &mut s,
        &db,
        device(MessageType::DData, "site-a"),
        msg(Some(2), vec![by_alias(42, MetricValue::Double(1.0))]),
        1,
    );
    assert_eq!(
        fx.problems,
        [Problem::UnknownAlias {
            node: "site-a".into(),
            alias: 42
        }]
    );
    assert_eq!(fx.rebirth.as_deref(), Some("site-a"));
    assert_eq!(db.seq(), seq_before);
}

#[test]
fn data_before_a_birth_is_refused_and_asks_for_one() {
    let (mut s, db) = (sites(), db());
    let fx = run(
        &mut s,
        &db,
        node(MessageType::NData, "site-x"),
        msg(Some(5), vec![by_alias(1, MetricValue::Float(1.0))]),
        0,
    );
    assert_eq!(
        fx.problems,
        [Problem::NotBorn {
            node: "site-x".into()
        }]
    );
    assert_eq!(fx.rebirth.as_deref(), Some("site-x"));
    assert_eq!(db.len(), 1);
}

#[test]
fn death_turns_tags_bad_and_rebirth_good_again() {
    let (mut s, db) = (sites(), db());
    born_site(&mut s, &db, "site-a");
    born_site(&mut s, &db, "site-b");
    // A device death: only that device's tags.
    run(
        &mut s,
        &db,
        device(MessageType::DDeath, "site-a"),
        msg(Some(2), vec![]),
        1,
    );
    let sp = db.get_by_name("site-a.PV1.P_set").unwrap();
    assert_eq!(
        (sp.quality.code, sp.quality.reason.as_deref()),
        (QualityCode::Bad, Some(DEVICE_OFFLINE))
    );
    assert_eq!(sp.value, Value::Float(10.0), "the last value is kept");
    assert!(db
        .get_by_name("site-a.Feeder.Volts")
        .unwrap()
        .quality
        .is_good());

    // A stale will (an earlier session's bdSeq) changes nothing.
    let death = |bd| {
        msg(
            None,
            vec![metric("bdSeq", 0, DataType::Int64, MetricValue::Long(bd))],
        )
    };
    let fx = run(
        &mut s,
        &db,
        node(MessageType::NDeath, "site-a"),
        death(6),
        2,
    );
    assert_eq!(
        fx.problems,
        [Problem::StaleDeath {
            node: "site-a".into()
        }]
    );
    assert!(db
        .get_by_name("site-a.Feeder.Volts")
        .unwrap()
        .quality
        .is_good());

    let fx = run(
        &mut s,
        &db,
        node(MessageType::NDeath, "site-a"),
        death(7),
        3,
    );
    assert!(fx.online_changed);
    for tag in [
        "site-a.Feeder.Volts",
        "site-a.PV1.P_set",
        "site-a.PV1.Running",
    ] {
        let q = db.get_by_name(tag).unwrap().quality;
        assert_eq!(q.reason.as_deref(), Some(SITE_OFFLINE), "{tag}");
    }
    assert!(db
        .get_by_name("site-b.Feeder.Volts")
        .unwrap()
        .quality
        .is_good());
    assert_eq!(s.online(), 1);

    born_site(&mut s, &db, "site-a");
    for tag in [
        "site-a.Feeder.Volts",
        "site-a.PV1.P_set",
        "site-a.PV1.Running",
    ] {
        assert!(db.get_by_name(tag).unwrap().quality.is_good(), "{tag}");
    }
}

#[test]
fn losing_the_broker_turns_every_remote_tag_bad() {
    let (mut s, db) = (sites(), db());
    born_site(&mut s, &db, "site-a");
    let bad = s.host_offline(&db, at(1));
    assert_eq!(bad.len(), 3);
    db.apply(bad);
    assert_eq!(
        db.get_by_name("site-a.Feeder.Volts")
            .unwrap()
            .quality
            .reason
            .as_deref(),
        Some(HOST_OFFLINE)
    );
    assert!(
        db.get_by_name("Local.A").unwrap().is_never_read(),
        "local tags untouched"
    );
    assert_eq!(s.known_nodes(), ["site-a"]);
}

#[test]
fn a_name_clash_with_a_local_tag_or_another_group_is_refused() {
    let (mut s, db) = (sites(), db());
    let clash = msg(
        Some(0),
        vec![metric("A", 1, DataType::Double, MetricValue::Double(1.0))],
    );
    let fx = run(&mut s, &db, node(MessageType::NBirth, "Local"), clash, 0);
    assert!(matches!(&fx.problems[..], [Problem::Refused { .. }]));
    assert!(db.get_by_name("Local.A").unwrap().is_never_read());
    // Another group, or a node not accepted: nothing at all.
    let other = Topic::node("Other", MessageType::NBirth, "site-a");
    assert_eq!(run(&mut s, &db, other, nbirth(1), 0).added, 0);
    let mut only_b = Sites::new(SitesPolicy {
        nodes: vec!["site-b".into()],
        ..SitesPolicy {
            group: G.into(),
            nodes: vec![],
            device_in_name: false,
            rebirth_interval: Duration::from_secs(5),
        }
    });
    assert_eq!(
        run(
            &mut only_b,
            &db,
            node(MessageType::NBirth, "site-a"),
            nbirth(1),
            0
        )
        .added,
        0
    );
}

#[test]
fn one_name_from_two_devices_is_refused_not_merged() {
    let (mut s, db) = (sites(), db());
    born_site(&mut s, &db, "site-a");
    // Device PV2 declares the same metric names as PV1: without
    // device_in_name they would be the same tags.
    let fx = run(
        &mut s,
        &db,
        Topic::device(G, MessageType::DBirth, "site-a", "PV2"),
        dbirth(2),
        0,
    );
    assert!(
        matches!(&fx.problems[..], [Problem::Refused { reason, .. }, _] if reason.contains("is already metric 'PV1/P_set' of site-a/PV1")),
        "{:?}",
        fx.problems
    );
    assert_eq!(fx.added, 0);
    // PV1's tags still follow PV1 only.
    let d = msg(Some(3), vec![by_alias(2, MetricValue::Double(99.0))]);
    run(
        &mut s,
        &db,
        Topic::device(G, MessageType::DData, "site-a", "PV2"),
        d,
        1,
    );
    assert_eq!(
        db.get_by_name("site-a.PV1.P_set").unwrap().value,
        Value::Float(10.0)
    );
}

#[test]
fn device_in_name_and_full_room() {
    let db = TagDb::with_room([], 2).unwrap();
    let mut s = Sites::new(SitesPolicy {
        group: G.into(),
        nodes: vec![],
        device_in_name: true,
        rebirth_interval: Duration::ZERO,
    });
    run(&mut s, &db, node(MessageType::NBirth, "n"), nbirth(1), 0);
    let fx = run(&mut s, &db, device(MessageType::DBirth, "n"), dbirth(1), 0);
    assert!(db.id("n.PV1.PV1.P_set").is_some());
    assert!(
        matches!(&fx.problems[..], [Problem::Refused { reason, .. }] if reason.contains("max_tags = 2")),
        "{:?}",
        fx.problems
    );
}

#[test]
fn a_write_becomes_a_dcmd_confirmed_only_by_the_reported_value() {
    let (mut s, db) = (sites(), db());
    born_site(&mut s, &db, "site-a");
    assert_eq!(
        s.command(&db, "site-a.PV1.Running", &Value::Bool(false), at(1))
            .unwrap_err(),
        WriteError::ReadOnly("site-a.PV1.Running".into())
    );
    assert_eq!(
        s.command(&db, "Local.A", &Value::Float(1.0), at(1))
            .unwrap_err(),
        WriteError::UnknownTag("Local.A".into())
    );
    assert!(matches!(
        s.command(&db, "site-a.PV1.P_set", &Value::Str("x".into()), at(1)),
        Err(WriteError::BadValue { .. })
    ));
    let (id, topic, payload, expected) = s
        .command(&db, "site-a.PV1.P_set", &Value::Int(42), at(1))
        .unwrap();
    assert_eq!(topic.to_string(), "spBv1.0/Grid/DCMD/site-a/PV1");
    assert_eq!(payload.metrics[0].name.as_deref(), Some("PV1/P_set"));
    assert_eq!(payload.metrics[0].alias, Some(2));
    assert_eq!(payload.metrics[0].value, Some(MetricValue::Double(42.0)));
    assert_eq!(expected, Value::Float(42.0));

    let mut pending = Pending::default();
    let (_, mut rx) = pending_add(&mut pending, id, expected);
    // A report of another value does not confirm it.
    pending.offer(&[(id, Sample::good(10.0, at(2)))], |_| "site-a".into());
    assert!(rx.try_recv().is_err());
    pending.offer(&[(id, Sample::good(42.0, at(3)))], |_| "site-a".into());
    assert_eq!(rx.try_recv().unwrap().unwrap().value, Value::Float(42.0));

    // A site that dies first fails the write; an offline site refuses it.
    let (_, mut rx) = pending_add(&mut pending, id, Value::Float(5.0));
    let death = msg(
        None,
        vec![metric("bdSeq", 0, DataType::Int64, MetricValue::Long(7))],
    );
    let fx = run(&mut s, &db, node(MessageType::NDeath, "site-a"), death, 4);
    pending.offer(&fx.samples, |_| "site-a".into());
    assert!(
        matches!(rx.try_recv().unwrap(), Err(WriteError::Device { reason, .. }) if reason.starts_with(SITE_OFFLINE))
    );
    assert!(matches!(
        s.command(&db, "site-a.PV1.P_set", &Value::Int(1), at(5)),
        Err(WriteError::Device { reason, .. }) if reason == SITE_OFFLINE
    ));
}

fn pending_add(
    p: &mut Pending,
    id: gridscada_tagdb::TagId,
    v: Value,
) -> (
    u64,
    tokio::sync::oneshot::Receiver<Result<Sample, WriteError>>,
) {
    p.add_for_test(id, v)
}

#[test]
fn the_rebirth_request_is_the_node_control_metric() {
    let (topic, p) = sites().rebirth_command("site-a", at(0));
    assert_eq!(topic.to_string(), "spBv1.0/Grid/NCMD/site-a");
    assert_eq!(p.metrics[0].name.as_deref(), Some(REBIRTH));
    assert_eq!(p.metrics[0].value, Some(MetricValue::Boolean(true)));
}

fn str_prop(v: &str) -> PropertyValue {
    PropertyValue {
        r#type: Some(DataType::String.code()),
        value: Some(PropertyValueKind::String(v.into())),
        ..Default::default()
    }
}

#[test]
fn a_birth_carries_the_edge_alarms_of_its_metrics() {
    let (mut s, db) = (sites(), db());
    let mut p = nbirth(7);
    let volts = p
        .metrics
        .iter_mut()
        .find(|m| m.name.as_deref() == Some("Feeder/Volts"))
        .unwrap();
    volts.properties.as_mut().unwrap().push(
        PROP_ALARMS,
        str_prop("hi = { limit = 253.0, priority = 600 }\n"),
    );
    let mut bad = metric("Feeder/Amps", 5, DataType::Float, MetricValue::Float(1.0));
    let mut props = PropertySet::default();
    props.push(PROP_ALARMS, str_prop("hi = \"not a table\""));
    bad.properties = Some(props);
    p.metrics.push(bad);
    let fx = run(&mut s, &db, node(MessageType::NBirth, "site-a"), p, 0);
    assert_eq!(fx.alarms.len(), 1);
    let a = &fx.alarms[0];
    assert_eq!(
        (a.tag.as_str(), a.node.as_str(), a.metric.as_str()),
        ("site-a.Feeder.Volts", "site-a", "Feeder/Volts")
    );
    assert_eq!(a.units, "V");
    assert_eq!(*a.config.hi.as_ref().unwrap().limit.get_ref(), 253.0);
    assert!(
        fx.problems
            .iter()
            .any(|p| p.label() == "bad_metric" && p.to_string().contains("Feeder/Amps")),
        "{:?}",
        fx.problems
    );
    // The tag is taken all the same.
    assert!(db.id("site-a.Feeder.Amps").is_some());
}

#[test]
fn historical_data_goes_to_the_history_not_the_current_value() {
    let (mut s, db) = (sites(), db());
    born_site(&mut s, &db, "site-a");
    let id = db.id("site-a.Feeder.Volts").unwrap();
    let mut past = by_alias(1, MetricValue::Float(199.0));
    past.is_historical = Some(true);
    past.timestamp = Some(1_600_000_000_000);
    let fx = run(
        &mut s,
        &db,
        node(MessageType::NData, "site-a"),
        msg(Some(2), vec![past]),
        1,
    );
    assert!(fx.samples.is_empty());
    assert_eq!(fx.historical.len(), 1);
    let (hid, h) = &fx.historical[0];
    assert_eq!(*hid, id);
    assert_eq!(h.value, Value::Float(199.0));
    assert_eq!(h.timestamp, Timestamp::from_millis(1_600_000_000_000));
    assert_eq!(
        db.get(id).unwrap().value,
        Value::Float(230.5),
        "the current value stays"
    );
}
