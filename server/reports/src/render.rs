//! A report as an HTML page (one self-contained file with a print
//! stylesheet: A4, tables not split across pages) and as CSV (one row per
//! figure: `section,subject,figure,value,unit`, so a spreadsheet can pivot
//! it). Pure formatting.

use std::fmt::Write;

use gridscada_tagdb::Timestamp;

use crate::figures::{UnitEnergy, BASELINE_MS, SUSTAINED_S};
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

/// A duration as an operator reads it, the HMI's words (`fmtDuration` in
/// hmi/js/format.js): "4.2 s", "45 s", "2 min 05 s", "8 h 45 min"; every
/// duration of the report is written with it.
pub fn duration_words(s: f64) -> String {
    if !s.is_finite() {
        return "—".to_string();
    }
    let s = s.max(0.0);
    if s < 59.5 {
        let digits = if s < 9.95 { 1 } else { 0 };
        return format!("{s:.digits$} s");
    }
    if s < 3570.0 {
        let whole = s.round() as u64;
        return format!("{} min {:02} s", whole / 60, whole % 60);
    }
    let minutes = (s / 60.0).round() as u64;
    format!("{} h {:02} min", minutes / 60, minutes % 60)
}

fn duration(v: Option<f64>) -> String {
    v.map_or("—".to_string(), duration_words)
}

/// The unit costs are in: `[reports] currency`, else the prices' own.
fn cost_unit(r: &Report) -> &str {
    r.currency.as_deref().unwrap_or("cost units")
}

/// A cost with its currency, for the page: "12.34 EUR".
fn cost_text(r: &Report, v: Option<f64>) -> String {
    match v {
        Some(v) if v.is_finite() => format!("{:.2} {}", v + 0.0, esc(cost_unit(r))),
        _ => "—".to_string(),
    }
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
dl.definitions { font-size: 12px; margin: 4px 0; }
dl.definitions dt { font-weight: 600; margin-top: 6px; }
dl.definitions dd { margin: 0 0 0 16px; }
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
             <th class=\"n\">Run time</th><th class=\"n\">Starts</th><th class=\"n\">Fuel l</th>\
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
                 <td class=\"n\">{}</td><td class=\"n\">{}</td></tr>",
                esc(&u.name),
                esc(&u.id),
                kind_label(u),
                u.kwh,
                if storage { format!("{:.1}", u.charged_kwh) } else { String::new() },
                if diesel { duration_words(u.run_h * 3600.0) } else { String::new() },
                if diesel { u.starts.to_string() } else { String::new() },
                if diesel { num(u.fuel_l, 1) } else { String::new() },
                if storage { num(u.cycles, 2) } else { String::new() },
                cost_text(r, Some(u.cost))
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
            cost_text(r, e.cost)
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
         <tr><th>Time to acknowledge: mean</th><td class=\"n\">{}</td></tr>\
         <tr><th>Time to acknowledge: median</th><td class=\"n\">{}</td></tr>\
         <tr><th>Time to acknowledge: 90th percentile</th><td class=\"n\">{}</td></tr>\
         <tr><th>Time to acknowledge: longest</th><td class=\"n\">{}</td></tr></table>",
        a.acknowledged,
        a.unacknowledged,
        duration(a.ack_mean_s),
        duration(a.ack_median_s),
        duration(a.ack_p90_s),
        duration(a.ack_max_s)
    );
    if !a.top.is_empty() {
        o.push_str(
            "<table id=\"top-alarms\"><tr><th>Top alarms: where · tag — alarm</th>\
             <th class=\"n\">Priority</th><th class=\"n\">Count</th></tr>",
        );
        for t in &a.top {
            // An alarm without a tag (a panel sequence's) is named by its key.
            let tag = if t.tag.is_empty() {
                &t.alarm_key
            } else {
                &t.tag
            };
            let _ = write!(
                o,
                "<tr><td>{} · {} — {}</td><td class=\"n\">{}</td><td class=\"n\">{}</td></tr>",
                esc(if t.place.is_empty() { "—" } else { &t.place }),
                esc(tag),
                esc(&t.message),
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
            // The panel by its configured name, as in the table above.
            let panel = r
                .outages
                .panels
                .iter()
                .find(|p| p.id == i.panel)
                .map_or_else(|| i.panel.clone(), |p| format!("{} ({})", p.name, p.id));
            let _ = write!(
                o,
                "<tr><td>{}</td><td class=\"n\">{}</td><td>{}{}</td><td>{}</td><td class=\"n\">{}</td>\
                 <td>{}</td><td class=\"n\">{}</td></tr>",
                esc(&panel),
                i.zone,
                if i.began_before { "before " } else { "" },
                time_text(i.start),
                i.end.map_or("still out".to_string(), time_text),
                duration_words(i.duration_s),
                if i.sustained { "sustained" } else { "momentary" },
                num(i.ens_kwh, 2)
            );
        }
        o.push_str("</table>");
    }
    definitions(&mut o, r);
    o.push_str("</body></html>\n");
    o
}

