//! The replay clocks: [`VirtualClock`] for `--max` (plant time jumps when
//! the whole stack is idle), the floored scaled clock for `--speed`, and
//! [`Pace`], which picks one.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, AtomicI64, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use std::task::{Poll, Waker};
use std::time::{Duration, Instant};

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
/// A request to a device that does not answer waits a short timeout and
/// costs no plant time. The timeout counts only wall time the runtime spent
/// parked, waiting ([`Clock::request_wait`]): time spent running other
/// tasks, in a long solve, or descheduled on a loaded machine is not the
/// device's silence, and counting it made the same scenario time out a
/// request on one run and not on the next.
pub struct VirtualClock {
    now_ms: AtomicI64,
    idle: Arc<IdleMeter>,
    timers: Mutex<Timers>,
    /// Set once the stack is up: how many transport operations are in flight.
    busy: OnceLock<Box<dyn Fn() -> u64 + Send + Sync>>,
    frozen: AtomicBool,
}

/// Wall time the runtime has spent parked (between its park and unpark
/// hooks), summed.
#[derive(Default)]
struct IdleMeter {
    total_ns: AtomicU64,
    parked_at: Mutex<Option<Instant>>,
}

impl IdleMeter {
    fn park(&self) {
        *self.parked_at.lock().unwrap_or_else(|e| e.into_inner()) = Some(Instant::now());
    }

    fn unpark(&self) {
        let since = self
            .parked_at
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .take();
        if let Some(t) = since {
            let ns = u64::try_from(t.elapsed().as_nanos()).unwrap_or(u64::MAX);
            self.total_ns.fetch_add(ns, Ordering::SeqCst);
        }
    }

    fn total(&self) -> u64 {
        self.total_ns.load(Ordering::SeqCst)
    }
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
            idle: Arc::default(),
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

    /// The runtime has nothing to run (its park hook): advance to the next
    /// deadline, unless a transaction is in flight.
    pub fn on_idle(&self) {
        self.idle.park();
        self.advance_when_idle();
    }

    /// The runtime woke up (its unpark hook).
    pub fn on_wake(&self) {
        self.idle.unpark();
    }

    fn advance_when_idle(&self) {
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

    /// `d` (at most [`VIRTUAL_TIMEOUT_CAP`]) of wall time spent parked.
    fn request_wait(&self, d: Duration) -> Option<SleepFuture> {
        let budget = u64::try_from(d.min(VIRTUAL_TIMEOUT_CAP).as_nanos()).unwrap_or(u64::MAX);
        let idle = self.idle.clone();
        let start = idle.total();
        Some(Box::pin(async move {
            loop {
                let used = idle.total().saturating_sub(start);
                if used >= budget {
                    return;
                }
                tokio::time::sleep(Duration::from_nanos(budget - used)).await;
            }
        }))
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The replay's runtime: one thread, the clock's park and unpark hooks.
    fn runtime(clock: &Arc<VirtualClock>) -> tokio::runtime::Runtime {
        let (park, wake) = (clock.clone(), clock.clone());
        tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .on_thread_park(move || park.on_idle())
            .on_thread_unpark(move || wake.on_wake())
            .build()
            .unwrap()
    }

    #[test]
    fn a_request_is_not_timed_out_while_the_runtime_is_busy() {
        let clock = VirtualClock::new(Timestamp::from_millis(0));
        clock.start(|| 1); // a transaction in flight: plant time holds
        let rt = runtime(&clock);
        let answered = rt.block_on(async {
            let wait = clock.request_wait(Duration::from_secs(1)).unwrap();
            let (tx, rx) = tokio::sync::oneshot::channel::<()>();
            // A long solve holds the thread past the wait's 250 ms, then
            // the device's answer comes.
            tokio::spawn(async move {
                std::thread::sleep(Duration::from_millis(400));
                tokio::task::yield_now().await;
                let _ = tx.send(());
            });
            tokio::select! {
                biased;
                _ = rx => true,
                _ = wait => false,
            }
        });
        assert!(answered, "the busy time counted as the device's silence");
    }

    #[test]
    fn a_silent_device_times_out_after_the_idle_wait() {
        let clock = VirtualClock::new(Timestamp::from_millis(0));
        clock.start(|| 1);
        let rt = runtime(&clock);
        let started = std::time::Instant::now();
        rt.block_on(clock.request_wait(Duration::from_secs(5)).unwrap());
        let took = started.elapsed();
        assert!(took >= VIRTUAL_TIMEOUT_CAP, "{took:?}");
        assert!(took < Duration::from_secs(5), "{took:?}");
        assert_eq!(clock.now(), Timestamp::from_millis(0), "plant time moved");
    }
}
