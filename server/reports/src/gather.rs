//! Reading what a report needs from the store, a day at a time, and putting
//! the figures together. A month is the sum of its days (energy), its
//! interruptions joined across midnight, and its alarm history in one pass,
//! so memory stays that of one day's samples of one tag at a time.

use gridscada_config::Plant;
use gridscada_store::{AlarmHistoryFilter, Store, StoreError};
use gridscada_tagdb::{QualityCode, Timestamp};

use crate::figures::{
    self, alarm_figures, Energy, Interruption, Outages, PanelReliability, SampleMap, TagIndex,
    BASELINE_MS, SUSTAINED_S,
};
use crate::series::Sample;
use crate::{Period, Report};

/// Raw samples read per tag and day; a tag logging more than this in one day
/// (more than every 0.2 s) is cut, and the report says its coverage.
const MAX_SAMPLES_PER_TAG_DAY: u32 = 500_000;

/// How far past a day's end samples are read, to tell a day whose recording
/// went on from one where the server stopped.
const LOOK_AHEAD_MS: i64 = 3_600_000;

/// Alarm history rows read per page.
const ALARM_PAGE: u32 = 5_000;

#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    #[error("reading the store: {0}")]
    Store(#[from] StoreError),
    #[error("the period {0} has not started yet")]
    Future(String),
}

/// The samples of `tags` over `from - BASELINE_MS .. to`, with the one in
/// force before.
async fn samples(
    store: &Store,
    tags: &[String],
    from: i64,
    to: i64,
) -> Result<SampleMap, StoreError> {
    let start = Timestamp::from_millis(from - BASELINE_MS);
    let mut map = SampleMap::new();
    for tag in tags {
        let mut v: Vec<Sample> = Vec::new();
        let conv = |s: &gridscada_store::RawSample| Sample {
            ts: s.ts.as_millis(),
            value: s.value,
            good: s.quality == QualityCode::Good,
        };
        if let Some(s) = store.sample_before(tag, start).await? {
            v.push(conv(&s));
        }
        let raw = store
            .raw_samples(
                &[tag.as_str()],
                start,
                Timestamp::from_millis(to),
                MAX_SAMPLES_PER_TAG_DAY,
            )
            .await?;
        v.extend(raw.iter().map(conv));
        map.insert(tag.clone(), v);
    }
    Ok(map)
}

/// Adds one day's energy into the month's.
fn add_energy(total: &mut Option<Energy>, day: Energy, day_h: f64) {
    let Some(t) = total.as_mut() else {
        let mut day = day;
        scale_coverage(&mut day, day_h);
        *total = Some(day);
        return;
    };
    let add = |a: &mut Option<f64>, b: Option<f64>| {
        if let Some(b) = b {
            *a = Some(a.unwrap_or(0.0) + b);
        }
    };
    for (tp, dp) in t.panels.iter_mut().zip(day.panels) {
        add(&mut tp.kwh, dp.kwh);
        tp.coverage += dp.coverage * day_h; // weighted; normalised at the end
        for (tz, dz) in tp.zones.iter_mut().zip(dp.zones) {
            add(&mut tz.kwh, dz.kwh);
        }
    }
    for (tu, du) in t.units.iter_mut().zip(day.units) {
        tu.kwh += du.kwh;
        tu.charged_kwh += du.charged_kwh;
        tu.run_h += du.run_h;
        tu.starts += du.starts;
        add(&mut tu.fuel_l, du.fuel_l);
        add(&mut tu.cycles, du.cycles);
        tu.cost += du.cost;
        tu.coverage += du.coverage * day_h;
    }
    add(&mut t.demand_kwh, day.demand_kwh);
    t.renewable_kwh += day.renewable_kwh;
    t.produced_kwh += day.produced_kwh;
    add(&mut t.cost, day.cost);
}