/// The report's notes: what every figure printed is, in the words of its
/// computation (`figures.rs`), so a reader need not guess.
fn definitions(o: &mut String, r: &Report) {
    let cost_unit = match &r.currency {
        Some(c) => format!("in {} (<code>[reports] currency</code>)", esc(c)),
        None => "in cost units: the unit of the configured prices \
                 (set <code>[reports] currency</code> to name the currency)"
            .to_string(),
    };
    let baseline_min = BASELINE_MS / 60_000;
    let sustained = duration_words(SUSTAINED_S);
    let items: [(&str, String); 20] = [
        ("Period", "from its start (00:00 UTC of the day, or of the month's 1st) to its end, or to when the report was made if the period was still running; all times are UTC.".into()),
        ("Data", "the share of the period the historian knew the values the row is computed from (for outages: every breaker state of the panel). A sample holds for twice its tag's max interval plus 5 minutes; past that, or past the last sample of any tag the report reads (the server stopped), the value is unknown and counts for nothing.".into()),
        ("Panel kWh", "the panel's meter (its first read-only, historised tag in kW, W or MW under the panel's prefix and outside its zones) integrated over the period; negative readings subtract.".into()),
        ("Zone kWh", "the zone's own meter (such a tag under PREFIX.ZoneN.) integrated the same way; a zone without one is not measured.".into()),
        ("kWh out", "a unit's power integrated where positive: produced (PV, wind, diesel), discharged (battery). A generator's negative readings (its auxiliaries) are not production.".into()),
        ("kWh in", "a battery's power integrated where negative: the energy it charged.".into()),
        ("Run time", "a diesel's time running (its running tag true; where that tag has no data, its power above zero); Starts: the times it went from stopped to running.".into()),
        ("Fuel l", "a diesel's litres per kWh × kWh out + no-load litres per hour × run time, from its fuel curve; — without one.".into()),
        ("Cycles", "a battery's equivalent full cycles: (kWh in + kWh out) / (2 × capacity).".into()),
        ("Cost", format!("{cost_unit}. PV and wind: cost per kWh × kWh out. Diesel: with a fuel price and fuel curve, fuel price × fuel litres, else cost per kWh × kWh out; plus start cost × starts. Battery: cycle cost per kWh × (kWh in + kWh out). The microgrid's cost is the sum of its units'.")),
        ("Demand kWh", "the microgrid's demand tag integrated over the period.".into()),
        ("Produced kWh", "the sum of every unit's kWh out: PV, wind, diesel and battery discharge.".into()),
        ("PV and wind share", "PV and wind kWh out / produced kWh. Battery discharge is in the denominator and its charging is not subtracted, so energy stored and discharged later counts twice in the denominator (once produced, once discharged) and PV or wind energy once in the numerator: it is a share of production, not of the energy served. A month's share is computed from the month's totals.".into()),
        ("Activations", "alarm activations annunciated in the period (ISA-18.2): an activation while the alarm is shelved, suppressed or out of service is not counted. Priority N: the same, per priority, highest first.".into()),
        ("Acknowledged", "activations of the period whose acknowledgement came within the period (one acknowledgement acknowledges every earlier activation of the same alarm); Not acknowledged in the period: the other activations of the period.".into()),
        ("Time to acknowledge", "from an activation to its acknowledgement, over the acknowledged activations: their mean; the median and the 90th percentile (the sorted times' entry at 0.5 × (count − 1) and 0.9 × (count − 1), rounded); and the longest.".into()),
        ("Top alarms", "the ten alarms activated most often in the period, each with where it is (by its configured name, the panel or microgrid unit whose prefix its tag is under, else the one whose prefix is the alarm's area; else that area) and its tag; an alarm of the server's own, such as a panel sequence's, has no tag and is named by its key.".into()),
        ("Sustained, Momentary", format!("a zone's interruptions (its breaker, the main MCCB or the ELCB open) lasting {sustained} or more, and shorter ones (IEEE 1366).")),
        ("SAIFI, SAIDI, MAIFI", "zones stand for customers: sustained interruptions per zone, minutes of sustained interruption per zone, momentary interruptions per zone.".into()),
        ("ENS kWh", format!("energy not supplied: with a zone meter, the zone's mean load over the {baseline_min} minutes before the interruption × its duration; without one, the panel meter's drop below its mean load over the {baseline_min} minutes before, shared equally among the zones out (exact for one zone out, an estimate for several). Duration: from the interruption's start (or the period's, when it began before) to its end (or the period's).")),
    ];
    o.push_str("<h2 id=\"definitions\">Definitions</h2><dl class=\"definitions\">");
    for (figure, meaning) in items {
        let _ = write!(o, "<dt>{figure}</dt><dd>{meaning}</dd>");
    }
    o.push_str("</dl>");
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
        row(&mut o, "unit", s, "cost", &val(Some(u.cost)), cost_unit(r));
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
        row(
            &mut o,
            "microgrid",
            "",
            "cost",
            &val(r.energy.cost),
            cost_unit(r),
        );
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

#[cfg(test)]
mod tests {
    use super::duration_words;

    #[test]
    fn durations_are_written_in_words() {
        for (s, words) in [
            (0.0, "0.0 s"),
            (4.24, "4.2 s"),
            (45.0, "45 s"),
            (59.4, "59 s"),
            (59.6, "1 min 00 s"),
            (125.0, "2 min 05 s"),
            (3569.0, "59 min 29 s"),
            (3600.0, "1 h 00 min"),
            (31_527.0, "8 h 45 min"),
            (90_000.0, "25 h 00 min"),
            (-3.0, "0.0 s"),
        ] {
            assert_eq!(duration_words(s), words, "{s} s");
        }
        assert_eq!(duration_words(f64::NAN), "—");
    }
}
