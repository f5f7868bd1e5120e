//! Gives the heap's free pages back to the system every half minute.
//!
//! A daemon's live heap stays flat (≈ 6.3 MB over a 6-minute soak with robots leaving,
//! joining and freezing, heaptrack), yet its anonymous memory grew ≈ 1.2 MB in five
//! minutes: glibc's allocator keeps the pages freed between live allocations, and one
//! `malloc_trim` gave nearly all of it back (docs/BENCHMARKS.md, "Soak"). Trimming
//! walks the heap's free lists once (125–336 µs on an idle agent here), on a task of its
//! own, never on a tick's path.
//! Other allocators (musl, macOS) have no `malloc_trim`: there this does nothing.

use std::time::{Duration, Instant};

/// How often the free pages go back.
pub const TRIM_PERIOD: Duration = Duration::from_secs(30);

/// Trims every `period`, until the task is aborted.
pub async fn trim_every(period: Duration) {
    let mut every = tokio::time::interval(period);
    every.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    every.tick().await; // the first tick completes at once: nothing to give back yet
    loop {
        every.tick().await;
        let t0 = Instant::now();
        let released = trim();
        tracing::debug!(released, took_us = t0.elapsed().as_micros() as u64, "heap trimmed");
    }
}

/// Returns the heap's free pages to the system; true if any went back.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn trim() -> bool {
    // SAFETY: malloc_trim takes the allocator's own locks; it frees nothing in use.
    unsafe { libc::malloc_trim(0) == 1 }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn trim() -> bool {
    false
}
