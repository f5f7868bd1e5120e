//! What is let in, and for which tick. Time is the fleet's clock, never a peer's word
//! ([`crate::clock`]): `now` is the robot's synchronised wall clock, a tick is one of its
//! 100 ms periods, and a frame or a peer's message is taken only for a tick within the
//! [`crate::clock::TickWindow`] around `now`. Others are refused and counted by reason,
//! so no tick number (huge, repeated, going backwards) can open ticks for the team or
//! block the ones that follow, and a restarted frame source goes on at the current tick.
//!
//! A tick's deadline runs from the first thing this robot heard of it, but never from
//! before the tick starts on its own clock unless that first thing is its own frame: a
//! peer that opens ticks early moves no deadline, and a robot whose clock runs a little
//! behind still decides as soon as its peers. What is remembered of decided ticks
//! reaches back as far as the window. A message from another daemon with our robot id
//! is noted, never counted.

use super::{Engine, Output, Tick};
use spwi_proto::*;
use std::time::Duration;

impl Engine {
    /// Checks a peer message's origin and tick; returns the tick to file it in.
    pub(super) fn accept_peer(
        &mut self,
        robot: &RobotId,
        instance: u64,
        tick: u64,
        now: Duration,
    ) -> Option<&mut Tick> {
        if *robot == self.cfg.robot {
            if instance != self.cfg.instance {
                self.metrics.duplicate_id_messages += 1;
                if self.duplicates.insert(instance) {
                    tracing::error!(robot = %robot, other_instance = instance, "another live daemon uses this robot id: peers cannot tell our votes apart; give each robot a unique id");
                }
            }
            return None;
        }
        self.active.insert(robot.clone()); // even a late message shows the peer is there
        if self.decided.contains_key(&tick) {
            self.metrics.late_messages += 1;
            return None;
        }
        Some(self.open_tick(tick, now))
    }

    /// Whether a message of `robot` for `tick` is for a tick near our clock; one that
    /// is not is refused and counted, and shows in the peer's clock record either way.
    pub(super) fn on_our_clock(&mut self, robot: &RobotId, tick: u64, now: Duration) -> bool {
        let refused = self.cfg.window.refuses(tick, now);
        if *robot != self.cfg.robot && self.live.contains(robot) {
            let clock = self.peer_clocks.entry(robot.clone()).or_default();
            match refused {
                None => clock.heard(tick, now),
                Some(_) => clock.heard_off_window(tick, now),
            }
        }
        match refused {
            Some(off) => {
                self.metrics.count_off_clock(off.message());
                if self.may_warn_off_clock(now) {
                    let by = crate::clock::signed_ms(tick_start(tick), now);
                    tracing::warn!(%robot, tick, "refused a message for a tick starting {by} ms from our clock's now (spwi_off_clock_total counts them; /status clocks shows the peer)");
                }
                false
            }
            None => true,
        }
    }

    /// At most one log line about ticks off our clock every 5 s.
    fn may_warn_off_clock(&mut self, now: Duration) -> bool {
        if self.warned_off_clock.is_some_and(|at| now.saturating_sub(at) < Duration::from_secs(5)) {
            return false;
        }
        self.warned_off_clock = Some(now);
        true
    }

    /// Whether `instance` is the one `robot`, a live member, runs as far as we heard.
    pub(super) fn is_live_instance(&self, robot: &RobotId, instance: u64) -> bool {
        self.live.contains(robot) && self.instances.get(robot).is_none_or(|&i| i == instance)
    }

    pub(super) fn warn_off_clock(&mut self, f: &DetectionFrame, now: Duration) {
        if !self.may_warn_off_clock(now) {
            return;
        }
        if f.capture_us == 0 {
            tracing::warn!("refused a frame without a capture time: its source must stamp capture_us (µs since the Unix epoch, on a synchronised clock)");
        } else {
            let by = crate::clock::signed_ms(Duration::from_micros(f.capture_us), now);
            tracing::warn!(
                tick = f.tick(),
                "refused a frame captured {} ms {} our clock (the window takes {} ticks back, {} ahead): is the source's clock synchronised?",
                by.unsigned_abs(),
                if by < 0 { "behind" } else { "ahead of" },
                self.cfg.window.past,
                self.cfg.window.ahead
            );
        }
    }

    /// Forgets what lies behind the window: ticks still open there are decided with
    /// what they hold (their deadline has passed), decided ones are forgotten.
    pub(super) fn forget_the_past(&mut self, now: Duration, out: &mut Vec<Output>) {
        let oldest = self.cfg.window.oldest(now);
        while let Some(&t) = self.open.keys().next().filter(|&&t| t < oldest) {
            self.decide(t, DecidedBy::Deadline, now, out);
        }
        if self.decided.keys().next().is_some_and(|&t| t < oldest) {
            self.decided = self.decided.split_off(&oldest);
        }
    }

    /// Tick `t`, opened if it was not: its deadline runs from now, or from its start on
    /// our clock if that is later.
    pub(super) fn open_tick(&mut self, tick: u64, now: Duration) -> &mut Tick {
        if !self.open.contains_key(&tick) && self.open.len() >= self.cfg.max_open_ticks {
            if let Some((old, _)) = self.open.pop_first() {
                self.metrics.evicted_ticks += 1;
                tracing::warn!(tick = old, "dropping an undecided tick: too many open");
            }
        }
        self.open.entry(tick).or_insert_with(|| Tick::new(now.max(tick_start(tick))))
    }
}
