//! A newcomer learns whom the team trusts from its peers' recent lessons.
//!
//! Trust is learned from the votes of decided ticks ([`crate::trust`], `decide.rs`). A
//! robot that joins, or restarts, has learned nothing: it trusts every member alike,
//! and the rule that a voter not yet established never decides a tick alone while a
//! trusted member is live then sets aside the very voters its peers count. Measured on
//! the container fleet, the three fresh robots of six decided "no class" where the
//! other three decided a station on 7 % of the ticks after they joined. So a robot
//! that has just started asks its peers for the team's history (a [`HistoryMsg`] of
//! one lesson without votes, whose tick is the first it decided: "what came before
//! this?"), and a few of them ([`EngineConfig::relayers`], ranked by a hash of the
//! asker's id, the same few on every robot) send the lessons they learned over the
//! [`MAX_HISTORY_TICKS`] ticks before it. The newcomer learns them, in tick order and
//! before its own, from a fresh book: it judges the same signed votes its peers judged.
//!
//! The newcomer asks, rather than its peers sending whenever a member appears: on a
//! lossy network members drop out and come back every few seconds, and a history of
//! up to 256 kB pushed to each of them every time would fill the links the votes need.
//! A robot asks only in its first seconds, at most [`HISTORY_ASKS`] times a second
//! apart, until a history comes; a peer answers one asker at most once a second. An
//! ask often arrives before its asker's liveliness token: the peer keeps it (a few, for
//! [`ASK_KEPT`]) and answers when the asker becomes a member. Only a peer that was
//! deciding before the asked tick answers: with its lessons, or with an empty history
//! if it learned none ("nothing came before"). Robots that started together (within
//! the window of each other) answer each other nothing.
//!
//! Until its history comes, the newcomer would decide with a book that trusts every
//! member alike, and name no station where its peers name one: measured again on the
//! container fleet, the fresh robots of six decided 5 of their first 50 ticks so. So a
//! robot that joins a team at work — a member's share names a decision of a tick before
//! the oldest the robot could take when it came — withholds its decisions while it
//! catches up (it still votes, shares, relays and learns): from its first ask until a
//! history taught it, or every member that tells it answered, or
//! [`EngineConfig::catch_up`] passed, whichever comes first, so that no peer can keep it
//! silent by not answering. Robots that start together withhold nothing.
//!
//! What a history can cost and do: it is taken only from a live member, only for ticks
//! within [`MAX_HISTORY_TICKS`] of now and before the first tick the receiver decided
//! itself, so a robot that has run longer takes none and nothing it decided is learned
//! twice. It never speaks for its sender: the sender's own votes are dropped, so no
//! member can make itself trusted by rewriting its past; in a secured fleet the daemon
//! also drops every vote whose origin's signature does not verify. What a sender can do
//! is leave votes out; the votes of several senders' histories are joined.
//!
//! [`EngineConfig::relayers`]: super::EngineConfig::relayers
//! [`EngineConfig::catch_up`]: super::EngineConfig::catch_up

use super::decide::VotesHeld;
use super::rounds::relay_rank;
use super::{Engine, Output};
use crate::hash::Fnv1a;
use crate::hindsight::Hindsight;
use crate::trust::TrustBook;
use spwi_proto::*;
use std::collections::{BTreeMap, BTreeSet};
use std::time::Duration;

/// How many times a new robot asks for the team's history.
pub const HISTORY_ASKS: u32 = 3;
/// For how many ticks after its first decision a robot still asks.
pub const ASKING_TICKS: u64 = 30;
/// How long a robot waits before asking again, or before answering one asker again.
const RESEND: Duration = Duration::from_secs(1);
/// How long an ask from a robot not (yet) a member is kept, to answer it when it
/// becomes one.
pub const ASK_KEPT: Duration = Duration::from_secs(2);
/// Most asks kept from robots not yet members.
const MAX_ASKS_KEPT: usize = 16;

/// Where a robot stands with histories: asked for its own, answered others'.
#[derive(Debug, Default)]
pub(super) struct HistoryState {
    asks: u32,
    /// When we first asked: our catching up runs from then.
    first_ask: Option<Duration>,
    last_ask: Option<Duration>,
    /// A live member's history taught us something: no more asking.
    taught: bool,
    /// Members that answered our asks (with lessons or none).
    answered_us: BTreeSet<RobotId>,
    /// The oldest tick we could take at our first input: robots whose first decisions
    /// come after it came with us.
    came: Option<u64>,
    /// A live member told us of a decision of a tick before we came: we joined a team
    /// at work, which has a history to learn.
    team_at_work: bool,
    /// When we last answered each asker (the last second's only).
    answered: BTreeMap<RobotId, Duration>,
    /// Asks of robots that were no members yet: the tick asked for, and when it came.
    kept_asks: BTreeMap<RobotId, (u64, Duration)>,
}

