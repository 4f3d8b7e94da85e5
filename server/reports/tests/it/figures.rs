//! The report's figures on a second test plant (three panels, no microgrid)
//! from hand-made historian samples whose totals are known.

use std::path::Path;

use gridscada_config::Plant;
use gridscada_reports::figures::{alarm_figures, alarm_place, energy, outages, SampleMap};
use gridscada_reports::series::Sample;
use gridscada_store::AlarmTransition;
use gridscada_tagdb::Timestamp;

const H: i64 = 3_600_000;
const MIN: i64 = 60_000;

fn plant() -> Plant {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/plants/three-panels");
    gridscada_config::load_path(&dir).expect("the test plant loads")
}

/// Samples of a step function given as (from, value) changes, re-logged
/// every 20 s, within the tags' max interval (30 s), as the recorder does.
fn steps(changes: &[(i64, f64)], until: i64) -> Vec<Sample> {
    let mut out = Vec::new();
    for (i, &(t, v)) in changes.iter().enumerate() {
        let next = changes.get(i + 1).map_or(until, |c| c.0);
        let mut at = t;
        while at < next {
            out.push(Sample::new(at, v));
            at += 20_000;
        }
    }
    out
}

/// Panel `pa` (2 zones): 4 kW on zone 1, 6 kW on zone 2. Zone 2 is out from
/// 01:00 to 02:00; the ELCB trips at 03:00 for one minute.
fn day() -> SampleMap {
    let end = 4 * H;
    let mut m = SampleMap::new();
    m.insert(
        "PA.PA.P_kW".into(),
        steps(
            &[
                (-H, 10.0),
                (H, 4.0),
                (2 * H, 10.0),
                (3 * H, 0.0),
                (3 * H + MIN, 10.0),
            ],
            end,
        ),
    );
    m.insert(
        "PA.ELCB.Closed".into(),
        steps(&[(-H, 1.0), (3 * H, 0.0), (3 * H + MIN, 1.0)], end),
    );
    m.insert("PA.MCCB.Closed".into(), steps(&[(-H, 1.0)], end));
    m.insert("PA.Zone1.Closed".into(), steps(&[(-H, 1.0)], end));
    m.insert(
        "PA.Zone2.Closed".into(),
        steps(&[(-H, 1.0), (H, 0.0), (2 * H, 1.0)], end),
    );
    m
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-6
}

#[test]
fn panel_energy_is_the_meter_integrated() {
    let e = energy(&plant(), &day(), 0, 4 * H);
    let pa = &e.panels[0];
    assert_eq!(pa.meter.as_deref(), Some("PA.PA.P_kW"));
    let want = 40.0 - 6.0 - 10.0 / 60.0;
    assert!(close(pa.kwh.unwrap(), want), "{:?}", pa.kwh);
    assert!(close(pa.coverage, 1.0));
    // The other panels have no data: unknown, not zero.
    assert_eq!(e.panels[1].kwh, None);
    assert!(e.units.is_empty() && e.renewable_share.is_none());
}

#[test]
fn interruptions_durations_and_energy_not_supplied() {
    let o = outages(&plant(), &day(), 0, 4 * H, &Default::default());
    let mine: Vec<_> = o.interruptions.iter().filter(|i| i.panel == "pa").collect();
    assert_eq!(mine.len(), 3, "{mine:#?}");
    let z2 = mine.iter().find(|i| i.zone == 2 && i.start == H).unwrap();
    assert_eq!(z2.end, Some(2 * H));
    assert!(close(z2.duration_s, 3600.0) && z2.sustained);
    assert!(close(z2.ens_kwh.unwrap(), 6.0), "{:?}", z2.ens_kwh);
    for zone in [1, 2] {
        let trip = mine
            .iter()
            .find(|i| i.zone == zone && i.start == 3 * H)
            .unwrap();
        assert!(close(trip.duration_s, 60.0) && !trip.sustained);
        // The 10 kW drop shared by the two zones out, for a minute.
        assert!(close(trip.ens_kwh.unwrap(), 5.0 / 60.0));
    }
    let pa = o.panels.iter().find(|p| p.id == "pa").unwrap();
    assert_eq!((pa.sustained, pa.momentary), (1, 2));
    assert!(close(pa.saifi, 0.5) && close(pa.saidi_min, 30.0) && close(pa.maifi, 1.0));
    assert!(close(pa.ens_kwh, 6.0 + 10.0 / 60.0));
    // No breaker data for the other panels: no interruption invented.
    let pb = o.panels.iter().find(|p| p.id == "pb").unwrap();
    assert_eq!((pb.sustained, pb.momentary, pb.coverage), (0, 0, 0.0));
}

