//! Flood limiting: at most `limit` alarm messages per window on a route;
//! what comes on top is held and told in one summary when the window ends,
//! so an alarm flood sends one summary, not 500 mails. Pure.

/// What to do with one more message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Offer {
    Send,
    /// Counted into the window's summary.
    Held,
}

/// The summary of a window's held messages.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    /// When the window opened and closed (ms).
    pub from_ms: i64,
    pub to_ms: i64,
    /// Messages sent in the window, and held.
    pub sent: u32,
    pub held: u32,
    /// The first held messages' lines (alarm and message), at most
    /// [`SUMMARY_LINES`].
    pub lines: Vec<String>,
}

/// How many held alarms a summary names one by one.
pub const SUMMARY_LINES: usize = 20;

#[derive(Debug, Clone)]
pub struct FloodWindow {
    limit: u32,
    window_ms: i64,
    /// The open window's start; `None`: no window open.
    start_ms: Option<i64>,
    sent: u32,
    held: u32,
    lines: Vec<String>,
}

impl FloodWindow {
    pub fn new(limit: u32, window_ms: i64) -> FloodWindow {
        FloodWindow {
            limit: limit.max(1),
            window_ms: window_ms.max(1),
            start_ms: None,
            sent: 0,
            held: 0,
            lines: vec![],
        }
    }

    /// One more message at `now_ms`, described by `line` (kept if held).
    /// Call [`FloodWindow::close_due`] first, so an ended window's summary
    /// goes out before a new window opens.
    pub fn offer(&mut self, now_ms: i64, line: impl FnOnce() -> String) -> Offer {
        let start = *self.start_ms.get_or_insert(now_ms);
        debug_assert!(now_ms < start + self.window_ms || self.held == 0);
        if now_ms >= start + self.window_ms {
            // The window ended with nothing held: a fresh one.
            self.start_ms = Some(now_ms);
            self.sent = 0;
        }
        if self.sent < self.limit {
            self.sent += 1;
            Offer::Send
        } else {
            self.held += 1;
            if self.lines.len() < SUMMARY_LINES {
                self.lines.push(line());
            }
            Offer::Held
        }
    }

    /// The summary of the window, once it has ended with messages held.
    /// The window closes with it.
    pub fn close_due(&mut self, now_ms: i64) -> Option<Summary> {
        let start = self.start_ms?;
        if now_ms < start + self.window_ms {
            return None;
        }
        let summary = (self.held > 0).then(|| Summary {
            from_ms: start,
            to_ms: start + self.window_ms,
            sent: self.sent,
            held: self.held,
            lines: std::mem::take(&mut self.lines),
        });
        self.start_ms = None;
        self.sent = 0;
        self.held = 0;
        self.lines.clear();
        summary
    }

    /// When the open window ends, if messages are held in it.
    pub fn due_at(&self) -> Option<i64> {
        self.start_ms
            .filter(|_| self.held > 0)
            .map(|s| s + self.window_ms)
    }
}

/// The wait before retry number `attempt` (1: after the first failure):
/// 10 s doubling to at most 15 min.
pub fn backoff_ms(attempt: u32) -> i64 {
    const FIRST_MS: i64 = 10_000;
    const MAX_MS: i64 = 15 * 60_000;
    let doublings = attempt.saturating_sub(1).min(16);
    (FIRST_MS << doublings).min(MAX_MS)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_flood_sends_the_limit_then_one_summary() {
        let mut w = FloodWindow::new(5, 60_000);
        let mut sent = 0;
        for i in 0..500 {
            let now = i * 100; // 500 alarms in 50 s
            assert_eq!(w.close_due(now), None);
            if w.offer(now, || format!("alarm {i}")) == Offer::Send {
                sent += 1;
            }
        }
        assert_eq!(sent, 5);
        assert_eq!(w.due_at(), Some(60_000));
        assert_eq!(w.close_due(59_999), None);
        let s = w.close_due(60_000).unwrap();
        assert_eq!((s.sent, s.held, s.from_ms, s.to_ms), (5, 495, 0, 60_000));
        assert_eq!(s.lines.len(), SUMMARY_LINES);
        assert_eq!(s.lines[0], "alarm 5");
        // Once told, the next alarm opens a fresh window and is sent.
        assert_eq!(w.close_due(61_000), None);
        assert_eq!(w.offer(61_000, String::new), Offer::Send);
        assert_eq!(w.due_at(), None);
    }

    #[test]
    fn a_quiet_route_is_never_held() {
        let mut w = FloodWindow::new(2, 60_000);
        for i in 0..10 {
            let now = i * 45_000; // one alarm every 45 s
            assert_eq!(w.close_due(now), None);
            assert_eq!(w.offer(now, String::new), Offer::Send, "alarm {i}");
        }
    }

    #[test]
    fn backoff_doubles_to_a_ceiling() {
        let waits: Vec<i64> = (1..=9).map(backoff_ms).collect();
        assert_eq!(
            waits,
            vec![10_000, 20_000, 40_000, 80_000, 160_000, 320_000, 640_000, 900_000, 900_000]
        );
        assert_eq!(backoff_ms(u32::MAX), 900_000);
        assert_eq!(backoff_ms(0), 10_000);
    }
}