impl Engine {
    /// Keeps a lesson just learned for newcomers: the latest [`MAX_HISTORY_TICKS`] ticks.
    pub(super) fn keep_learned(&mut self, tick: u64, votes: VotesHeld) {
        if !votes.is_empty() {
            self.learned.insert(tick, votes);
        }
        self.forget_oldest_lessons();
    }

    fn forget_oldest_lessons(&mut self) {
        while self.learned.len() > MAX_HISTORY_TICKS {
            self.learned.pop_first();
        }
    }

    /// Asks for the team's history while we are new (decided nothing yet, or for less
    /// than [`ASKING_TICKS`]), have peers, were taught nothing, asked fewer than
    /// [`HISTORY_ASKS`] times, and not within the last second.
    pub(super) fn ask_for_history(&mut self, now: Duration, out: &mut Vec<Output>) {
        let new = self.first_decided.is_none_or(|t| tick_at(now) < t + ASKING_TICKS);
        let due = self.history.last_ask.is_none_or(|at| now >= at + RESEND);
        if !new || self.history.taught || self.live.is_empty() || self.history.asks >= HISTORY_ASKS || !due {
            return;
        }
        self.history.asks += 1;
        self.history.first_ask.get_or_insert(now);
        self.history.last_ask = Some(now);
        self.metrics.histories_asked += 1;
        let (robot, instance) = (self.cfg.robot.clone(), self.cfg.instance);
        let before = Lesson { tick: self.taught_before(now), votes: Vec::new() };
        out.push(Output::History(HistoryMsg { robot, instance, lessons: vec![before] }));
    }

    /// The ticks a history can teach us lie before this one: the first we decided, or
    /// the oldest we could still decide.
    fn taught_before(&self, now: Duration) -> u64 {
        self.first_decided.unwrap_or_else(|| self.cfg.window.oldest(now))
    }

    /// A member asked for the team's history before tick `before`: if we were deciding
    /// before it, are among the peers that tell it, and did not within the last
    /// second, our lessons of the [`MAX_HISTORY_TICKS`] ticks before it go out (none
    /// when we learned none). A robot that came with the asker has nothing to say.
    fn answer_history(&mut self, asker: &RobotId, before: u64, now: Duration, out: &mut Vec<Output>) {
        let from = before.saturating_sub(MAX_HISTORY_TICKS as u64);
        let at_work_before = self.first_decided.is_some_and(|first| first < before);
        if !at_work_before || !self.tells_history_to(asker) {
            return;
        }
        if self.history.answered.get(asker).is_some_and(|&at| now < at + RESEND) {
            return;
        }
        self.history.answered.retain(|_, at| now < *at + RESEND);
        self.history.answered.insert(asker.clone(), now);
        let mut lessons: Vec<Lesson> = self
            .learned
            .range(from..before)
            .map(|(&tick, votes)| Lesson { tick, votes: votes.values().cloned().collect() })
            .collect();
        let (robot, instance) = (self.cfg.robot.clone(), self.cfg.instance);
        loop {
            let h = HistoryMsg { robot: robot.clone(), instance, lessons };
            // A large fleet's ten seconds may not fit one message: the oldest go first.
            if encode(&h).len() <= MAX_MESSAGE_BYTES || h.lessons.len() <= 1 {
                self.metrics.histories_sent += 1;
                out.push(Output::History(h));
                return;
            }
            lessons = h.lessons;
            lessons.drain(..lessons.len().div_ceil(4));
        }
    }

    /// Whether we rank among the [`super::EngineConfig::relayers`] live members (the
    /// newcomer aside) first by a hash of the newcomer's id and theirs.
    fn tells_history_to(&self, newcomer: &RobotId) -> bool {
        let candidates = self.live.iter().chain(std::iter::once(&self.cfg.robot)).filter(|r| *r != newcomer);
        tellers(newcomer, candidates, self.cfg.relayers).contains(&&self.cfg.robot)
    }

    /// Whether we still withhold our decisions while we learn the team's history: we
    /// asked, no history taught us, some member that tells us has not answered, and
    /// [`super::EngineConfig::catch_up`] has not passed since our first ask.
    pub(super) fn catching_up(&self, now: Duration) -> bool {
        let Some(first) = self.history.first_ask else { return false };
        let h = &self.history;
        if !h.team_at_work || h.taught || now >= first + self.cfg.catch_up || self.live.is_empty() {
            return false;
        }
        let mine = tellers(&self.cfg.robot, self.live.iter(), self.cfg.relayers);
        !mine.iter().all(|r| self.history.answered_us.contains(*r))
    }

