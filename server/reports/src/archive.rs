//! The report folder, `DATA/reports/`: one `ID.html`, `ID.csv` and
//! `ID.json` per report (ID `2024-06-21` or `2024-06`), each written to a
//! temporary file and renamed, so a reader never sees half a report. And the
//! schedule: yesterday's report once the day is over, last month's once the
//! month is.

use std::io;
use std::path::{Path, PathBuf};

use gridscada_tagdb::Timestamp;
use serde::Serialize;

use crate::{render, Period, Report};

/// A report's formats, as file extensions.
pub const FORMATS: [&str; 3] = ["html", "csv", "json"];

/// The report folder.
#[derive(Debug, Clone)]
pub struct Archive {
    dir: PathBuf,
}

/// A report in the folder.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct ReportEntry {
    pub id: String,
    /// `day` or `month`.
    pub kind: &'static str,
    /// When its HTML was written, ms since the epoch.
    pub modified: i64,
    /// The formats present.
    pub formats: Vec<&'static str>,
}

impl Archive {
    /// The folder under the data folder.
    pub fn in_data_dir(data_dir: &Path) -> Self {
        Archive {
            dir: data_dir.join("reports"),
        }
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The path of `period`'s report in `format` (one of [`FORMATS`]).
    pub fn path(&self, period: Period, format: &str) -> PathBuf {
        self.dir.join(format!("{period}.{format}"))
    }

    /// Writes the report's three files.
    pub fn save(&self, r: &Report) -> io::Result<()> {
        std::fs::create_dir_all(&self.dir)?;
        let json = serde_json::to_string_pretty(r).map_err(io::Error::other)?;
        for (format, text) in [
            ("json", json),
            ("csv", render::csv(r)),
            ("html", render::html(r)),
        ] {
            let path = self.path(r.period, format);
            let tmp = path.with_extension(format!("{format}.tmp"));
            std::fs::write(&tmp, text)?;
            std::fs::rename(&tmp, &path)?;
        }
        Ok(())
    }

    /// Whether `period` has a report (its HTML, written last).
    pub fn has(&self, period: Period) -> bool {
        self.path(period, "html").is_file()
    }

    /// The reports in the folder, newest period first. Files whose name is
    /// not a period are ignored.
    pub fn list(&self) -> io::Result<Vec<ReportEntry>> {
        let mut out: Vec<(Period, ReportEntry)> = Vec::new();
        let rd = match std::fs::read_dir(&self.dir) {
            Ok(rd) => rd,
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(Vec::new()),
            Err(e) => return Err(e),
        };
        for entry in rd {
            let entry = entry?;
            let name = entry.file_name();
            let Some(name) = name.to_str() else { continue };
            let Some(stem) = name.strip_suffix(".html") else {
                continue;
            };
            let Ok(period) = Period::parse(stem) else {
                continue;
            };
            let modified = entry
                .metadata()
                .and_then(|m| m.modified())
                .ok()
                .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
                .map_or(0, |d| d.as_millis() as i64);
            out.push((
                period,
                ReportEntry {
                    id: period.to_string(),
                    kind: if period.is_month() { "month" } else { "day" },
                    modified,
                    formats: FORMATS
                        .into_iter()
                        .filter(|f| self.path(period, f).is_file())
                        .collect(),
                },
            ));
        }
        out.sort_by(|a, b| {
            b.0.start()
                .cmp(&a.0.start())
                .then(a.0.is_month().cmp(&b.0.is_month()))
        });
        Ok(out.into_iter().map(|(_, e)| e).collect())
    }
}

/// When scheduled reports are due: a day's report `delay_s` after the day
/// ends, a month's `delay_s` after it ends (on the 1st), so the historian's
/// last samples of the period are written first.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Schedule {
    pub daily: bool,
    pub monthly: bool,
    pub delay_s: u64,
}

impl Schedule {
    /// The periods due at `now` that `has` says are not yet made: the last
    /// finished day and month (only those: a server that was off for a week
    /// does not make a week of reports at start; they can be made on demand).
    pub fn due(&self, now: Timestamp, has: &dyn Fn(Period) -> bool) -> Vec<Period> {
        let settled = Timestamp::from_millis(now.as_millis() - (self.delay_s as i64) * 1000);
        let mut out = Vec::new();
        if self.daily {
            let day = Period::day_of(settled).previous();
            if !has(day) {
                out.push(day);
            }
        }
        if self.monthly {
            let month = Period::month_of(settled).previous();
            if !has(month) {
                out.push(month);
            }
        }
        out
    }
}

