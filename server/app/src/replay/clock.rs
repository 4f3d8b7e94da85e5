//! The replay clocks: [`VirtualClock`] for `--max` (plant time jumps when
//! the whole stack is idle), the floored scaled clock for `--speed`, and
//! [`Pace`], which picks one.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, AtomicI64, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use std::task::{Poll, Waker};
use std::time::Duration;

use gridscada_tagdb::{Clock, ScaledClock, SleepFuture, Timestamp};

/// A plant clock that moves only when the whole stack is idle: `--max`.
///
/// Runs on a current-thread runtime whose park hook calls
/// [`VirtualClock::on_idle`]. The runtime parks only when no task can run;
/// if then no Modbus transaction is in flight (the poller's gauge), nothing
/// can happen until plant time moves, so the clock jumps to the earliest
/// sleeper's deadline and wakes it. Every scan, timer, dispatch period and
/// simulator step therefore happens at its exact plant time, in the same
/// order on every run, and the replay goes as fast as the CPU allows.
///
/// A request to a device that does not answer waits a short wall-time
/// timeout ([`VirtualClock::to_wall`]) and costs no plant time.
pub struct VirtualClock {
    now_ms: AtomicI64,
    timers: Mutex<Timers>,
    /// Set once the stack is up: how many transport operations are in flight.
    busy: OnceLock<Box<dyn Fn() -> u64 + Send + Sync>>,
    frozen: AtomicBool,
}

#[derive(Default)]
struct Timers {
    next_seq: u64,
    /// (deadline ms, registration order) -> waker slot.
    pending: BTreeMap<(i64, u64), Arc<Mutex<SleepSlot>>>,
}

#[derive(Default)]
struct SleepSlot {
    done: bool,
    waker: Option<Waker>,
}

/// Wall-time ceiling of a Modbus timeout under the virtual clock: loopback
/// answers come in microseconds, so this only bounds what a silent device
/// costs; it stays well above scheduling hiccups of a loaded machine, where
/// a spurious timeout would make the run differ from the last.
const VIRTUAL_TIMEOUT_CAP: Duration = Duration::from_millis(250);

impl VirtualClock {
    pub fn new(start: Timestamp) -> Arc<Self> {
        Arc::new(VirtualClock {
            now_ms: AtomicI64::new(start.as_millis()),
            timers: Mutex::new(Timers::default()),
            busy: OnceLock::new(),
            frozen: AtomicBool::new(false),
        })
    }

    /// Lets plant time move, given the poller's in-flight gauge.
    pub fn start(&self, busy: impl Fn() -> u64 + Send + Sync + 'static) {
        let _ = self.busy.set(Box::new(busy));
    }

    /// Stops plant time (while the run's records are collected).
    pub fn freeze(&self) {
        self.frozen.store(true, Ordering::SeqCst);
    }

    /// The runtime has nothing to run: advance to the next deadline.
    pub fn on_idle(&self) {
        if self.frozen.load(Ordering::SeqCst) {
            return;
        }
        let Some(busy) = self.busy.get() else { return };
        if busy() > 0 {
            return;
        }
        let mut wake = Vec::new();
        {
            let mut t = self.timers.lock().unwrap_or_else(|e| e.into_inner());
            // Forget sleeps whose futures were dropped.
            t.pending.retain(|_, s| Arc::strong_count(s) > 1);
            let Some((&(deadline, _), _)) = t.pending.iter().next() else {
                return;
            };
            let now = self.now_ms.load(Ordering::SeqCst).max(deadline);
            self.now_ms.store(now, Ordering::SeqCst);
            while let Some(entry) = t.pending.first_entry() {
                if entry.key().0 > now {
                    break;
                }
                wake.push(entry.remove());
            }
        }
        for slot in wake {
            let mut s = slot.lock().unwrap_or_else(|e| e.into_inner());
            s.done = true;
            if let Some(w) = s.waker.take() {
                w.wake();
            }
        }
    }
}

impl Clock for VirtualClock {
    fn now(&self) -> Timestamp {
        Timestamp::from_millis(self.now_ms.load(Ordering::SeqCst))
    }

    fn sleep(&self, d: Duration) -> SleepFuture {
        let slot = Arc::new(Mutex::new(SleepSlot::default()));
        if d.is_zero() {
            slot.lock().unwrap_or_else(|e| e.into_inner()).done = true;
        } else {
            let deadline = self
                .now_ms
                .load(Ordering::SeqCst)
                .saturating_add(d.as_millis().max(1) as i64);
            let mut t = self.timers.lock().unwrap_or_else(|e| e.into_inner());
            let seq = t.next_seq;
            t.next_seq += 1;
            t.pending.insert((deadline, seq), slot.clone());
        }
        Box::pin(std::future::poll_fn(move |cx| {
            let mut s = slot.lock().unwrap_or_else(|e| e.into_inner());
            if s.done {
                Poll::Ready(())
            } else {
                s.waker = Some(cx.waker().clone());
                Poll::Pending
            }
        }))
    }

    /// Plant time does not move while a request is in flight, so timeouts
    /// only need to bound how long a silent device holds the replay.
    fn to_wall(&self, d: Duration) -> Duration {
        d.min(VIRTUAL_TIMEOUT_CAP)
    }
}

/// A scaled clock whose Modbus timeouts never shrink below what loopback
/// needs under load (at ×700 a 300 ms timeout would be 0.4 ms of wall time).
pub(super) struct FlooredClock(pub(super) ScaledClock);

/// Least wall time a request timeout is given under `--speed`.
const SCALED_TIMEOUT_FLOOR: Duration = Duration::from_millis(25);

impl Clock for FlooredClock {
    fn now(&self) -> Timestamp {
        self.0.now()
    }
    fn sleep(&self, d: Duration) -> SleepFuture {
        self.0.sleep(d)
    }
    fn speed(&self) -> f64 {
        self.0.speed()
    }
    fn to_wall(&self, d: Duration) -> Duration {
        self.0.to_wall(d).max(SCALED_TIMEOUT_FLOOR.min(d))
    }
}

/// How plant time runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Pace {
    /// As fast as the stack can go, on the [`VirtualClock`].
    Max,
    /// `speed` plant seconds per wall second.
    Scaled(f64),
}

impl Pace {
    pub(super) fn label(self) -> String {
        match self {
            Pace::Max => "virtual (--max): plant time advances when the stack is idle".into(),
            Pace::Scaled(s) => format!("scaled ×{s}"),
        }
    }
}