    /// Notes when we came: the oldest tick we could take at our first input (the
    /// oldest an ask of ours names, so the members deciding before it are the ones
    /// that answer).
    pub(super) fn note_coming(&mut self, now: Duration) {
        if self.history.came.is_none() {
            self.history.came = Some(self.cfg.window.oldest(now));
        }
    }

    /// A live member decided tick `decided`: if that was before we came, we joined a
    /// team at work, and catch up with it. (Robots that start within the window of
    /// each other decide nothing before each other: none of them withholds a decision.)
    pub(super) fn note_peer_decided(&mut self, decided: u64) {
        if self.history.came.is_some_and(|came| decided < came) {
            self.history.team_at_work = true;
        }
    }

    /// A robot became a member: an ask it sent before is answered now.
    pub(super) fn answer_kept_ask(&mut self, robot: &RobotId, now: Duration, out: &mut Vec<Output>) {
        if let Some((before, at)) = self.history.kept_asks.remove(robot) {
            if now < at + ASK_KEPT {
                self.answer_history(robot, before, now, out);
            }
        }
    }

    /// Keeps the ask of a robot that is no member yet (the newest [`MAX_ASKS_KEPT`]).
    fn keep_ask(&mut self, asker: &RobotId, before: u64, now: Duration) {
        self.history.kept_asks.retain(|_, (_, at)| now < *at + ASK_KEPT);
        if self.history.kept_asks.len() >= MAX_ASKS_KEPT && !self.history.kept_asks.contains_key(asker) {
            return;
        }
        self.history.kept_asks.insert(asker.clone(), (before, now));
    }

    /// A peer's history: one lesson without votes asks for ours; otherwise the votes of
    /// others for ticks we never decided, within reach, join what we learned, and we
    /// learn it all again from a fresh book.
    pub(super) fn on_history(&mut self, h: HistoryMsg, now: Duration, out: &mut Vec<Output>) {
        let ask = match &h.lessons[..] {
            [ask] if ask.votes.is_empty() => Some(ask.tick),
            _ => None,
        };
        if h.robot == self.cfg.robot {
            self.metrics.histories_ignored += 1;
            return;
        }
        if !self.live.contains(&h.robot) {
            match ask {
                Some(before) => self.keep_ask(&h.robot, before, now),
                None => self.metrics.histories_ignored += 1,
            }
            return;
        }
        if let Some(before) = ask {
            self.answer_history(&h.robot, before, now, out);
            return;
        }
        self.history.answered_us.insert(h.robot.clone());
        if h.lessons.is_empty() {
            return; // "nothing came before": robots that started together
        }
        let now_tick = tick_at(now);
        let oldest = now_tick.saturating_sub(MAX_HISTORY_TICKS as u64);
        let before = self.taught_before(now);
        let mut taken = 0;
        for lesson in h.lessons.into_iter().filter(|l| (oldest..before).contains(&l.tick)) {
            let held = self.learned.entry(lesson.tick).or_default();
            for v in lesson.votes.into_iter().filter(|v| v.robot != h.robot) {
                if let std::collections::btree_map::Entry::Vacant(slot) = held.entry(v.robot.clone()) {
                    slot.insert(v);
                    taken += 1;
                }
            }
        }
        self.learned.retain(|_, votes| !votes.is_empty());
        self.forget_oldest_lessons();
        if taken == 0 {
            self.metrics.histories_ignored += 1;
            return;
        }
        self.history.taught = true;
        self.metrics.history_votes_learned += taken;
        self.relearn();
    }

    /// Forgets what we learned and learns every kept lesson again, in tick order.
    fn relearn(&mut self) {
        self.trust = TrustBook::new(self.cfg.trust);
        self.hindsight = Hindsight::default();
        let learned = std::mem::take(&mut self.learned);
        for votes in learned.values() {
            self.learn(votes);
        }
        self.learned = learned;
    }
}

/// The members that tell `newcomer` the team's history: the first `n` of `candidates`
/// by a hash of the newcomer's id and theirs. Every robot ranks them alike, so the
/// newcomer knows whose answers to wait for.
fn tellers<'a>(newcomer: &RobotId, candidates: impl Iterator<Item = &'a RobotId>, n: usize) -> Vec<&'a RobotId> {
    let mut fnv = Fnv1a::default();
    fnv.eat(newcomer.as_str().as_bytes());
    let key = fnv.0;
    let mut ranked: Vec<(u64, &RobotId)> = candidates.map(|r| (relay_rank(key, r), r)).collect();
    ranked.sort();
    ranked.into_iter().take(n).map(|(_, r)| r).collect()
}
