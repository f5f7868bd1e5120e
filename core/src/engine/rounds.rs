//! The rounds of a tick: relaying the ballots held, asking for a missing vote, and
//! answering a peer whose ballots lack one.
//!
//! The decision is a deterministic function of the ballots held, so robots that hold
//! the same ballots decide the same; relaying each robot's ballots partway through the
//! tick is what makes them hold the same ballots when links lose messages. A relay sent
//! once is lost as easily as the vote it carries (docs/BENCHMARKS.md, "Asking for a
//! missing vote", measures how often that left robots counting different ballots). So
//! every Ballots message lists every vote its sender holds, which also says what it
//! lacks; a robot still waiting for a vote sends its ballots again, a few times before
//! the deadline, and a relayer of the tick that holds a vote a peer's ballots lack
//! answers with its own (also after it decided the tick). Each round needs a message
//! there and one back, so a few rounds bring the missing votes in on lossy links, and on
//! links that lose nothing no robot waits past the relay time and nothing more is sent.
//!
//! A vote relayed by a peer counts only if its origin is a live member and the vote is
//! of the origin's live instance (the one we hear from directly); the origin's own copy
//! replaces a relayed one.

use super::{Engine, EngineConfig, Output, Tick};
use crate::hash::Fnv1a;
use spwi_proto::*;
use std::collections::BTreeMap;
use std::time::Duration;

