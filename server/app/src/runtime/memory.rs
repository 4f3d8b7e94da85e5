//! Gives the memory that start-up freed back to the system.
//!
//! Loading a large plant parses every tag file and builds indexes and
//! snapshots that are dropped once the stack runs; glibc keeps those pages
//! in its arenas, so the server's resident size stays at the start-up peak
//! (122 MiB above what it holds at a million tags, docs/BENCHMARKS.md).
//! One trim once the first scans and the historian's start snapshot are
//! through hands them back. Owns nothing else; touches no component.

use std::time::Duration;

/// Long enough for the first scan of every device and the historian's
/// start snapshot at a million tags (they take a few seconds).
const AFTER_START_UP: Duration = Duration::from_secs(30);

/// Trims the allocator once, `AFTER_START_UP` after it is called.
pub(crate) async fn trim_after_start_up() {
    tokio::time::sleep(AFTER_START_UP).await;
    trim();
}

#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn trim() {
    // SAFETY: malloc_trim only returns free pages of glibc's own arenas to
    // the kernel; it takes glibc's arena locks and touches no live block.
    let released = unsafe { libc::malloc_trim(0) };
    tracing::debug!(
        released = released != 0,
        "memory freed at start-up returned"
    );
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn trim() {}
