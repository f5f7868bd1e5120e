//! The fleet's clock. A tick is a 100 ms period of a synchronised wall clock
//! (`tick = floor(capture time / 100 ms)`, time since the Unix epoch), so every robot
//! names the same tick for the same moment without asking anyone: a frame source that
//! restarts goes on at the current tick, and no robot's counter sets the team's time.
//! Real robots keep their hosts' clocks within a few milliseconds with chrony or PTP
//! (deploy/README.md says how, and what an offset costs).
//!
//! Each robot takes a frame or a peer's message only for a tick near its own clock
//! ([`TickWindow`]): a few ticks back, for what is late, and a few ahead, for clocks
//! slightly ahead of ours. Everything else is refused and counted ([`OffClock`]), so a
//! tick number from far away, in either direction, costs one comparison.
//!
//! The engine takes `now` as an argument and never reads a clock itself; the daemon
//! reads [`FleetClock`], the evaluation and a replay inject theirs.

use serde::{Deserialize, Serialize};
use spwi_proto::{tick_at, tick_start, TICK_PERIOD};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

/// The ticks a robot takes input for, around the tick of its clock.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct TickWindow {
    /// How many ticks before the current one are still taken (late frames and messages).
    pub past: u64,
    /// How many ticks after the current one are taken (clocks a little ahead of ours).
    pub ahead: u64,
}

impl Default for TickWindow {
    fn default() -> Self {
        TickWindow { past: 5, ahead: 2 }
    }
}

/// Why a tick was refused: it lies before or after the window, frame or message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum OffClock {
    FrameTooOld,
    FrameTooNew,
    MessageTooOld,
    MessageTooNew,
}

impl OffClock {
    /// The `reason` label of `spwi_off_clock_total`.
    pub fn label(self) -> &'static str {
        match self {
            OffClock::FrameTooOld => "frame_too_old",
            OffClock::FrameTooNew => "frame_too_new",
            OffClock::MessageTooOld => "message_too_old",
            OffClock::MessageTooNew => "message_too_new",
        }
    }

    /// The same side of the window, for one of our own frames.
    pub fn frame(self) -> OffClock {
        match self {
            OffClock::FrameTooOld | OffClock::MessageTooOld => OffClock::FrameTooOld,
            OffClock::FrameTooNew | OffClock::MessageTooNew => OffClock::FrameTooNew,
        }
    }

    /// The same side of the window, for a peer's message.
    pub fn message(self) -> OffClock {
        match self {
            OffClock::FrameTooOld | OffClock::MessageTooOld => OffClock::MessageTooOld,
            OffClock::FrameTooNew | OffClock::MessageTooNew => OffClock::MessageTooNew,
        }
    }
}

impl TickWindow {
    /// The oldest tick taken at `now`.
    pub fn oldest(&self, now: Duration) -> u64 {
        tick_at(now).saturating_sub(self.past)
    }

    /// The newest tick taken at `now`.
    pub fn newest(&self, now: Duration) -> u64 {
        tick_at(now).saturating_add(self.ahead)
    }

    /// `None` when `tick` is taken at `now`, else which side of the window it lies on
    /// (named as for a message; [`OffClock::frame`] renames it for a frame).
    pub fn refuses(&self, tick: u64, now: Duration) -> Option<OffClock> {
        if tick < self.oldest(now) {
            Some(OffClock::MessageTooOld)
        } else if tick > self.newest(now) {
            Some(OffClock::MessageTooNew)
        } else {
            None
        }
    }

    /// How long after a tick starts the window lets it go: what a deadline must fit in.
    pub fn reach(&self) -> Duration {
        TICK_PERIOD * self.past as u32
    }
}

/// How one source's ticks sit against our clock: the start of the tick it named less
/// the moment we heard it, averaged over its latest messages within our window (ms;
/// negative: its ticks start before we hear them, as they should by a link's delay);
/// how many of its messages fell outside the window, and by how much the latest did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct PeerClock {
    /// `None` until it is first heard within the window.
    pub offset_ms: Option<f32>,
    pub refused: u64,
    /// The same offset for its latest message outside the window (ms).
    pub last_refused_ms: Option<i64>,
}