/// Where robot `robot` ranks among tick `tick`'s relayers (lower first): FNV-1a of the
/// two, then a 64-bit finaliser (splitmix64's) so that every bit of the tick moves the
/// order.
pub(super) fn relay_rank(tick: u64, robot: &RobotId) -> u64 {
    let mut fnv = Fnv1a::default();
    fnv.eat(&tick.to_le_bytes());
    fnv.eat(robot.as_str().as_bytes());
    let mut h = fnv.0;
    h = (h ^ (h >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    h = (h ^ (h >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    h ^ (h >> 31)
}

/// Decided ticks whose ballots we keep to answer peers still deciding them (a tick is
/// decided within its deadline, well before the next but one starts).
pub(super) const ANSWERED_TICKS: usize = 2;

impl Engine {
    /// A peer's relayed ballots: the votes we do not hold yet join the tick (never our
    /// own, never a stale peer's); for a tick already decided they are only counted.
    pub(super) fn on_ballots(&mut self, b: BallotsMsg, now: Duration, out: &mut Vec<Output>) {
        if !self.on_our_clock(&b.robot, b.tick, now) {
            return;
        }
        if b.robot == self.cfg.robot {
            // Our own relay (or another daemon's with our id, which this notes).
            self.accept_peer(&b.robot, b.instance, b.tick, now);
            return;
        }
        if let Some(ours) = self.decided.get(&b.tick) {
            let missed = b.votes.iter().filter(|v| v.robot != self.cfg.robot && !ours.voters.contains(&v.robot));
            self.metrics.late_relayed_ballots += missed.count() as u64;
        }
        self.answer(&b, out);
        let me = self.cfg.robot.clone();
        let relayer = b.robot.clone();
        let (usable, foreign): (Vec<VoteMsg>, Vec<VoteMsg>) = b
            .votes
            .into_iter()
            .filter(|v| v.robot != me && !self.peer_is_stale(&v.robot))
            .partition(|v| v.robot == relayer || self.is_live_instance(&v.robot, v.instance));
        self.metrics.foreign_votes += foreign.len() as u64;
        match self.accept_peer(&b.robot, b.instance, b.tick, now) {
            Some(tick) => {
                let mut used = 0;
                for v in usable {
                    if let std::collections::btree_map::Entry::Vacant(slot) = tick.votes.entry(v.robot.clone()) {
                        slot.insert(v);
                        used += 1;
                    }
                }
                self.metrics.relayed_ballots_used += used;
            }
            // Decided already: what we lacked still joins what we learn from the tick.
            None => usable.into_iter().for_each(|v| self.late_vote(v)),
        }
        self.advance(b.tick, now, out);
    }

    /// A peer's ballots list every vote it holds for their tick: if they lack one we
    /// hold (not the peer's own) and we relay the tick, we answer with ours, at most
    /// `ask_rounds` times a tick, also once we decided it.
    fn answer(&mut self, theirs: &BallotsMsg, out: &mut Vec<Output>) {
        let t = theirs.tick;
        if self.cfg.relay_after.is_none() || !self.relays(t) {
            return;
        }
        let Some(tick) = self.open.get_mut(&t).or_else(|| self.settled.get_mut(&t)) else { return };
        let held = |r: &RobotId| *r == theirs.robot || theirs.votes.iter().any(|v| v.robot == *r);
        if tick.answers < self.cfg.ask_rounds && !tick.votes.keys().all(held) {
            tick.answers += 1;
            self.metrics.ballot_answers += 1;
            out.push(ballots(&self.cfg, t, &tick.votes));
        }
    }

    /// When round `k` of tick `t` comes: round 0 at the relay time, then the asks,
    /// spread evenly between it and the deadline (`None`: no relays, or no rounds left).
    pub(super) fn round_time(&self, t: &Tick, k: u32) -> Option<Duration> {
        let after = self.cfg.relay_after.filter(|_| k <= self.cfg.ask_rounds)?;
        Some(t.started + after + self.cfg.decision_deadline.saturating_sub(after) * k / (self.cfg.ask_rounds + 1))
    }

    /// The rounds of tick `t` that came by `now` (one message however many came): at the
    /// first, the relay time, the tick's relayers publish the ballots they hold (nothing
    /// when they hold none); at each later one, a robot still waiting for a member's
    /// vote publishes them, an ask.
    pub(super) fn run_rounds(&mut self, t: u64, now: Duration, out: &mut Vec<Output>) {
        let tick = &self.open[&t];
        let due = (tick.rounds..).take_while(|&k| self.round_time(tick, k).is_some_and(|at| now >= at)).count();
        if due == 0 {
            return;
        }
        let relay = self.owes_relay(t);
        // Not at the relay time itself: the relays of that moment are still on their way.
        let ask = tick.rounds + due as u32 > 1 && self.waits_for_a_vote(tick);
        let tick = self.open.get_mut(&t).expect("open");
        tick.rounds += due as u32;
        if relay || ask {
            if ask && !relay {
                self.metrics.ballot_asks += 1;
            }
            out.push(ballots(&self.cfg, t, &tick.votes));
        }
    }

    /// We relay open tick `t`, hold votes to relay, and its relay time is yet to pass.
    pub(super) fn owes_relay(&self, t: u64) -> bool {
        let tick = &self.open[&t];
        self.cfg.relay_after.is_some() && tick.rounds == 0 && self.relays(t) && !tick.votes.is_empty()
    }

    /// Whether we relay tick `t`'s ballots. Every member holding them relaying them
    /// would send each vote once per member again: n² votes a tick, n − 1 messages to
    /// each robot, most of a large fleet's traffic (docs/BENCHMARKS.md). A vote lost on
    /// one link needs only a few other paths, so `relayers` members relay each tick:
    /// those that rank first by a hash of the tick and their id, a different few each
    /// tick so that no robot carries it alone; every member when the fleet has no
    /// more. The members counted are ours and the peers we wait for; two robots that
    /// count differently for a moment only change how many relay.
    pub(super) fn relays(&self, t: u64) -> bool {
        let mine = (relay_rank(t, &self.cfg.robot), &self.cfg.robot);
        let ahead = self.live.intersection(&self.active).filter(|r| (relay_rank(t, r), *r) < mine).count();
        ahead < self.cfg.relayers
    }
}

/// Our Ballots message for tick `t`: every vote we hold for it.
pub(super) fn ballots(cfg: &EngineConfig, t: u64, held: &BTreeMap<RobotId, VoteMsg>) -> Output {
    let votes = held.values().cloned().collect();
    Output::Ballots(BallotsMsg { robot: cfg.robot.clone(), instance: cfg.instance, tick: t, votes })
}
