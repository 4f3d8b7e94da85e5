//! The report as one self-contained HTML page: inline CSS and SVG plots,
//! no scripts, fonts or other external assets.
//!
//! Owns the rendering only; every number comes from the [`Report`].

use std::fmt::Write;

use super::report::{Plot, Report};
use super::time::format_offset;

const PALETTE: &[&str] = &[
    "#e69f00", "#0072b2", "#009e73", "#d55e00", "#555555", "#cc79a7", "#56b4e9", "#f0e442",
];

/// Escapes text for HTML content and attribute values.
pub fn esc(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

fn offset(s: f64) -> String {
    format_offset(std::time::Duration::from_millis(
        (s.max(0.0) * 1000.0) as u64,
    ))
}

fn num(v: f64) -> String {
    if !v.is_finite() {
        return "—".into();
    }
    if v == v.trunc() && v.abs() < 1e12 {
        format!("{v:.0}")
    } else if v.abs() >= 100.0 {
        format!("{v:.1}")
    } else {
        format!("{v:.3}")
    }
}

/// Renders the page.
pub fn render(r: &Report) -> String {
    let mut h = String::with_capacity(64 * 1024);
    let verdict = if r.passed { "PASSED" } else { "FAILED" };
    let _ = write!(
        h,
        r#"<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<title>{title} — replay report</title>
<style>
body{{font:14px/1.4 system-ui,sans-serif;margin:1.5em auto;max-width:1000px;color:#222;padding:0 1em}}
h1{{font-size:1.5em;margin-bottom:.2em}} h2{{font-size:1.15em;margin-top:1.6em;border-bottom:1px solid #ccc}}
table{{border-collapse:collapse;margin:.5em 0}} td,th{{border:1px solid #ddd;padding:2px 8px;text-align:left;vertical-align:top}}
th{{background:#f4f4f4}} td.n{{text-align:right;font-variant-numeric:tabular-nums}}
.pass{{color:#086b08;font-weight:bold}} .fail{{color:#b00020;font-weight:bold}}
.muted{{color:#666}} svg{{background:#fff;border:1px solid #ddd;margin:.4em 0}}
.figs{{columns:2;column-gap:2em}} .figs table{{width:100%}}
</style></head><body>
<h1>{title}</h1>
<p class="muted">{desc}</p>
<p><span class="{cls}">{verdict}</span> — {n_pass} of {n_exp} expectations met.
Plant time {dur} from {file}, step {step} s, seed {seed}, plant: {plant}.<br>
Clock: {clock}; wall time {wall:.1} s, speed-up ×{speed:.0}.</p>
"#,
        title = esc(&r.scenario),
        desc = esc(&r.description),
        cls = if r.passed { "pass" } else { "fail" },
        n_pass = r.expectations.iter().filter(|e| e.passed).count(),
        n_exp = r.expectations.len(),
        dur = offset(r.duration_s),
        file = esc(&r.file),
        step = num(r.step_s),
        seed = r.seed,
        plant = esc(&r.plant),
        clock = esc(&r.clock),
        wall = r.wall_s,
        speed = r.speedup,
    );
    for n in &r.notes {
        let _ = writeln!(h, "<p class=\"muted\">Note: {}</p>", esc(n));
    }

    h.push_str("<h2>Expectations</h2>\n<table><tr><th>line</th><th>result</th><th>expected</th><th>actual</th><th>what</th></tr>\n");
    for e in &r.expectations {
        let _ = writeln!(
            h,
            "<tr><td class=n>{}</td><td class={}>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            e.line,
            if e.passed { "pass" } else { "fail" },
            match (e.passed, &e.known_failure) {
                (true, _) => "pass".to_string(),
                (false, Some(why)) => format!("known failure: {}", esc(why)),
                (false, None) => "FAIL".to_string(),
            },
            esc(&e.expected),
            esc(&e.actual),
            esc(&e.description)
        );
    }
    h.push_str("</table>\n");

    h.push_str("<h2>Plots</h2>\n");
    for p in &r.plots {
        h.push_str(&svg_plot(p));
    }

    h.push_str("<h2>Cost</h2>\n<table><tr><th></th><th>fuel</th><th>energy</th><th>storage cycling</th><th>unserved (VOLL)</th><th>total</th></tr>\n");
    let mut cost_row = |name: &str, c: &super::report::CostBreakdown| {
        let _ = writeln!(
            h,
            "<tr><th>{}</th><td class=n>{}</td><td class=n>{}</td><td class=n>{}</td><td class=n>{}</td><td class=n><b>{}</b></td></tr>",
            esc(name),
            num(c.fuel),
            num(c.energy),
            num(c.storage_cycling),
            num(c.unserved),
            num(c.total)
        );
    };
    cost_row("dispatch as configured", &r.cost.optimal);
    if let Some(rule) = &r.cost.rule {
        cost_row("rule-based dispatch", rule);
    }
    h.push_str("</table>\n");
    let optimum = r.cost.optimum.as_ref();
    let optimum_text = match optimum {
        Some(o) => match o.cost {
            Some(c) if c > 0.0 => format!(
                " Perfect-foresight optimum {} ({} periods of {} s, diesel {} h, {} start(s), {}): realized / optimum {:.3}.",
                num(c),
                o.periods,
                num(o.period_s),
                num(o.diesel_runtime_h),
                o.diesel_starts,
                if o.proven {
                    "proven".to_string()
                } else {
                    format!("not proven, lower bound {}", num(o.lower_bound.unwrap_or(f64::NAN)))
                },
                r.cost.optimal.total / c
            ),
            _ => format!(
                " No perfect-foresight optimum: {}.",
                esc(o.reason.as_deref().unwrap_or("none"))
            ),
        },
        None => String::new(),
    };
    let _ = writeln!(
        h,
        "<p class=muted>Fuel price {} per litre; value of lost load {} per kWh.{}{}</p>",
        num(r.cost.fuel_price_per_l),
        num(r.cost.voll_per_kwh),
        match r.cost.ratio {
            Some(x) => format!(" Cost ratio (configured / rule): {x:.3}."),
            None => String::new(),
        },
        optimum_text
    );

    if !r.faults.is_empty() {
        h.push_str("<h2>Fault-isolation sequences</h2>\n<table><tr><th>panel</th><th>ended at</th><th>outcome</th><th>restoration s</th><th>bound s</th><th>switching ops</th><th>re-energisations</th><th>trips</th></tr>\n");
        for f in &r.faults {
            let _ = writeln!(
                h,
                "<tr><td>{}</td><td>{}</td><td>{}</td><td class=n>{}</td><td class=n>{}</td><td class=n>{}</td><td class=n>{}</td><td class=n>{}</td></tr>",
                esc(&f.panel),
                offset(f.at_s),
                esc(&f.outcome),
                f.restore_s.map_or_else(|| "—".into(), num),
                num(f.bound_s),
                f.switching_ops,
                f.reenergisations,
                f.trips
            );
        }
        h.push_str("</table>\n");
    }

    let a = &r.alarms;
    let _ = writeln!(
        h,
        "<h2>Alarms (ISA-18.2)</h2>\n<p>{} activations; {} per 10 min on average, {} at peak; {} flood period(s), {}% of the time in flood; {} active and {} unacknowledged at the end.{}</p>",
        a.activations,
        num(a.average_per_10min),
        num(a.max_per_10min),
        a.floods,
        num(a.percent_time_in_flood),
        a.active_end,
        a.unacked_end,
        if a.chattering.is_empty() {
            String::new()
        } else {
            format!(" Chattering: {}.", esc(&a.chattering.join(", ")))
        }
    );

    h.push_str("<h2>Figures</h2>\n<div class=figs><table><tr><th>figure</th><th>value</th></tr>\n");
    for (k, v) in &r.figures {
        let _ = writeln!(
            h,
            "<tr><td>{}</td><td class=n>{}</td></tr>",
            esc(k),
            num(*v)
        );
    }
    h.push_str("</table></div>\n");

    h.push_str("<h2>Timeline</h2>\n<table><tr><th>time</th><th>source</th><th>what</th></tr>\n");
    for t in &r.timeline {
        let _ = writeln!(
            h,
            "<tr><td>{}</td><td>{}</td><td>{}{}</td></tr>",
            offset(t.at_s),
            esc(&t.source),
            esc(&t.text),
            t.priority
                .map(|p| format!(" <span class=muted>(priority {p})</span>"))
                .unwrap_or_default()
        );
    }
    h.push_str("</table>\n</body></html>\n");
    h
}

/// A line chart as inline SVG.
pub fn svg_plot(p: &Plot) -> String {
    let (w, ht) = (960.0, 260.0);
    let (ml, mr, mt, mb) = (60.0, 150.0, 24.0, 30.0);
    let pw = w - ml - mr;
    let ph = ht - mt - mb;
    let mut s = String::new();
    let t0 = p.t_s.first().copied().unwrap_or(0.0);
    let t1 = p.t_s.last().copied().unwrap_or(1.0).max(t0 + 1.0);
    let vals = p
        .lines
        .iter()
        .flat_map(|l| l.values.iter())
        .filter(|v| v.is_finite());
    let (mut lo, mut hi) = vals.fold((f64::MAX, f64::MIN), |(a, b), v| (a.min(*v), b.max(*v)));
    if lo > hi {
        (lo, hi) = (0.0, 1.0);
    }
    lo = lo.min(0.0);
    if hi - lo < 1e-9 {
        hi = lo + 1.0;
    }
    let pad = (hi - lo) * 0.05;
    hi += pad;
    let x = |t: f64| ml + (t - t0) / (t1 - t0) * pw;
    let y = |v: f64| mt + (hi - v) / (hi - lo) * ph;
    let _ = write!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{ht}" viewBox="0 0 {w} {ht}" role="img" aria-label="{t}"><text x="{ml}" y="16" font-size="13" font-weight="bold">{t} ({u})</text>"#,
        t = esc(&p.title),
        u = esc(&p.unit)
    );
    for i in 0..=4 {
        let v = lo + (hi - lo) * f64::from(i) / 4.0;
        let yy = y(v);
        let _ = write!(
            s,
            r##"<line x1="{ml}" x2="{:.1}" y1="{yy:.1}" y2="{yy:.1}" stroke="#eee"/><text x="{:.1}" y="{:.1}" font-size="11" text-anchor="end">{}</text>"##,
            ml + pw,
            ml - 4.0,
            yy + 4.0,
            num((v * 10.0).round() / 10.0)
        );
    }
    for i in 0..=6 {
        let t = t0 + (t1 - t0) * f64::from(i) / 6.0;
        let _ = write!(
            s,
            r#"<text x="{:.1}" y="{:.1}" font-size="11" text-anchor="middle">{}</text>"#,
            x(t),
            mt + ph + 16.0,
            &offset(t)[..5.min(offset(t).len())]
        );
    }
    let _ = write!(
        s,
        r##"<rect x="{ml}" y="{mt}" width="{pw}" height="{ph}" fill="none" stroke="#999"/>"##
    );
    for (i, l) in p.lines.iter().enumerate() {
        let color = PALETTE[i % PALETTE.len()];
        let mut pts = String::new();
        for (t, v) in p.t_s.iter().zip(&l.values) {
            if v.is_finite() {
                let _ = write!(pts, "{:.1},{:.1} ", x(*t), y(*v));
            }
        }
        let _ = write!(
            s,
            r#"<polyline fill="none" stroke="{color}" stroke-width="1.5" points="{}"/><rect x="{:.1}" y="{:.1}" width="12" height="3" fill="{color}"/><text x="{:.1}" y="{:.1}" font-size="12">{}</text>"#,
            pts.trim_end(),
            ml + pw + 10.0,
            mt + 10.0 + 18.0 * i as f64,
            ml + pw + 26.0,
            mt + 15.0 + 18.0 * i as f64,
            esc(&l.name)
        );
    }
    s.push_str("</svg>\n");
    s
}

#[cfg(test)]
mod tests {
    use super::super::report::Line;
    use super::*;

    #[test]
    fn escapes_and_plots_without_external_assets() {
        assert_eq!(esc("<a href='x'>&"), "&lt;a href=&#39;x&#39;&gt;&amp;");
        let p = Plot {
            title: "Power <by> source".into(),
            unit: "kW".into(),
            t_s: vec![0.0, 60.0, 120.0],
            lines: vec![Line {
                name: "pv1".into(),
                values: vec![0.0, 10.0, f64::NAN],
            }],
        };
        let svg = svg_plot(&p);
        assert!(svg.contains("<polyline"));
        assert!(svg.contains("Power &lt;by&gt; source"));
        assert!(!svg.contains("NaN"));
        assert!(!svg.contains("href"));
    }
}