impl PeerClock {
    /// Weight of the latest message in the average (about the last 20).
    const RATE: f32 = 0.05;

    /// A message of tick `tick` heard at `now`.
    pub fn heard(&mut self, tick: u64, now: Duration) {
        let x = signed_ms(tick_start(tick), now) as f32;
        self.offset_ms = Some(self.offset_ms.map_or(x, |m| m + Self::RATE * (x - m)));
    }

    /// A message of tick `tick` heard at `now`, outside our window.
    pub fn heard_off_window(&mut self, tick: u64, now: Duration) {
        self.refused += 1;
        self.last_refused_ms = Some(signed_ms(tick_start(tick), now));
    }
}

/// `at − now` in whole milliseconds, negative when `at` is earlier.
pub fn signed_ms(at: Duration, now: Duration) -> i64 {
    if at >= now {
        (at - now).as_millis().min(i64::MAX as u128) as i64
    } else {
        -((now - at).as_millis().min(i64::MAX as u128) as i64)
    }
}

/// The daemon's clock: the host's wall clock (time since the Unix epoch), which chrony
/// or PTP keeps in step with the fleet's, plus an offset that is zero on a real robot
/// (tests and benchmarks shift one robot's clock to see what an offset costs).
#[derive(Debug, Clone, Copy, Default)]
pub struct FleetClock {
    offset_ms: i64,
}

impl FleetClock {
    pub fn with_offset_ms(offset_ms: i64) -> FleetClock {
        FleetClock { offset_ms }
    }

    /// Now on the fleet's clock, as this host reads it.
    pub fn now(&self) -> Duration {
        let wall = SystemTime::now().duration_since(UNIX_EPOCH).unwrap_or_default();
        let shift = Duration::from_millis(self.offset_ms.unsigned_abs());
        if self.offset_ms >= 0 {
            wall + shift
        } else {
            wall.saturating_sub(shift)
        }
    }

    /// How long from now until `at` on this clock (zero if it has passed).
    pub fn until(&self, at: Duration) -> Duration {
        at.saturating_sub(self.now())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(m: u64) -> Duration {
        Duration::from_millis(m)
    }

    #[test]
    fn the_window_takes_a_few_ticks_back_and_fewer_ahead_and_nothing_beyond() {
        let w = TickWindow { past: 5, ahead: 2 };
        let now = ms(1_000_050); // tick 10_000
        assert_eq!(w.refuses(10_000, now), None);
        assert_eq!(w.refuses(9_995, now), None);
        assert_eq!(w.refuses(10_002, now), None);
        assert_eq!(w.refuses(9_994, now), Some(OffClock::MessageTooOld));
        assert_eq!(w.refuses(10_003, now), Some(OffClock::MessageTooNew));
        assert_eq!(w.refuses(u64::MAX, now), Some(OffClock::MessageTooNew));
        assert_eq!(w.refuses(0, now), Some(OffClock::MessageTooOld));
        assert_eq!(w.refuses(0, now).map(OffClock::frame), Some(OffClock::FrameTooOld));
        // near the epoch the window cannot reach below tick 0
        assert_eq!(w.refuses(0, ms(30)), None);
        assert_eq!(w.reach(), ms(500));
    }

    #[test]
    fn a_peers_clock_is_averaged_from_what_it_names_and_when_it_is_heard() {
        let mut c = PeerClock::default();
        c.heard(10, ms(1_003)); // tick 10 starts at 1000 ms: heard 3 ms after
        assert_eq!(c.offset_ms, Some(-3.0));
        for _ in 0..200 {
            c.heard(10, ms(970)); // a clock 30 ms ahead of ours
        }
        assert!((c.offset_ms.unwrap() - 30.0).abs() < 0.1, "{c:?}");
        assert_eq!(signed_ms(ms(5), ms(7)), -2);
    }

    #[test]
    fn a_shifted_clock_reads_the_wall_clock_shifted() {
        let (a, b) = (FleetClock::default().now(), FleetClock::with_offset_ms(-60_000).now());
        assert!(a > b + ms(59_000) && a < b + ms(61_000));
        assert!(FleetClock::with_offset_ms(50).now() > a);
    }
}