#[test]
fn an_interruption_still_running_at_the_end_counts_to_the_end() {
    let mut d = day();
    d.insert(
        "PA.PA.P_kW".into(),
        steps(
            &[
                (-H, 10.0),
                (H, 4.0),
                (2 * H, 10.0),
                (3 * H, 0.0),
                (3 * H + MIN, 10.0),
                (3 * H + 30 * MIN, 6.0),
            ],
            4 * H,
        ),
    );
    d.insert(
        "PA.Zone1.Closed".into(),
        steps(&[(-H, 1.0), (3 * H + 30 * MIN, 0.0)], 4 * H),
    );
    let o = outages(&plant(), &d, 0, 4 * H, &Default::default());
    let open = o
        .interruptions
        .iter()
        .find(|i| i.zone == 1 && i.end.is_none())
        .unwrap();
    assert!(close(open.duration_s, 1800.0) && open.sustained);
    // Zone 1's 4 kW for half an hour.
    assert!(close(open.ens_kwh.unwrap(), 2.0), "{:?}", open.ens_kwh);
}

fn transition(ts: i64, key: &str, priority: i32, activation: bool, cause: &str) -> AlarmTransition {
    AlarmTransition {
        ts: Timestamp::from_millis(ts),
        alarm_key: key.into(),
        tag: key.into(),
        kind: "hi".into(),
        from_state: String::new(),
        to_state: String::new(),
        cause: Some(cause.into()),
        activation,
        value: None,
        limit: None,
        user: None,
        message: format!("{key} high"),
        priority,
        selection: String::new(),
    }
}

#[test]
fn alarm_counts_top_alarms_and_time_to_acknowledge() {
    let t = [
        transition(0, "a", 800, true, "activate"),
        transition(10_000, "b", 500, true, "activate"),
        transition(20_000, "a", 800, false, "return"),
        transition(30_000, "a", 800, true, "activate"),
        transition(60_000, "a", 800, false, "ack"),
        transition(70_000, "b", 500, false, "ack"),
        transition(80_000, "c", 500, true, "activate"),
    ];
    let f = alarm_figures(&plant(), &t);
    assert_eq!(f.activations, 4);
    assert_eq!(f.by_priority, vec![(800, 2), (500, 2)]);
    assert_eq!(f.top[0].alarm_key, "a");
    assert_eq!(f.top[0].count, 2);
    assert_eq!((f.acknowledged, f.unacknowledged), (3, 1));
    // 60 s, 30 s and 60 s.
    assert_eq!(f.ack_max_s, Some(60.0));
    assert_eq!(f.ack_median_s, Some(60.0));
    assert!(close(f.ack_mean_s.unwrap(), 50.0));
}

#[test]
fn an_alarm_is_placed_by_its_tag_else_its_selection_by_configured_names() {
    let p = plant();
    // A tag under a panel's prefix: the panel's name.
    assert_eq!(
        alarm_place(&p, "PA.Zone1.Closed", "anything"),
        "Pump station panel"
    );
    // No tag (a panel sequence's alarm, grouped under its panel's prefix).
    assert_eq!(alarm_place(&p, "", "PB"), "Workshop panel");
    // A prefix is a whole first part: PAX is not under PA.
    assert_eq!(alarm_place(&p, "PAX.Volts", "Yard"), "Yard");
    assert_eq!(alarm_place(&p, "", ""), "");
}

