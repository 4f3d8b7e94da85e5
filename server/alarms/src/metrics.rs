//! ISA-18.2 alarm-system performance metrics, computed on the server.
//!
//! **Owns:** pure functions from alarm history (annunciated activations) and
//! current alarm states to a serializable [`AlarmMetrics`] report: alarm rate
//! per operator per 10 minutes, flood periods, the most frequent alarms,
//! chattering alarms, stale alarms and the priority distribution.
//!
//! **Must not touch:** storage or clocks. The caller reads the history for
//! the time range (from the store) and passes the current states.
//!
//! Definitions used:
//! - rates are counted in fixed 10-minute intervals aligned to `from`, divided
//!   by the number of operator positions;
//! - a flood interval has more than `flood_threshold` (10) activations per
//!   operator; consecutive flood intervals merge into one flood period;
//! - an alarm chatters when it activates `chatter_count` (3) or more times
//!   within any `chatter_window` (60 s);
//! - an alarm is stale when it has been active longer than `stale_after` (24 h).

use std::collections::{BTreeMap, HashMap};
use std::time::Duration;

use gridscada_tagdb::Timestamp;
use serde::{Deserialize, Serialize};

use crate::model::{AlarmStateRecord, AlarmTransition};

/// One annunciated alarm activation.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Activation {
    pub time: Timestamp,
    pub key: String,
    pub priority: u32,
}

/// The annunciated activations among `transitions`.
pub fn activations(transitions: &[AlarmTransition]) -> Vec<Activation> {
    transitions
        .iter()
        .filter(|t| t.is_annunciated_activation())
        .map(|t| Activation {
            time: t.time,
            key: t.key.clone(),
            priority: t.priority,
        })
        .collect()
}

/// Parameters of the metrics. `Default` gives the ISA-18.2 values.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct MetricsOptions {
    /// Operator positions sharing the alarm load (at least 1).
    pub operators: u32,
    pub interval: Duration,
    pub flood_threshold: u32,
    pub top_n: usize,
    pub chatter_count: u32,
    pub chatter_window: Duration,
    pub stale_after: Duration,
}

