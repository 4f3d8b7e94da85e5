//! Reading the set out: summaries and views for the HMI, records to
//! persist, and restoring from them at start-up.

use crate::machine::Alarm;
use crate::model::{AlarmFilter, AlarmId, AlarmKind, AlarmStateRecord, AlarmView};

use super::defs::system_def;
use super::{AlarmSet, RestoreReport};

/// The view of `a` if a list with `filter` shows it.
fn shown(a: &Alarm, filter: &AlarmFilter) -> Option<AlarmView> {
    // Cheap pre-check before building a view: Normal alarms are the vast
    // majority and the default list never shows them.
    (!filter.states.is_empty() || a.is_active() || !a.is_acked())
        .then(|| a.view())
        .filter(|v| filter.matches(v))
}

impl AlarmSet {
    /// The alarms the filter shows, newest change first (then higher priority).
    pub fn summary(&self, filter: &AlarmFilter) -> Vec<AlarmView> {
        let mut v: Vec<AlarmView> = self
            .alarms
            .iter()
            .filter_map(|a| shown(a, filter))
            .collect();
        v.sort_by(|a, b| {
            b.last_change
                .cmp(&a.last_change)
                .then(b.priority.cmp(&a.priority))
                .then(a.id.cmp(&b.id))
        });
        v
    }

    /// What became of alarms `ids` for a list the filter shows: the views
    /// of those it shows now, and the ids of those it no longer shows.
    pub fn summary_of(
        &self,
        ids: impl IntoIterator<Item = AlarmId>,
        filter: &AlarmFilter,
    ) -> (Vec<AlarmView>, Vec<AlarmId>) {
        let (mut shown, mut gone) = (vec![], vec![]);
        for id in ids {
            let Some(a) = self.alarm(id) else { continue };
            match self::shown(a, filter) {
                Some(v) => shown.push(v),
                None => gone.push(id),
            }
        }
        (shown, gone)
    }

    /// Every alarm's view, in id order.
    pub fn all_views(&self) -> Vec<AlarmView> {
        self.alarms.iter().map(Alarm::view).collect()
    }

    /// Every alarm's persistent state.
    pub fn records(&self) -> Vec<AlarmStateRecord> {
        self.alarms.iter().map(Alarm::record).collect()
    }

    pub fn record(&self, id: AlarmId) -> Option<AlarmStateRecord> {
        self.alarm(id).map(Alarm::record)
    }

    /// Restores persisted states at start-up, before any sample is applied.
    /// Records of system alarms are recreated; records of alarms the
    /// configuration no longer has are skipped. Suppression is recomputed from
    /// the restored triggers.
    pub fn restore(&mut self, records: &[AlarmStateRecord]) -> RestoreReport {
        let mut report = RestoreReport::default();
        for r in records {
            let id = match self.by_key.get(&r.key) {
                Some(id) => *id,
                None if r.kind == AlarmKind::System => {
                    match self.add(system_def(&r.key, r.priority, &r.selection, &r.message)) {
                        Ok(id) => {
                            report.recreated += 1;
                            id
                        }
                        Err(_) => {
                            report.skipped.push(r.key.clone());
                            continue;
                        }
                    }
                }
                None => {
                    report.skipped.push(r.key.clone());
                    continue;
                }
            };
            self.alarms[id.index()].restore(r);
            report.restored += 1;
        }
        for r in &mut self.rules {
            r.engaged = self.alarms[r.trigger.index()].is_active();
            r.clear_since = None;
        }
        for i in 0..self.alarms.len() {
            let want = self.suppression_wanted(AlarmId(i as u32));
            self.alarms[i].restore_suppressed(want);
        }
        self.deadline_hint = self.exact_deadline();
        report
    }
}
