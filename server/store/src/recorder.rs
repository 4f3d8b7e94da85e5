//! The historian's logging policy: which samples are worth writing. Pure, no
//! I/O: the app feeds it tag changes and a periodic tick, and hands what it
//! returns to the [`crate::Historian`] writer.
//!
//! A tag's sample is logged when
//! - it is the first seen for the tag;
//! - its quality class changes (good / uncertain / bad);
//! - its value moved more than the tag's deadband from the last *logged* value
//!   (absolute; a deadband of 0 logs every change);
//! - it is older than the last logged one (a device's buffered event that
//!   arrives after an outage, at its own time): it is logged at that time,
//!   and when its quality class differs from the last logged row's (Good
//!   again after the outage's Bad), the return is logged too, just after
//!   that row, so the trend does not stay Bad;
//! - and, from [`Recorder::tick`], when nothing was logged for the tag's max
//!   interval: the last seen value is logged again, stamped with the tick time,
//!   so a flat trend still has points and "no data" means "no data".
//!
//! String tags have no numeric value and are not logged.

use std::sync::Arc;
use std::time::Duration;

use gridscada_config::HistoryConfig;
use gridscada_tagdb::{QualityCode, Sample, TagId, Timestamp, Value};

use crate::HistorySample;

/// The logging settings of one tag.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordPolicy {
    pub enabled: bool,
    /// Absolute change from the last logged value that is worth a row.
    pub deadband: f64,
    /// Log at least this often; `None` = only on change.
    pub max_interval: Option<Duration>,
}

impl Default for RecordPolicy {
    fn default() -> Self {
        RecordPolicy::from_config(&HistoryConfig::default())
    }
}

impl RecordPolicy {
    /// From a tag's `history` settings. Nonsense values (negative or NaN
    /// deadband, non-positive interval) fall back to "log every change" and
    /// "no periodic re-log" rather than failing.
    pub fn from_config(c: &HistoryConfig) -> Self {
        let deadband = *c.deadband.get_ref();
        let interval = *c.max_interval_s.get_ref();
        RecordPolicy {
            enabled: c.enabled,
            deadband: if deadband.is_finite() && deadband > 0.0 {
                deadband
            } else {
                0.0
            },
            max_interval: (interval.is_finite() && interval > 0.0)
                .then(|| Duration::from_secs_f64(interval.min(1.0e9))),
        }
    }
}

/// A sample as the policy remembers it. Laid out for a million tags: 40
/// bytes, where `Option<f64>` and `Option<i128>` (16-aligned) took 64.
#[derive(Debug, Clone, Copy)]
struct Seen {
    /// NaN for none (Bad, or not a finite number: never a logged value).
    value: f64,
    /// The exact integer where `value` rounds it (outside ±2^53), as two
    /// words, if `has_exact`.
    exact: [u64; 2],
    has_exact: bool,
    quality: QualityCode,
    ts: Timestamp,
}

impl Seen {
    fn new(value: Option<f64>, exact: Option<i128>, quality: QualityCode, ts: Timestamp) -> Seen {
        let bits = exact.unwrap_or(0) as u128;
        Seen {
            value: value.filter(|v| v.is_finite()).unwrap_or(f64::NAN),
            exact: [(bits >> 64) as u64, bits as u64],
            has_exact: exact.is_some(),
            quality,
            ts,
        }
    }

    fn value(&self) -> Option<f64> {
        Some(self.value).filter(|v| !v.is_nan())
    }

    fn exact(&self) -> Option<i128> {
        self.has_exact
            .then(|| ((u128::from(self.exact[0]) << 64) | u128::from(self.exact[1])) as i128)
    }
}

#[derive(Debug)]
struct TagState {
    name: Arc<str>,
    /// Index in [`Recorder::policies`]: tags share a handful of policies.
    policy: u32,
    last_logged: Option<Seen>,
    last_seen: Option<Seen>,
    /// The time of the last late row, so a device that sends the same old
    /// timestamp at every integrity report does not rewrite it each time.
    last_late: Option<Timestamp>,
    /// When the last logged row is a return after an outage: the time of
    /// the late sample it holds, so a later late sample updates it.
    return_from: Option<Timestamp>,
}