impl Default for MetricsOptions {
    fn default() -> Self {
        MetricsOptions {
            operators: 1,
            interval: Duration::from_secs(600),
            flood_threshold: 10,
            top_n: 10,
            chatter_count: 3,
            chatter_window: Duration::from_secs(60),
            stale_after: Duration::from_secs(24 * 3600),
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IntervalCount {
    pub start: Timestamp,
    pub count: u32,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FloodPeriod {
    pub start: Timestamp,
    pub end: Timestamp,
    /// Activations within the period (all operators).
    pub count: u32,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrequentAlarm {
    pub key: String,
    pub count: u32,
    /// Share of all activations in the range, percent.
    pub percent: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChatteringAlarm {
    pub key: String,
    /// Activations in the whole range.
    pub activations: u32,
    /// Most activations within one chatter window.
    pub max_in_window: u32,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StaleAlarm {
    pub key: String,
    pub active_since: Timestamp,
    pub hours: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PriorityCount {
    pub priority: u32,
    pub count: u32,
    pub percent: f64,
}

/// The metrics report for one time range.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AlarmMetrics {
    pub from: Timestamp,
    pub to: Timestamp,
    pub operators: u32,
    pub total_activations: u32,
    /// Activations per interval (all operators), every interval of the range.
    pub per_interval: Vec<IntervalCount>,
    /// Mean activations per operator per interval.
    pub average_per_interval_per_operator: f64,
    /// Peak activations per operator in one interval.
    pub max_per_interval_per_operator: f64,
    pub floods: Vec<FloodPeriod>,
    /// Share of the range spent in flood, percent.
    pub percent_time_in_flood: f64,
    /// Most frequent alarms, most first (ties by key).
    pub top: Vec<FrequentAlarm>,
    pub chattering: Vec<ChatteringAlarm>,
    pub stale: Vec<StaleAlarm>,
    /// Activations by priority, highest priority first.
    pub priority_distribution: Vec<PriorityCount>,
}

/// The ISA-18.2 (and EEMUA 191) performance targets the KPI screen holds
/// the measured figures against.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MetricTargets {
    /// Average annunciated alarms per operator per 10 minutes: about 1 is
    /// "very likely acceptable"...
    pub average_per_interval_per_operator: f64,
    /// ...and 2 the most that is manageable.
    pub average_per_interval_per_operator_max: f64,
    /// Peak alarms per operator in one 10-minute interval: over 10 is a flood.
    pub max_per_interval_per_operator: f64,
    /// Share of the time in flood, percent: under 1.
    pub percent_time_in_flood: f64,
    /// The 10 most frequent alarms' share of all activations, percent: at
    /// most 5 (about 1 is the aim).
    pub top10_percent: f64,
    /// Chattering alarms: none.
    pub chattering: u32,
    /// Stale alarms (active over 24 h): fewer than 5 on any day.
    pub stale: u32,
    /// Shelved alarms at once: ISA-18.2 sets no figure, only that each one
    /// is authorised, has an end and is reviewed; more than this many (a
    /// site guideline) means shelving is used instead of fixing.
    pub shelved: u32,
}

impl Default for MetricTargets {
    fn default() -> Self {
        MetricTargets {
            average_per_interval_per_operator: 1.0,
            average_per_interval_per_operator_max: 2.0,
            max_per_interval_per_operator: 10.0,
            percent_time_in_flood: 1.0,
            top10_percent: 5.0,
            chattering: 0,
            stale: 5,
            shelved: 5,
        }
    }
}

fn percent(part: u32, whole: u32) -> f64 {
    if whole == 0 {
        0.0
    } else {
        100.0 * part as f64 / whole as f64
    }
}

/// Computes the metrics of the activations within `[from, to)` and of the
/// current states (for stale alarms, judged at `to`). Activations outside the
/// range are ignored; the input need not be sorted.
pub fn compute(
    activations: &[Activation],
    current: &[AlarmStateRecord],
    from: Timestamp,
    to: Timestamp,
    opts: &MetricsOptions,
) -> AlarmMetrics {
    let operators = opts.operators.max(1);
    let interval_ms = (opts.interval.as_millis() as i64).max(1);
    let mut acts: Vec<&Activation> = activations
        .iter()
        .filter(|a| a.time >= from && a.time < to)
        .collect();
    acts.sort_by(|a, b| a.time.cmp(&b.time).then(a.key.cmp(&b.key)));
    let total = acts.len() as u32;

    // Rate per fixed interval.
    let span = (to.as_millis() - from.as_millis()).max(0);
    let n_intervals = ((span + interval_ms - 1) / interval_ms) as usize;
    let mut counts = vec![0u32; n_intervals];
    for a in &acts {
        let i = ((a.time.as_millis() - from.as_millis()) / interval_ms) as usize;
        if let Some(c) = counts.get_mut(i) {
            *c += 1;
        }
    }
    let per_interval: Vec<IntervalCount> = counts
        .iter()
        .enumerate()
        .map(|(i, c)| IntervalCount {
            start: Timestamp::from_millis(from.as_millis() + i as i64 * interval_ms),
            count: *c,
        })
        .collect();
    let per_op = |c: u32| c as f64 / operators as f64;
    let average = if counts.is_empty() {
        0.0
    } else {
        per_op(total) / counts.len() as f64
    };
    let max = counts.iter().copied().max().map(per_op).unwrap_or(0.0);

    // Floods: runs of intervals over the threshold per operator.
    let mut floods: Vec<FloodPeriod> = Vec::new();
    let mut flood_ms = 0i64;
    let mut last_flood: Option<usize> = None;
    for (i, c) in counts.iter().enumerate() {
        if per_op(*c) <= opts.flood_threshold as f64 {
            continue;
        }
        let start = from.as_millis() + i as i64 * interval_ms;
        let end = (start + interval_ms).min(to.as_millis());
        flood_ms += end - start;
        match (last_flood, floods.last_mut()) {
            (Some(prev), Some(f)) if prev + 1 == i => {
                f.end = Timestamp::from_millis(end);
                f.count += c;
            }
            _ => floods.push(FloodPeriod {
                start: Timestamp::from_millis(start),
                end: Timestamp::from_millis(end),
                count: *c,
            }),
        }
        last_flood = Some(i);
    }
    let percent_time_in_flood = if span == 0 {
        0.0
    } else {
        100.0 * flood_ms as f64 / span as f64
    };

    // Per-alarm activation times (sorted, since `acts` is).
    let mut by_key: HashMap<&str, Vec<Timestamp>> = HashMap::new();
    for a in &acts {
        by_key.entry(a.key.as_str()).or_default().push(a.time);
    }
    let mut top: Vec<FrequentAlarm> = by_key
        .iter()
        .map(|(k, t)| FrequentAlarm {
            key: (*k).to_owned(),
            count: t.len() as u32,
            percent: percent(t.len() as u32, total),
        })
        .collect();
    top.sort_by(|a, b| b.count.cmp(&a.count).then(a.key.cmp(&b.key)));
    top.truncate(opts.top_n);

    let window_ms = opts.chatter_window.as_millis() as i64;
    let mut chattering: Vec<ChatteringAlarm> = by_key
        .iter()
        .filter_map(|(k, times)| {
            let max_in_window = max_in_window(times, window_ms);
            (max_in_window >= opts.chatter_count.max(2)).then(|| ChatteringAlarm {
                key: (*k).to_owned(),
                activations: times.len() as u32,
                max_in_window,
            })
        })
        .collect();
    chattering.sort_by(|a, b| {
        b.max_in_window
            .cmp(&a.max_in_window)
            .then(b.activations.cmp(&a.activations))
            .then(a.key.cmp(&b.key))
    });

    let stale_ms = opts.stale_after.as_millis() as i64;
    let mut stale: Vec<StaleAlarm> = current
        .iter()
        .filter(|r| r.active)
        .filter_map(|r| {
            let since = r.active_since?;
            let age = to.as_millis() - since.as_millis();
            (age > stale_ms).then(|| StaleAlarm {
                key: r.key.clone(),
                active_since: since,
                hours: age as f64 / 3_600_000.0,
            })
        })
        .collect();
    stale.sort_by(|a, b| a.active_since.cmp(&b.active_since).then(a.key.cmp(&b.key)));

    let mut prio: BTreeMap<u32, u32> = BTreeMap::new();
    for a in &acts {
        *prio.entry(a.priority).or_default() += 1;
    }
    let priority_distribution = prio
        .into_iter()
        .rev()
        .map(|(priority, count)| PriorityCount {
            priority,
            count,
            percent: percent(count, total),
        })
        .collect();

    AlarmMetrics {
        from,
        to,
        operators,
        total_activations: total,
        per_interval,
        average_per_interval_per_operator: average,
        max_per_interval_per_operator: max,
        floods,
        percent_time_in_flood,
        top,
        chattering,
        stale,
        priority_distribution,
    }
}

/// The most times within any window of `window_ms` (inclusive of both ends),
/// for sorted `times`.
fn max_in_window(times: &[Timestamp], window_ms: i64) -> u32 {
    let mut best = 0usize;
    let mut lo = 0usize;
    for hi in 0..times.len() {
        while times[hi].as_millis() - times[lo].as_millis() > window_ms {
            lo += 1;
        }
        best = best.max(hi - lo + 1);
    }
    best as u32
}
