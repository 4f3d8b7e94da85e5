//! A report as an HTML page (one self-contained file with a print
//! stylesheet: A4, tables not split across pages) and as CSV (one row per
//! figure: `section,subject,figure,value,unit`, so a spreadsheet can pivot
//! it). Pure formatting.

use std::fmt::Write;

use gridscada_tagdb::Timestamp;

use crate::figures::UnitEnergy;
use crate::Report;

/// Escapes text for HTML.
fn esc(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            '\'' => o.push_str("&#39;"),
            c => o.push(c),
        }
    }
    o
}

/// `YYYY-MM-DD HH:MM:SS` UTC.
pub fn time_text(ms: i64) -> String {
    let c = Timestamp::from_millis(ms).civil_utc();
    format!(
        "{:04}-{:02}-{:02} {:02}:{:02}:{:02}",
        c.year, c.month, c.day, c.hour, c.minute, c.second
    )
}

fn num(v: Option<f64>, digits: usize) -> String {
    match v {
        Some(v) if v.is_finite() => format!("{:.digits$}", v + 0.0),
        _ => "—".to_string(),
    }
}

fn duration_text(s: f64) -> String {
    let s = s.max(0.0).round() as u64;
    format!("{}:{:02}:{:02}", s / 3600, s / 60 % 60, s % 60)
}

fn kind_label(u: &UnitEnergy) -> &'static str {
    match u.kind {
        gridscada_config::UnitKind::Pv => "PV",
        gridscada_config::UnitKind::Wind => "Wind",
        gridscada_config::UnitKind::Storage => "Battery",
        gridscada_config::UnitKind::Diesel => "Diesel",
    }
}