/// The rows one sample asks for: its own, and at most one more.
#[derive(Debug, Default)]
pub struct Rows([Option<HistorySample>; 2]);

impl IntoIterator for Rows {
    type Item = HistorySample;
    type IntoIter = std::iter::Flatten<std::array::IntoIter<Option<HistorySample>, 2>>;
    fn into_iter(self) -> Self::IntoIter {
        self.0.into_iter().flatten()
    }
}

/// Per-tag logging policy and the memory it needs (last logged, last seen).
/// Indexed by tag id, which is dense: a million tags cost their states and
/// nothing more (a hash map would be half empty at that size).
#[derive(Debug, Default)]
pub struct Recorder {
    tags: Vec<Option<TagState>>,
    registered: usize,
    /// The distinct policies, and where each is in the list.
    policies: Vec<RecordPolicy>,
    policy_index: std::collections::HashMap<(bool, u64, Option<Duration>), u32>,
}

/// Whether `a` and `b` differ by more than `deadband`; NaN/None count as a
/// value of their own (a change to or from them is always logged).
fn moved(a: Option<f64>, b: Option<f64>, deadband: f64) -> bool {
    match (a.filter(|v| v.is_finite()), b.filter(|v| v.is_finite())) {
        (Some(x), Some(y)) => {
            if deadband == 0.0 {
                x != y
            } else {
                (x - y).abs() > deadband
            }
        }
        (None, None) => false,
        _ => true,
    }
}

impl Recorder {
    pub fn new() -> Self {
        Recorder::default()
    }

    /// Registers a tag (or replaces its policy, keeping what was logged).
    pub fn set_policy(&mut self, id: TagId, name: impl Into<Arc<str>>, policy: RecordPolicy) {
        let name = name.into();
        let key = (
            policy.enabled,
            policy.deadband.to_bits(),
            policy.max_interval,
        );
        let policies = &mut self.policies;
        let policy = *self.policy_index.entry(key).or_insert_with(|| {
            policies.push(policy);
            (policies.len() - 1) as u32
        });
        if self.tags.len() <= id.index() {
            self.tags.resize_with(id.index() + 1, || None);
        }
        match &mut self.tags[id.index()] {
            Some(t) => {
                t.policy = policy;
                t.name = name;
            }
            slot @ None => {
                *slot = Some(TagState {
                    name,
                    policy,
                    last_logged: None,
                    last_seen: None,
                    last_late: None,
                    return_from: None,
                });
                self.registered += 1;
            }
        }
    }

    /// Makes room for tags up to `count` ids at once (start-up registers
    /// every configured tag).
    pub fn reserve(&mut self, count: usize) {
        self.tags.reserve(count.saturating_sub(self.tags.len()));
    }

    /// Tags registered.
    pub fn len(&self) -> usize {
        self.registered
    }

    pub fn is_empty(&self) -> bool {
        self.registered == 0
    }

    /// Offers a new sample of a tag; returns its own row to log, if any
    /// (see [`Recorder::offer_rows`] for every row it asks for).
    pub fn offer(&mut self, id: TagId, sample: &Sample) -> Option<HistorySample> {
        self.offer_rows(id, sample).into_iter().next()
    }

    /// Offers a new sample of a tag; returns the rows to log. Unknown tags,
    /// disabled tags, string values and never-read samples are not logged.
    pub fn offer_rows(&mut self, id: TagId, sample: &Sample) -> Rows {
        let Some(Some(t)) = self.tags.get_mut(id.index()) else {
            return Rows::default();
        };
        Rows(t.offer(&self.policies[t.policy as usize], sample))
    }
}

impl TagState {
    fn row(&self, s: Seen) -> HistorySample {
        HistorySample {
            tag: self.name.clone(),
            ts: s.ts,
            value: s.value(),
            exact: s.exact(),
            quality: s.quality,
        }
    }

