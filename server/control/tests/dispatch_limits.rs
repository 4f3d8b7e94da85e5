//! A dispatch problem far over the limits is refused from a count of its
//! text, without being read into memory (200,000 units were refused only
//! after 27 s and 209 MB, once a JSON tree of them had been built and
//! validated). Alone in its test binary: the allocator below counts every
//! allocation of the process.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering::Relaxed};
use std::time::Duration;

use gridscada_control::dispatch::solve_text;

/// The system allocator, counting the bytes live and the most live at once.
struct Counting;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            let live = LIVE.fetch_add(layout.size(), Relaxed) + layout.size();
            PEAK.fetch_max(live, Relaxed);
        }
        p
    }

    unsafe fn dealloc(&self, p: *mut u8, layout: Layout) {
        unsafe { System.dealloc(p, layout) };
        LIVE.fetch_sub(layout.size(), Relaxed);
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// What refusing may allocate beyond the text: the error and its message.
/// The problem's JSON tree alone would take over 100 MB.
const BUDGET: usize = 4 * 1024 * 1024;

#[test]
fn a_problem_of_200000_units_is_refused_before_it_is_read() {
    let units: Vec<String> = (0..200_000)
        .map(|i| format!(r#"{{"id": "pv{i}", "available_kw": 1.0, "cost_per_kwh": 0.0}}"#))
        .collect();
    let text = format!(
        r#"{{"dt_h": 0.25, "demand_kw": 10.0, "voll_per_kwh": 5.0, "pv": [{}]}}"#,
        units.join(",")
    );
    drop(units);
    let before = LIVE.load(Relaxed);
    PEAK.store(before, Relaxed);
    // Solved beside this thread, which stops the test as soon as the budget
    // is exceeded rather than waiting for a slow refusal to finish.
    let solve = std::thread::spawn(move || solve_text(&text));
    while !solve.is_finished() {
        let used = PEAK.load(Relaxed).saturating_sub(before);
        assert!(
            used <= BUDGET,
            "refusing allocated {used} bytes, more than {BUDGET}"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    let out = solve.join().expect("the solve panicked");
    let used = PEAK.load(Relaxed).saturating_sub(before);
    assert!(
        used <= BUDGET,
        "refusing allocated {used} bytes, more than {BUDGET}"
    );
    assert_eq!(out.exit_code, 1, "{}", out.stderr);
    assert!(out.stdout.is_empty(), "{}", out.stdout);
    assert_eq!(
        out.stderr,
        "error: 200000 units; at most 1000 (PV, wind, oil and storage together) are accepted\n"
    );
}