/// A day of `pa` with three alarms, one of a sequence (no tag),
/// acknowledged after 8 h 45 min, 125 s and 125 s, as a report.
fn report(currency: Option<&str>) -> gridscada_reports::Report {
    let p = plant();
    let mut seq = transition(0, "pa:zone2.isolated", 700, true, "activate");
    seq.tag = String::new();
    seq.selection = "PA".into();
    seq.message = "zone 2 is faulty and isolated (left off)".into();
    let mut seq_ack = seq.clone();
    seq_ack.ts = Timestamp::from_millis(8 * H + 45 * MIN);
    seq_ack.activation = false;
    seq_ack.cause = Some("ack".into());
    let volts = transition(H, "PA.PA.V_L1", 500, true, "activate");
    let volts_ack = transition(H + 125_000, "PA.PA.V_L1", 500, false, "ack");
    let volts2 = transition(2 * H, "PA.PA.V_L2", 500, true, "activate");
    let volts2_ack = transition(2 * H + 125_000, "PA.PA.V_L2", 500, false, "ack");
    let period = gridscada_reports::Period::parse("1970-01-01").unwrap();
    gridscada_reports::Report {
        site: "test".into(),
        currency: currency.map(str::to_string),
        period,
        id: period.to_string(),
        from: 0,
        to: 4 * H,
        generated_at: 4 * H,
        energy: energy(&p, &day(), 0, 4 * H),
        alarms: alarm_figures(&p, &[seq, volts, volts_ack, volts2, volts2_ack, seq_ack]),
        outages: outages(&p, &day(), 0, 4 * H, &Default::default()),
    }
}

#[test]
fn the_page_names_where_each_top_alarm_is_and_writes_durations_in_words() {
    let html = gridscada_reports::render::html(&report(Some("EUR")));
    assert!(
        html.contains(
            "<td>Pump station panel · pa:zone2.isolated — zone 2 is faulty and isolated (left off)</td>"
        ),
        "{html}"
    );
    assert!(html.contains("<td>Pump station panel · PA.PA.V_L1 — PA.PA.V_L1 high</td>"));
    // Time to acknowledge: 125 s, 125 s and 8 h 45 min: their mean, median
    // and longest.
    let ack = |figure: &str, words: &str| {
        format!("<tr><th>Time to acknowledge: {figure}</th><td class=\"n\">{words}</td></tr>")
    };
    assert!(html.contains(&ack("mean", "2 h 56 min")), "{html}");
    assert!(html.contains(&ack("median", "2 min 05 s")), "{html}");
    assert!(html.contains(&ack("longest", "8 h 45 min")), "{html}");
    // The interruption of an hour, and the trips of a minute.
    assert!(html.contains("<td class=\"n\">1 h 00 min</td>"), "{html}");
    assert!(html.contains("<td class=\"n\">1 min 00 s</td>"), "{html}");
}

#[test]
fn every_figure_is_defined_in_the_notes_and_costs_carry_the_currency() {
    let html = gridscada_reports::render::html(&report(Some("EUR")));
    let notes = &html[html
        .find("<h2 id=\"definitions\">")
        .expect("a Definitions section")..];
    for figure in [
        "Data",
        "Panel kWh",
        "Zone kWh",
        "kWh out",
        "kWh in",
        "Run time",
        "Fuel l",
        "Cycles",
        "Cost",
        "Demand kWh",
        "Produced kWh",
        "PV and wind share",
        "Activations",
        "Acknowledged",
        "Time to acknowledge",
        "Top alarms",
        "SAIFI, SAIDI, MAIFI",
        "ENS kWh",
    ] {
        assert!(
            notes.contains(&format!("<dt>{figure}</dt>")),
            "{figure} is not defined"
        );
    }
    assert!(notes.contains("Battery discharge is in the denominator"));
    assert!(notes.contains("in EUR"));
    assert!(notes.contains("5 min 00 s or more"));
    let csv = gridscada_reports::render::csv(&report(Some("EUR")));
    assert!(
        !csv.lines()
            .any(|l| l.contains(",cost,") && !l.ends_with(",EUR")),
        "{csv}"
    );
    // Without a currency, costs are in the prices' own unit, said so.
    let html = gridscada_reports::render::html(&report(None));
    assert!(html.contains("in cost units"));
}