impl Schedule {
    /// From `[reports]`; `None` when neither report is scheduled.
    pub fn from_config(c: &gridscada_config::ReportsConfig) -> Option<Schedule> {
        (c.daily || c.monthly).then(|| Schedule {
            daily: c.daily,
            monthly: c.monthly,
            delay_s: (c.delay_min.get_ref().clamp(0.0, 1440.0) * 60.0) as u64,
        })
    }
}

/// How often the schedule looks for a report due.
const SCHEDULE_CHECK: std::time::Duration = std::time::Duration::from_secs(60);

/// Makes the scheduled reports as they fall due, for as long as the server
/// runs. A report that fails (the store away) is tried again at the next
/// check; each one made or failed is logged.
pub async fn run_schedule(
    store: gridscada_store::Store,
    plant: std::sync::Arc<gridscada_config::Plant>,
    archive: Archive,
    schedule: Schedule,
    clock: std::sync::Arc<dyn gridscada_tagdb::Clock>,
) {
    // Periods with nothing recorded (a fresh install's yesterday): no
    // report, and not tried again.
    let mut empty: std::collections::HashSet<Period> = std::collections::HashSet::new();
    loop {
        let now = clock.now();
        let due: Vec<Period> = {
            let a = archive.clone();
            schedule.due(now, &move |p| a.has(p))
        };
        let due: Vec<Period> = due.into_iter().filter(|p| !empty.contains(p)).collect();
        for period in due {
            match crate::generate(&store, &plant, period, now).await {
                Ok(report) if report.is_empty() => {
                    tracing::info!(%period, "nothing recorded in the period: no scheduled report");
                    empty.insert(period);
                }
                Ok(report) => {
                    let a = archive.clone();
                    match tokio::task::spawn_blocking(move || a.save(&report)).await {
                        Ok(Ok(())) => {
                            tracing::info!(%period, dir = %archive.dir().display(), "report made")
                        }
                        Ok(Err(e)) => {
                            tracing::error!(%period, error = %e, "cannot write the report")
                        }
                        Err(e) => tracing::error!(%period, error = %e, "report writer failed"),
                    }
                }
                Err(e) => {
                    tracing::warn!(%period, error = %e, "cannot make the scheduled report; trying again")
                }
            }
        }
        tokio::time::sleep(SCHEDULE_CHECK).await;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(text: &str) -> Timestamp {
        Timestamp::parse_utc_text(text).unwrap()
    }

    #[test]
    fn yesterday_and_last_month_are_due_after_the_delay() {
        let s = Schedule {
            daily: true,
            monthly: true,
            delay_s: 900,
        };
        let none = |_: Period| false;
        let ids = |v: Vec<Period>| v.iter().map(|p| p.to_string()).collect::<Vec<_>>();
        assert_eq!(
            ids(s.due(at("2024-07-01T00:20:00Z"), &none)),
            ["2024-06-30", "2024-06"]
        );
        // Before the delay, the day before yesterday's and the month before's.
        assert_eq!(
            ids(s.due(at("2024-07-01T00:10:00Z"), &none)),
            ["2024-06-29", "2024-05"]
        );
        let all = |_: Period| true;
        assert!(s.due(at("2024-07-01T00:20:00Z"), &all).is_empty());
    }

    #[test]
    fn the_report_folder_lists_what_was_saved_and_ignores_other_files() {
        let dir = std::env::temp_dir().join(format!("gs-reports-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let a = Archive::in_data_dir(&dir);
        assert!(a.list().unwrap().is_empty());
        std::fs::create_dir_all(a.dir()).unwrap();
        for name in [
            "2024-06-21.html",
            "2024-06-21.csv",
            "2024-06.html",
            "notes.html",
            "2024-06-22.csv",
        ] {
            std::fs::write(a.dir().join(name), "x").unwrap();
        }
        let l = a.list().unwrap();
        let ids: Vec<(&str, &str)> = l.iter().map(|e| (e.id.as_str(), e.kind)).collect();
        assert_eq!(ids, [("2024-06-21", "day"), ("2024-06", "month")]);
        assert_eq!(l[0].formats, ["html", "csv"]);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