/// Joins interruptions that run across a day's end, and recomputes each
/// panel's figures over the whole period.
fn join_outages(plant: &Plant, days: Vec<Outages>) -> Outages {
    let mut all: Vec<Interruption> = Vec::new();
    for day in days {
        for i in day.interruptions {
            let cont = all.iter_mut().rev().find(|p| {
                p.panel == i.panel && p.zone == i.zone && p.end.is_none() && i.began_before
            });
            match cont {
                Some(p) => {
                    p.end = i.end;
                    p.duration_s += i.duration_s;
                    p.sustained = p.duration_s >= SUSTAINED_S;
                    p.ens_kwh = match (p.ens_kwh, i.ens_kwh) {
                        (None, None) => None,
                        (a, b) => Some(a.unwrap_or(0.0) + b.unwrap_or(0.0)),
                    };
                }
                None => all.push(i),
            }
        }
    }
    let mut panels: Vec<PanelReliability> = Vec::new();
    for p in &plant.panels {
        let id = p.id.get_ref();
        let zones = *p.zones.get_ref();
        let mine: Vec<&Interruption> = all.iter().filter(|i| &i.panel == id).collect();
        let sustained: Vec<&&Interruption> = mine.iter().filter(|i| i.sustained).collect();
        let n = f64::from(zones.max(1));
        let momentary = mine.len() - sustained.len();
        panels.push(PanelReliability {
            id: id.clone(),
            name: p.name.clone(),
            zones,
            sustained: sustained.len() as u32,
            momentary: momentary as u32,
            saifi: sustained.len() as f64 / n,
            saidi_min: sustained.iter().map(|i| i.duration_s).sum::<f64>() / 60.0 / n,
            maifi: momentary as f64 / n,
            ens_kwh: mine.iter().filter_map(|i| i.ens_kwh).sum(),
            coverage: 0.0,
        });
    }
    Outages {
        interruptions: all,
        panels,
        open_baselines: Default::default(),
    }
}

/// Makes the report of `period` from what the store holds. `now` cuts a
/// period still running (its figures cover up to `now`).
pub async fn generate(
    store: &Store,
    plant: &Plant,
    period: Period,
    now: Timestamp,
) -> Result<Report, ReportError> {
    let from = period.start().as_millis();
    let to = period.end().as_millis().min(now.as_millis());
    if to <= from {
        return Err(ReportError::Future(period.to_string()));
    }
    let tags = TagIndex::new(plant).report_tags();
    let mut energy: Option<Energy> = None;
    let mut outages: Vec<Outages> = Vec::new();
    let mut coverage_h = 0.0;
    let mut reliability_cov: Vec<f64> = vec![0.0; plant.panels.len()];
    let mut baselines = figures::Baselines::new();
    let mut day = from;
    while day < to {
        let end = (day + 86_400_000).min(to);
        // An hour past the day's end (not past now) is read too: it shows
        // whether recording went on after the day.
        let ahead = (end + LOOK_AHEAD_MS).min(now.as_millis()).max(end);
        let data = samples(store, &tags, day, ahead).await?;
        // Past the last sample of any of the tags nothing was recorded (the
        // server stopped): the day's figures end there, and do not hold the
        // last values to midnight.
        let recorded = data
            .values()
            .filter_map(|v| v.last())
            .map(|s| s.ts)
            .max()
            .unwrap_or(day);
        let until = end.min(recorded.max(day));
        let h = (until - day) as f64 / 3_600_000.0;
        add_energy(&mut energy, figures::energy(plant, &data, day, until), h);
        let o = figures::outages(plant, &data, day, until, &baselines);
        baselines = o.open_baselines.clone();
        for (c, p) in reliability_cov.iter_mut().zip(&o.panels) {
            *c += p.coverage * h;
        }
        outages.push(o);
        coverage_h += (end - day) as f64 / 3_600_000.0;
        day = end;
    }
    let mut energy = energy.expect("at least one day");
    if coverage_h > 0.0 {
        scale_coverage(&mut energy, 1.0 / coverage_h);
    }
    energy.renewable_share =
        (energy.produced_kwh > 0.0).then(|| energy.renewable_kwh / energy.produced_kwh);
    let mut outages = join_outages(plant, outages);
    for (p, c) in outages.panels.iter_mut().zip(reliability_cov) {
        p.coverage = if coverage_h > 0.0 {
            c / coverage_h
        } else {
            0.0
        };
    }
    let mut transitions = Vec::new();
    let mut offset = 0;
    loop {
        let page = store
            .alarm_history(&AlarmHistoryFilter {
                from: Some(Timestamp::from_millis(from)),
                to: Some(Timestamp::from_millis(to)),
                limit: ALARM_PAGE,
                offset,
                oldest_first: true,
                ..Default::default()
            })
            .await?;
        let n = page.len() as u32;
        transitions.extend(page.into_iter().map(|r| r.transition));
        if n < ALARM_PAGE {
            break;
        }
        offset += n;
    }
    Ok(Report {
        site: plant.server.site().to_string(),
        currency: plant.reports.currency().map(str::to_string),
        period,
        id: period.to_string(),
        from,
        to,
        generated_at: now.as_millis(),
        energy,
        alarms: alarm_figures(plant, &transitions),
        outages,
    })
}

/// Multiplies every coverage by `k`: days are added weighted by their
/// hours, and the sum divided by the period's hours at the end.
fn scale_coverage(e: &mut Energy, k: f64) {
    for p in &mut e.panels {
        p.coverage *= k;
    }
    for u in &mut e.units {
        u.coverage *= k;
    }
}
