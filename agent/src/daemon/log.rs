//! Warnings that can repeat every tick (a peer sending garbage, Zenoh holding up
//! publishing) are logged at most once per period, with how many were held back.

use std::time::{Duration, Instant};

/// Logs at most one warning per period and says how many were suppressed.
pub(crate) struct RateLimitedLog {
    period: Duration,
    last: Option<Instant>,
    suppressed: u64,
}

impl RateLimitedLog {
    pub fn new(period: Duration) -> Self {
        RateLimitedLog { period, last: None, suppressed: 0 }
    }

    pub fn warn(&mut self, msg: impl FnOnce() -> String) {
        let now = Instant::now();
        if self.last.is_some_and(|l| now - l < self.period) {
            self.suppressed += 1;
            return;
        }
        tracing::warn!(suppressed = self.suppressed, "{}", msg());
        self.last = Some(now);
        self.suppressed = 0;
    }
}
