//! The standard `process_*` series, read from `/proc/self` on Linux.
//!
//! Elsewhere, or where a file cannot be read, the series are left out: a
//! missing figure is better than a wrong one, and a scrape never fails on it.

use super::Prom;

/// Adds whatever this platform tells about the server's own process.
pub fn render(out: &mut Prom) {
    #[cfg(target_os = "linux")]
    linux::render(out);
    #[cfg(not(target_os = "linux"))]
    let _ = out;
}

#[cfg(target_os = "linux")]
mod linux {
    use super::Prom;

    /// Clock ticks per second of `/proc/*/stat` (`USER_HZ`): 100 in the
    /// kernel's user ABI on every architecture we build for.
    const TICKS_PER_S: f64 = 100.0;

    pub(super) fn render(out: &mut Prom) {
        let stat = std::fs::read_to_string("/proc/self/stat").ok();
        // The fields after the command name, which is in parentheses and may
        // hold spaces: field 3 of proc(5) is `after[0]`.
        let after: Vec<&str> = stat
            .as_deref()
            .and_then(|s| s.rsplit_once(')'))
            .map(|(_, rest)| rest.split_whitespace().collect())
            .unwrap_or_default();
        let field = |n: usize| after.get(n - 3).and_then(|v| v.parse::<f64>().ok());
        if let (Some(utime), Some(stime)) = (field(14), field(15)) {
            out.counter(
                "process_cpu_seconds_total",
                "Total user and system CPU time spent in seconds.",
                &[],
                (utime + stime) / TICKS_PER_S,
            );
        }
        let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
        let kib = |key: &str| {
            status.lines().find_map(|l| {
                l.strip_prefix(key)?
                    .trim()
                    .strip_suffix("kB")?
                    .trim()
                    .parse::<f64>()
                    .ok()
            })
        };
        if let Some(rss) = kib("VmRSS:") {
            out.gauge(
                "process_resident_memory_bytes",
                "Resident memory size in bytes.",
                &[],
                rss * 1024.0,
            );
        }
        if let Some(vm) = kib("VmSize:") {
            out.gauge(
                "process_virtual_memory_bytes",
                "Virtual memory size in bytes.",
                &[],
                vm * 1024.0,
            );
        }
        if let Ok(fds) = std::fs::read_dir("/proc/self/fd") {
            out.gauge(
                "process_open_fds",
                "Number of open file descriptors.",
                &[],
                fds.count() as f64,
            );
        }
        let limits = std::fs::read_to_string("/proc/self/limits").unwrap_or_default();
        let max_fds = limits.lines().find_map(|l| {
            let soft = l
                .strip_prefix("Max open files")?
                .split_whitespace()
                .next()?;
            soft.parse::<f64>().ok()
        });
        if let Some(max) = max_fds {
            out.gauge(
                "process_max_fds",
                "Maximum number of open file descriptors.",
                &[],
                max,
            );
        }
        let boot = std::fs::read_to_string("/proc/stat").ok().and_then(|s| {
            s.lines()
                .find_map(|l| l.strip_prefix("btime ")?.trim().parse::<f64>().ok())
        });
        if let (Some(boot), Some(start)) = (boot, field(22)) {
            out.gauge(
                "process_start_time_seconds",
                "Start time of the process since unix epoch in seconds.",
                &[],
                boot + start / TICKS_PER_S,
            );
        }
    }

    #[cfg(test)]
    mod tests {
        use super::*;

        #[test]
        fn every_process_series_is_read() {
            let mut p = Prom::default();
            render(&mut p);
            let text = p.finish();
            for name in [
                "process_cpu_seconds_total ",
                "process_resident_memory_bytes ",
                "process_virtual_memory_bytes ",
                "process_open_fds ",
                "process_max_fds ",
                "process_start_time_seconds ",
            ] {
                assert!(text.contains(name), "{name} missing:\n{text}");
            }
            let start: f64 = text
                .lines()
                .find_map(|l| l.strip_prefix("process_start_time_seconds "))
                .unwrap()
                .parse()
                .unwrap();
            let now = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .unwrap()
                .as_secs_f64();
            assert!(
                start <= now + 1.0 && start > now - 3600.0,
                "{start} vs {now}"
            );
        }
    }
}
