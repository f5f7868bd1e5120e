//! Feeds that repeat themselves. A live detector's output moves with sensor noise even
//! when the worker and the robot stand still, so a worker detection seen before bit for
//! bit — the last frame's (a frozen camera or detector) or one of the last minute's (a
//! camera replaying a clip) — is confident, plausible and wrong. The engine counts such
//! repeats in its own feed (the worker's box and keypoints) and in each peer's
//! embedding, and sets a feed aside while it repeats.

use crate::hash::Fnv1a;
use std::collections::VecDeque;

/// How many of a feed's latest values a repeat is looked for among: a minute at 10 Hz,
/// longer than any clip a looping camera plays back within it.
pub const REMEMBERED: usize = 600;

/// A feed's latest [`REMEMBERED`] values, each kept as a 64-bit fingerprint, and how
/// long its current run is: the value that started it and the values after it that had
/// been shown before.
#[derive(Debug, Clone, Default)]
pub struct Repeats {
    recent: VecDeque<u64>,
    count: u32,
}

impl Repeats {
    /// Takes the feed's next value (`None`: nothing to compare, e.g. no worker in view,
    /// which neither ends a run of repeats nor adds to it: a clip played back with gaps
    /// in it stays a clip).
    pub fn see(&mut self, value: Option<impl IntoIterator<Item = f32>>) {
        let Some(value) = value else { return };
        let mut h = Fnv1a::default();
        for x in value {
            h.eat(&x.to_bits().to_le_bytes());
        }
        self.count = if self.recent.contains(&h.0) { self.count + 1 } else { 1 };
        if self.recent.len() == REMEMBERED {
            self.recent.pop_front();
        }
        self.recent.push_back(h.0);
    }

    /// The feed's last `after - 1` values in a row were shown before (for 3, a frozen
    /// feed's third identical frame); never when `after` is 0.
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
        r.see(None::<[f32; 2]>);
        assert!(!r.is_stale(2), "a frame without a value adds nothing");
        r.see(Some([1.0, 2.000001]));
        assert!(r.is_stale(2), "nor does it break the run: the value was seen before");
        r.see(None::<[f32; 2]>);
        assert!(r.is_stale(2), "still stale until a new value comes");
    }

    #[test]
    fn a_feed_playing_back_a_clip_is_stale_once_the_clip_comes_round_again() {
        let mut r = Repeats::default();
        let clip: Vec<[f32; 2]> = (0..50).map(|i| [i as f32, 0.5]).collect();
        for v in &clip {
            r.see(Some(*v));
            assert!(!r.is_stale(3), "every value new the first time");
        }
        r.see(Some(clip[0]));
        assert!(!r.is_stale(3));
        r.see(Some(clip[1]));
        assert!(r.is_stale(3), "two values in a row seen before, as a frozen feed's third frame");
        // A clip older than what is remembered is not recognised.
        let mut r = Repeats::default();
        for i in 0..REMEMBERED + 3 {
            r.see(Some([i as f32]));
        }
        for i in 0..3 {
            r.see(Some([i as f32]));
        }
        assert!(!r.is_stale(2));
    }
}
