//! Feeds that repeat themselves. A live detector's output moves with sensor noise even
//! when the worker and the robot stand still, so the same worker detection bit for bit,
//! frame after frame, is a frozen camera or detector: confident, plausible and wrong.
//! The engine counts repeats of its own feed (the worker's box and keypoints) and of
//! each peer's embedding, and sets a feed aside while it repeats.

/// How many times in a row the latest value of a feed has been seen.
#[derive(Debug, Clone)]
pub struct Repeats<T> {
    last: Option<T>,
    count: u32,
}

impl<T> Default for Repeats<T> {
    fn default() -> Self {
        Repeats { last: None, count: 0 }
    }
}

impl<T: PartialEq> Repeats<T> {
    /// Takes the feed's next value (`None`: nothing to compare, e.g. no worker in view,
    /// which ends a run of repeats).
    pub fn see(&mut self, value: Option<T>) {
        match value {
            Some(v) if self.last.as_ref() == Some(&v) => self.count += 1,
            Some(v) => {
                self.last = Some(v);
                self.count = 1;
            }
            None => {
                self.last = None;
                self.count = 0;
            }
        }
    }

    /// The feed has shown the same value `after` times in a row (never when `after` is 0).
    pub fn is_stale(&self, after: u32) -> bool {
        after > 0 && self.count >= after
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_feed_is_stale_from_the_nth_identical_value_until_it_changes() {
        let mut r = Repeats::default();
        for _ in 0..2 {
            r.see(Some([1.0f32, 2.0]));
            assert!(!r.is_stale(3));
        }
        r.see(Some([1.0, 2.0]));
        assert!(r.is_stale(3) && !r.is_stale(0), "third identical value: stale (0 never is)");
        r.see(Some([1.0, 2.000001]));
        assert!(!r.is_stale(3), "a change, however small, is a live feed");
        r.see(Some([1.0, 2.000001]));
        r.see(None);
        r.see(Some([1.0, 2.000001]));
        assert!(!r.is_stale(2), "a frame without the value breaks the run");
    }
}