    fn offer(&mut self, policy: &RecordPolicy, sample: &Sample) -> [Option<HistorySample>; 2] {
        let t = self;
        if !policy.enabled || matches!(sample.value, Value::Str(_)) {
            return [None, None];
        }
        // A tag never read yet has no history to log: logging its start
        // state would put a Bad sample at 1970-01-01 into every trend, for
        // retention to delete later.
        if sample.is_never_read() {
            return [None, None];
        }
        // A Bad value is not a measurement: it is logged as a gap, so that
        // trend minima and averages never include it.
        let bad = sample.quality.code == gridscada_tagdb::QualityCode::Bad;
        let now = Seen::new(
            sample.value.as_f64().filter(|_| !bad),
            sample
                .value
                .as_i128()
                .filter(|_| sample.value.is_wide_integer() && !bad),
            sample.quality.code,
            sample.timestamp,
        );
        if let Some(l) = t.last_logged {
            if now.ts < l.ts {
                if t.last_late == Some(now.ts) {
                    return [None, None];
                }
                t.last_late = Some(now.ts);
                let own = Some(t.row(now));
                let back = match t.return_from {
                    // The return row holds an older late sample: this one
                    // is the newer state.
                    Some(from) if now.ts > from => Seen { ts: l.ts, ..now },
                    _ if l.quality != now.quality => Seen {
                        ts: l.ts.add(std::time::Duration::from_millis(1)),
                        ..now
                    },
                    _ => return [own, None],
                };
                t.return_from = Some(now.ts);
                t.last_logged = Some(back);
                t.last_seen = Some(back);
                return [own, Some(t.row(back))];
            }
        }
        t.last_seen = Some(now);
        let log = match t.last_logged {
            None => true,
            Some(l) => {
                l.quality != now.quality
                    || moved(l.value(), now.value(), policy.deadband)
                    // A float cannot see a step of one in a wide integer.
                    || (policy.deadband == 0.0 && l.exact() != now.exact())
            }
        };
        if !log {
            return [None, None];
        }
        t.last_logged = Some(now);
        t.return_from = None;
        [Some(t.row(now)), None]
    }
}