const STYLE: &str = r#"
body { font: 13px/1.4 system-ui, sans-serif; color: #222; margin: 24px; }
h1 { font-size: 20px; margin: 0 0 4px; }
h2 { font-size: 16px; margin: 20px 0 6px; border-bottom: 1px solid #888; }
.meta { color: #555; margin-bottom: 12px; }
table { border-collapse: collapse; margin: 4px 0 12px; }
th, td { border: 1px solid #bbb; padding: 3px 8px; text-align: left; }
td.n, th.n { text-align: right; font-variant-numeric: tabular-nums; }
th { background: #eee; }
.note { color: #555; font-size: 12px; }
@media print {
  @page { size: A4; margin: 15mm; }
  body { margin: 0; font-size: 9pt; }
  th, td { padding: 2px 5px; }
  h2 { break-after: avoid; }
  table { break-inside: avoid; }
  th { background: #eee !important; -webkit-print-color-adjust: exact; print-color-adjust: exact; }
}
"#;

/// The report as one HTML page.
pub fn html(r: &Report) -> String {
    let mut o = String::new();
    let title = esc(&format!("{} — {}", r.title(), r.site));
    let _ = write!(
        o,
        "<!doctype html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\
         <title>{title}</title><style>{STYLE}</style></head><body>\
         <h1>{title}</h1><p class=\"meta\">{} to {} UTC · generated {} UTC</p>",
        time_text(r.from),
        time_text(r.to),
        time_text(r.generated_at)
    );
    let e = &r.energy;
    o.push_str("<h2>Energy</h2><table><tr><th>Panel</th><th>Meter</th><th class=\"n\">kWh</th><th class=\"n\">Data</th></tr>");
    for p in &e.panels {
        let _ = write!(
            o,
            "<tr><td>{} ({})</td><td>{}</td><td class=\"n\">{}</td><td class=\"n\">{:.0} %</td></tr>",
            esc(&p.name),
            esc(&p.id),
            esc(p.meter.as_deref().unwrap_or("no meter")),
            num(p.kwh, 1),
            p.coverage * 100.0
        );
    }
    o.push_str("</table>");
    let zones: Vec<_> = e
        .panels
        .iter()
        .flat_map(|p| p.zones.iter().map(move |z| (p, z)))
        .filter(|(_, z)| z.meter.is_some())
        .collect();
    if zones.is_empty() {
        o.push_str(
            "<p class=\"note\">No zone has a meter of its own: zone energy is not measured.</p>",
        );
    } else {
        o.push_str("<table><tr><th>Zone</th><th>Meter</th><th class=\"n\">kWh</th></tr>");
        for (p, z) in zones {
            let _ = write!(
                o,
                "<tr><td>{} zone {}</td><td>{}</td><td class=\"n\">{}</td></tr>",
                esc(&p.id),
                z.zone,
                esc(z.meter.as_deref().unwrap_or("")),
                num(z.kwh, 1)
            );
        }
        o.push_str("</table>");
    }
    if !e.units.is_empty() {
        o.push_str(
            "<table><tr><th>Unit</th><th>Kind</th><th class=\"n\">kWh out</th><th class=\"n\">kWh in</th>\
             <th class=\"n\">Run h</th><th class=\"n\">Starts</th><th class=\"n\">Fuel l</th>\
             <th class=\"n\">Cycles</th><th class=\"n\">Cost</th></tr>",
        );
        for u in &e.units {
            let diesel = u.kind == gridscada_config::UnitKind::Diesel;
            let storage = u.kind == gridscada_config::UnitKind::Storage;
            let _ =
                write!(
                o,
                "<tr><td>{} ({})</td><td>{}</td><td class=\"n\">{:.1}</td><td class=\"n\">{}</td>\
                 <td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td>\
                 <td class=\"n\">{}</td><td class=\"n\">{:.2}</td></tr>",
                esc(&u.name),
                esc(&u.id),
                kind_label(u),
                u.kwh,
                if storage { format!("{:.1}", u.charged_kwh) } else { String::new() },
                if diesel { format!("{:.2}", u.run_h) } else { String::new() },
                if diesel { u.starts.to_string() } else { String::new() },
                if diesel { num(u.fuel_l, 1) } else { String::new() },
                if storage { num(u.cycles, 2) } else { String::new() },
                u.cost
            );
        }
        let _ = write!(
            o,
            "</table><table><tr><th>Demand kWh</th><td class=\"n\">{}</td></tr>\
             <tr><th>Produced kWh</th><td class=\"n\">{:.1}</td></tr>\
             <tr><th>PV and wind share</th><td class=\"n\">{}</td></tr>\
             <tr><th>Cost</th><td class=\"n\">{}</td></tr></table>",
            num(e.demand_kwh, 1),
            e.produced_kwh,
            e.renewable_share
                .map_or("—".to_string(), |s| format!("{:.1} %", s * 100.0)),
            num(e.cost, 2)
        );
    }
    let a = &r.alarms;
    let _ = write!(
        o,
        "<h2>Alarms</h2><table><tr><th>Activations</th><td class=\"n\">{}</td></tr>",
        a.activations
    );
    for (p, n) in &a.by_priority {
        let _ = write!(o, "<tr><th>Priority {p}</th><td class=\"n\">{n}</td></tr>");
    }
    let _ = write!(
        o,
        "<tr><th>Acknowledged</th><td class=\"n\">{}</td></tr>\
         <tr><th>Not acknowledged in the period</th><td class=\"n\">{}</td></tr>\
         <tr><th>Time to acknowledge: mean / median / 90 % / max</th><td class=\"n\">{} / {} / {} / {} s</td></tr></table>",
        a.acknowledged,
        a.unacknowledged,
        num(a.ack_mean_s, 0),
        num(a.ack_median_s, 0),
        num(a.ack_p90_s, 0),
        num(a.ack_max_s, 0)
    );
    if !a.top.is_empty() {
        o.push_str("<table><tr><th>Top alarms</th><th>Tag</th><th class=\"n\">Priority</th><th class=\"n\">Count</th></tr>");
        for t in &a.top {
            let _ = write!(
                o,
                "<tr><td>{}</td><td>{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td></tr>",
                esc(&t.message),
                esc(&t.tag),
                t.priority,
                t.count
            );
        }
        o.push_str("</table>");
    }
    o.push_str(
        "<h2>Outages</h2><table><tr><th>Panel</th><th class=\"n\">Zones</th><th class=\"n\">Sustained</th>\
         <th class=\"n\">Momentary</th><th class=\"n\">SAIFI</th><th class=\"n\">SAIDI min</th>\
         <th class=\"n\">MAIFI</th><th class=\"n\">ENS kWh</th><th class=\"n\">Data</th></tr>",
    );
    for p in &r.outages.panels {
        let _ = write!(
            o,
            "<tr><td>{} ({})</td><td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td>\
             <td class=\"n\">{:.2}</td><td class=\"n\">{:.1}</td><td class=\"n\">{:.2}</td>\
             <td class=\"n\">{:.2}</td><td class=\"n\">{:.0} %</td></tr>",
            esc(&p.name),
            esc(&p.id),
            p.zones,
            p.sustained,
            p.momentary,
            p.saifi + 0.0,
            p.saidi_min + 0.0,
            p.maifi + 0.0,
            p.ens_kwh + 0.0,
            p.coverage * 100.0
        );
    }
    o.push_str("</table>");
    if r.outages.interruptions.is_empty() {
        o.push_str("<p class=\"note\">No interruption.</p>");
    } else {
        o.push_str(
            "<table><tr><th>Panel</th><th class=\"n\">Zone</th><th>Start UTC</th><th>End UTC</th>\
             <th class=\"n\">Duration</th><th>Kind</th><th class=\"n\">ENS kWh</th></tr>",
        );
        for i in &r.outages.interruptions {
            let _ = write!(
                o,
                "<tr><td>{}</td><td class=\"n\">{}</td><td>{}{}</td><td>{}</td><td class=\"n\">{}</td>\
                 <td>{}</td><td class=\"n\">{}</td></tr>",
                esc(&i.panel),
                i.zone,
                if i.began_before { "before " } else { "" },
                time_text(i.start),
                i.end.map_or("still out".to_string(), time_text),
                duration_text(i.duration_s),
                if i.sustained { "sustained" } else { "momentary" },
                num(i.ens_kwh, 2)
            );
        }
        o.push_str("</table>");
    }
    o.push_str(
        "<p class=\"note\">Zones stand for customers in SAIFI/SAIDI/MAIFI; interruptions of 5 minutes or \
         more are sustained. Energy not supplied is the load before the interruption over its \
         duration. \"Data\" is the share of the period the historian knew the values.</p></body></html>\n",
    );
    o
}

/// A CSV field with the formula guard of the historian export.
fn field(o: &mut String, s: &str) {
    gridscada_store::csv_field(o, s);
}

/// One row. `value` is a number or time this module formatted, written as
/// is (a negative number is not a formula); the names go through the guard.
fn row(o: &mut String, section: &str, subject: &str, figure: &str, value: &str, unit: &str) {
    field(o, section);
    o.push(',');
    field(o, subject);
    o.push(',');
    field(o, figure);
    o.push(',');
    o.push_str(value);
    o.push(',');
    field(o, unit);
    o.push('\n');
}

fn val(v: Option<f64>) -> String {
    // + 0.0 turns a negative zero into zero.
    v.filter(|v| v.is_finite())
        .map_or(String::new(), |v| format!("{:.4}", v + 0.0))
}

/// The report as CSV: `section,subject,figure,value,unit`.
pub fn csv(r: &Report) -> String {
    let mut o = String::from("section,subject,figure,value,unit\n");
    let period = r.id.as_str();
    row(&mut o, "report", period, "from", &time_text(r.from), "UTC");
    row(&mut o, "report", period, "to", &time_text(r.to), "UTC");
    for p in &r.energy.panels {
        row(&mut o, "energy", &p.id, "energy", &val(p.kwh), "kWh");
        row(
            &mut o,
            "energy",
            &p.id,
            "coverage",
            &val(Some(p.coverage)),
            "share",
        );
        for z in &p.zones {
            if z.meter.is_some() {
                row(
                    &mut o,
                    "energy",
                    &format!("{}.zone{}", p.id, z.zone),
                    "energy",
                    &val(z.kwh),
                    "kWh",
                );
            }
        }
    }
    for u in &r.energy.units {
        let s = u.id.as_str();
        row(&mut o, "unit", s, "energy_out", &val(Some(u.kwh)), "kWh");
        row(
            &mut o,
            "unit",
            s,
            "energy_in",
            &val(Some(u.charged_kwh)),
            "kWh",
        );
        row(&mut o, "unit", s, "run_hours", &val(Some(u.run_h)), "h");
        row(&mut o, "unit", s, "starts", &u.starts.to_string(), "");
        row(&mut o, "unit", s, "fuel", &val(u.fuel_l), "l");
        row(&mut o, "unit", s, "cycles", &val(u.cycles), "");
        row(&mut o, "unit", s, "cost", &val(Some(u.cost)), "");
    }
    if !r.energy.units.is_empty() {
        row(
            &mut o,
            "microgrid",
            "",
            "demand",
            &val(r.energy.demand_kwh),
            "kWh",
        );
        row(
            &mut o,
            "microgrid",
            "",
            "produced",
            &val(Some(r.energy.produced_kwh)),
            "kWh",
        );
        row(
            &mut o,
            "microgrid",
            "",
            "renewable_share",
            &val(r.energy.renewable_share),
            "share",
        );
        row(&mut o, "microgrid", "", "cost", &val(r.energy.cost), "");
    }
    let a = &r.alarms;
    row(
        &mut o,
        "alarms",
        "",
        "activations",
        &a.activations.to_string(),
        "",
    );
    for (p, n) in &a.by_priority {
        row(
            &mut o,
            "alarms",
            &format!("priority {p}"),
            "activations",
            &n.to_string(),
            "",
        );
    }
    row(
        &mut o,
        "alarms",
        "",
        "acknowledged",
        &a.acknowledged.to_string(),
        "",
    );
    row(
        &mut o,
        "alarms",
        "",
        "unacknowledged",
        &a.unacknowledged.to_string(),
        "",
    );
    row(&mut o, "alarms", "", "ack_mean", &val(a.ack_mean_s), "s");
    row(
        &mut o,
        "alarms",
        "",
        "ack_median",
        &val(a.ack_median_s),
        "s",
    );
    row(&mut o, "alarms", "", "ack_p90", &val(a.ack_p90_s), "s");
    row(&mut o, "alarms", "", "ack_max", &val(a.ack_max_s), "s");
    for t in &a.top {
        row(
            &mut o,
            "top_alarm",
            &t.alarm_key,
            "activations",
            &t.count.to_string(),
            "",
        );
    }
    for p in &r.outages.panels {
        let s = p.id.as_str();
        row(
            &mut o,
            "reliability",
            s,
            "sustained",
            &p.sustained.to_string(),
            "",
        );
        row(
            &mut o,
            "reliability",
            s,
            "momentary",
            &p.momentary.to_string(),
            "",
        );
        row(
            &mut o,
            "reliability",
            s,
            "saifi",
            &val(Some(p.saifi)),
            "per zone",
        );
        row(
            &mut o,
            "reliability",
            s,
            "saidi",
            &val(Some(p.saidi_min)),
            "min per zone",
        );
        row(
            &mut o,
            "reliability",
            s,
            "maifi",
            &val(Some(p.maifi)),
            "per zone",
        );
        row(
            &mut o,
            "reliability",
            s,
            "ens",
            &val(Some(p.ens_kwh)),
            "kWh",
        );
    }
    for i in &r.outages.interruptions {
        let s = format!("{}.zone{}", i.panel, i.zone);
        row(
            &mut o,
            "interruption",
            &s,
            "start",
            &time_text(i.start),
            "UTC",
        );
        row(
            &mut o,
            "interruption",
            &s,
            "end",
            &i.end.map_or(String::new(), time_text),
            "UTC",
        );
        row(
            &mut o,
            "interruption",
            &s,
            "duration",
            &val(Some(i.duration_s)),
            "s",
        );
        row(&mut o, "interruption", &s, "ens", &val(i.ens_kwh), "kWh");
    }
    o
}