impl Recorder {
    /// The periodic re-logs due at `now`: for each tag whose last logged row is
    /// at least its max interval old, the last seen value stamped `now`.
    pub fn tick(&mut self, now: Timestamp) -> Vec<HistorySample> {
        let mut out = Vec::new();
        for t in self.tags.iter_mut().flatten() {
            let policy = &self.policies[t.policy as usize];
            let (Some(interval), true) = (policy.max_interval, policy.enabled) else {
                continue;
            };
            let (Some(logged), Some(seen)) = (t.last_logged, t.last_seen) else {
                continue;
            };
            if now.since(logged.ts) < interval {
                continue;
            }
            let row = Seen { ts: now, ..seen };
            t.last_logged = Some(row);
            t.last_seen = Some(row);
            out.push(t.row(row));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use gridscada_tagdb::Quality;

    /// A million tags each hold one of these for the whole run.
    #[test]
    fn a_tag_state_is_compact() {
        let state = std::mem::size_of::<Option<TagState>>();
        println!("Seen {} B, TagState {state} B", std::mem::size_of::<Seen>());
        assert!(state <= 136, "{state} bytes a tag");
    }

    #[test]
    fn a_seen_sample_keeps_its_value_and_exact_integer() {
        let wide = i128::from(u64::MAX) + 5;
        let s = Seen::new(
            Some(1.5),
            Some(-wide),
            QualityCode::Good,
            Timestamp::from_millis(7),
        );
        assert_eq!((s.value(), s.exact()), (Some(1.5), Some(-wide)));
        let none = Seen::new(
            Some(f64::INFINITY),
            None,
            QualityCode::Bad,
            Timestamp::from_millis(7),
        );
        assert_eq!((none.value(), none.exact()), (None, None));
    }

    fn at(ms: i64, v: f64) -> Sample {
        Sample::good(v, Timestamp::from_millis(ms))
    }

    fn rec(deadband: f64, interval_s: Option<u64>) -> Recorder {
        let mut r = Recorder::new();
        r.set_policy(
            TagId(0),
            "SS1.Zone1.V",
            RecordPolicy {
                enabled: true,
                deadband,
                max_interval: interval_s.map(Duration::from_secs),
            },
        );
        r
    }

    #[test]
    fn a_wide_integer_is_logged_exactly_and_a_step_of_one_is_seen() {
        let mut r = rec(0.0, None);
        let id = TagId(0);
        let big = 12_345_678_901_234_567_891u64;
        let s = |ms, u| Sample::good(Value::from_u64(u), Timestamp::from_millis(ms));
        let first = r.offer(id, &s(1, big)).unwrap();
        assert_eq!(first.exact, Some(i128::from(big)));
        // big + 1 is the same f64: only the exact integer shows the change.
        let next = r.offer(id, &s(2, big + 1)).unwrap();
        assert_eq!(next.exact, Some(i128::from(big) + 1));
        assert!(r.offer(id, &s(3, big + 1)).is_none());
        // A small integer needs no exact copy.
        assert_eq!(r.offer(id, &s(4, 7)).unwrap().exact, None);
    }

    #[test]
    fn a_tag_never_read_is_not_logged_at_1970() {
        let mut r = rec(0.0, Some(60));
        let id = TagId(0);
        assert!(r
            .offer(id, &Sample::never_read(Value::Float(0.0)))
            .is_none());
        // Nor re-logged by the interval before its first reading.
        assert!(r.tick(Timestamp::from_millis(3_600_000)).is_empty());
        // Its first reading is.
        assert!(r.offer(id, &at(5_000, 230.0)).is_some());
    }

    #[test]
    fn deadband_is_measured_from_the_last_logged_value() {
        let mut r = rec(1.0, None);
        let id = TagId(0);
        assert!(r.offer(id, &at(0, 230.0)).is_some());
        // Creeping by 0.6 twice: neither step alone passes, the sum does.
        assert!(r.offer(id, &at(1, 230.6)).is_none());
        let logged = r
            .offer(id, &at(2, 231.2))
            .expect("1.2 from the last logged");
        assert_eq!(logged.value, Some(231.2));
        // Exactly the deadband is not "more than" it.
        assert!(r.offer(id, &at(3, 232.2)).is_none());
        assert!(r.offer(id, &at(4, 229.0)).is_some());
    }

    #[test]
    fn zero_deadband_logs_every_change_and_only_changes() {
        let mut r = rec(0.0, None);
        let id = TagId(0);
        assert!(r.offer(id, &at(0, 1.0)).is_some());
        assert!(r.offer(id, &at(1, 1.0)).is_none());
        assert!(r.offer(id, &at(2, 1.0000001)).is_some());
    }

    #[test]
    fn a_bad_sample_is_logged_as_a_gap() {
        let mut r = rec(0.0, None);
        let id = TagId(0);
        assert!(r.offer(id, &at(0, 230.0)).is_some());
        let bad = Sample {
            value: 230.0.into(),
            quality: Quality::bad("device offline"),
            timestamp: Timestamp::from_millis(1000),
        };
        let logged = r.offer(id, &bad).unwrap();
        assert_eq!(
            logged.value, None,
            "a Bad value must never reach trend minima or averages"
        );
    }

    #[test]
    fn quality_change_is_logged_even_inside_the_deadband() {
        let mut r = rec(10.0, None);
        let id = TagId(0);
        r.offer(id, &at(0, 5.0));
        let bad = Sample {
            value: Value::Float(5.0),
            quality: Quality::bad("device offline"),
            timestamp: Timestamp::from_millis(1),
        };
        let row = r.offer(id, &bad).expect("quality change");
        assert_eq!(row.quality, QualityCode::Bad);
        // Another reason, same class: no new row.
        let bad2 = Sample {
            quality: Quality::bad("timeout"),
            timestamp: Timestamp::from_millis(2),
            ..bad
        };
        assert!(r.offer(id, &bad2).is_none());
        assert!(r.offer(id, &at(3, 5.0)).is_some());
    }

    #[test]
    fn tick_relogs_the_last_seen_value_when_due() {
        let mut r = rec(5.0, Some(60));
        let id = TagId(0);
        r.offer(id, &at(0, 100.0));
        r.offer(id, &at(10_000, 102.0)); // inside deadband: seen, not logged
        assert!(r.tick(Timestamp::from_millis(59_999)).is_empty());
        let due = r.tick(Timestamp::from_millis(60_000));
        assert_eq!(due.len(), 1);
        assert_eq!(due[0].value, Some(102.0));
        assert_eq!(due[0].ts, Timestamp::from_millis(60_000));
        // The re-log restarts the interval and becomes the deadband reference.
        assert!(r.tick(Timestamp::from_millis(100_000)).is_empty());
        assert!(r.offer(id, &at(100_001, 106.0)).is_none());
        assert!(r.offer(id, &at(100_002, 107.5)).is_some());
    }

    #[test]
    fn late_samples_are_logged_at_their_time_and_a_return_to_good_after_them() {
        let mut r = rec(0.0, None);
        let id = TagId(0);
        assert!(r.offer(id, &at(100, 1.0)).is_some());
        // The link drops: Bad at 200.
        let lost = Sample {
            value: Value::Float(1.0),
            quality: Quality::bad("communication lost"),
            timestamp: Timestamp::from_millis(200),
        };
        assert!(r.offer(id, &lost).is_some());
        // Buffered events from during the outage arrive afterwards, at
        // their own (earlier) times: each is logged there, and the first
        // one also marks the return to Good just after the Bad row.
        let rows: Vec<_> = r.offer_rows(id, &at(150, 2.0)).into_iter().collect();
        assert_eq!(
            rows.iter().map(|h| h.ts.as_millis()).collect::<Vec<_>>(),
            vec![150, 201]
        );
        assert_eq!(rows[1].quality, QualityCode::Good);
        // A later one of them: logged at its time, and the return row
        // (rewritten at the same time) takes its value.
        let rows: Vec<_> = r.offer_rows(id, &at(160, 3.0)).into_iter().collect();
        assert_eq!(
            rows.iter()
                .map(|h| (h.ts.as_millis(), h.value))
                .collect::<Vec<_>>(),
            vec![(160, Some(3.0)), (201, Some(3.0))]
        );
        // The same old time again (an integrity report): not rewritten.
        assert_eq!(r.offer_rows(id, &at(160, 3.0)).into_iter().count(), 0);
        // Newer samples go on from the return.
        assert!(
            r.offer(id, &at(300, 3.0)).is_none(),
            "same value as the return row"
        );
        assert!(r.offer(id, &at(301, 4.0)).is_some());
    }

    #[test]
    fn disabled_unknown_and_string_samples_are_skipped() {
        let mut r = rec(0.0, Some(1));
        let id = TagId(0);
        assert!(r.offer(TagId(9), &at(0, 1.0)).is_none());
        assert!(r
            .offer(id, &Sample::good("text", Timestamp::from_millis(0)))
            .is_none());
        assert!(r.offer(id, &at(100, 1.0)).is_some());
        r.set_policy(
            id,
            "SS1.Zone1.V",
            RecordPolicy {
                enabled: false,
                ..RecordPolicy::default()
            },
        );
        assert!(r.offer(id, &at(200, 3.0)).is_none());
        assert!(r.tick(Timestamp::from_millis(10_000)).is_empty());
    }

    #[test]
    fn bools_log_as_numbers_and_nan_is_a_value_of_its_own() {
        let mut r = rec(0.5, None);
        let id = TagId(0);
        let b = |ms, v: bool| Sample::good(v, Timestamp::from_millis(ms));
        assert_eq!(r.offer(id, &b(0, true)).unwrap().value, Some(1.0));
        assert_eq!(r.offer(id, &b(1, false)).unwrap().value, Some(0.0));
        assert_eq!(r.offer(id, &at(2, f64::NAN)).unwrap().value, None);
        assert!(r.offer(id, &at(3, f64::NAN)).is_none());
        assert!(r.offer(id, &at(4, 0.0)).is_some());
    }

    #[test]
    fn policy_from_config_sanitises() {
        let mut c = HistoryConfig::default();
        let p = RecordPolicy::from_config(&c);
        assert_eq!(p.max_interval, Some(Duration::from_secs(900)));
        assert_eq!(p.deadband, 0.0);
        c.deadband = serde_spanned::Spanned::new(0..0, -3.0);
        c.max_interval_s = serde_spanned::Spanned::new(0..0, 0.0);
        let p = RecordPolicy::from_config(&c);
        assert_eq!(p.deadband, 0.0);
        assert_eq!(p.max_interval, None);
    }
}
