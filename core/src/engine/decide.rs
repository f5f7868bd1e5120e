//! Deciding a tick: once our frame is in and every active member voted or abstained,
//! or when the deadline passes, the ballots held become the team's decision, and each
//! voter is judged against the others ([`crate::trust`]).
//!
//! Membership decides whom to wait for: live members (liveliness) that have spoken at
//! least once, so a peer that joins never stalls a tick, and one that leaves is not
//! waited for. Each ballot weighs the trust its receiver learned of its voter, never
//! what the voter says of itself.
//!
//! Trust is learned from each tick's ballots, but not at once: a tick's lesson is every
//! vote held for it [`LESSON_LAG`] ticks later, the ones that came after the decision
//! (relayed, answered) included, and every robot learns it as it decides the tick that
//! many ticks on, weighing its ballots by the trust it holds then. A robot that decided
//! a tick without a vote lost on its link still learns from it once the vote comes in,
//! so robots whose ballots differed for a moment learn alike, and robots that learned
//! alike weigh the next ballots alike: agreement does not drift apart tick after tick.
//! Nothing in a lesson is any peer's word about the others. Each lesson also waits,
//! with the ones before it, for the worker to stay at a station ([`crate::hindsight`]):
//! then each of their votes is judged by it. The decision names a
//! digest of the ballots counted; each robot's next share carries it in brief
//! ([`Verdict`]), so comparing verdicts measures how often the team agrees without any
//! robot hearing every peer's decisions.

use super::rounds::{ballots, ANSWERED_TICKS};
use super::{Engine, Output, Tick};
use crate::consensus::{self, Ballot};
use crate::metrics::{Metrics, Stage};
use crate::sight;
use spwi_proto::*;
use std::collections::BTreeMap;
use std::time::{Duration, Instant};

/// How many ticks after a tick its votes are learned from (see the module doc): the
/// relays, asks and answers of a tick are over well before then.
pub const LESSON_LAG: u64 = 2;

/// The votes held for a decided tick, by voter: a lesson waiting to be learned (late
/// votes join it), or one learned and kept for newcomers ([`super::history`]).
pub(super) type VotesHeld = BTreeMap<RobotId, VoteMsg>;

impl Engine {
    pub(super) fn advance_all(&mut self, now: Duration, out: &mut Vec<Output>) {
        let ticks: Vec<u64> = self.open.keys().copied().collect();
        for t in ticks {
            self.advance(t, now, out);
        }
    }

    /// Moves tick `t` on as far as its messages and `now` allow.
    pub(super) fn advance(&mut self, t: u64, now: Duration, out: &mut Vec<Output>) {
        let Some(tick) = self.open.get(&t) else { return };
        let decision_due = now >= tick.started + self.cfg.decision_deadline;

        // Relay, then ask: partway through the tick, the ballots we hold go to every peer.
        self.run_rounds(t, now, out);

        // The decision, once our frame is in and every active member voted or abstained.
        let tick = &self.open[&t];
        let all_voted = tick.own_frame.is_some() && !self.waits_for_a_vote(tick);
        if all_voted {
            self.decide(t, DecidedBy::AllVoted, now, out);
        } else if decision_due {
            self.decide(t, DecidedBy::Deadline, now, out);
        }
    }

    /// Some active member has neither voted nor abstained in `tick` (as far as we heard).
    pub(super) fn waits_for_a_vote(&self, tick: &Tick) -> bool {
        self.live.intersection(&self.active).any(|r| !tick.abstaining.contains(r) && !tick.votes.contains_key(r))
    }

    pub(super) fn decide(&mut self, t: u64, by: DecidedBy, now: Duration, out: &mut Vec<Output>) {
        // Deciding before the relay time: if we relay the tick, the ballots we hold go
        // out now, since a peer that lost one of them may still be waiting.
        if self.owes_relay(t) {
            out.push(ballots(&self.cfg, t, &self.open[&t].votes));
        }
        let mut tick = self.open.remove(&t).expect("open");
        let t0 = Instant::now();
        self.learn_lessons_before(t);
        // Each ballot weighs what we learned of its voter, and the view the tick's
        // estimates bear out ([`sight`]). Voters we doubt are set
        // aside while one we trust votes, and never decide a tick for the team while
        // a trusted member (we at least) is live: the tick then goes without a class.
        let votes: Vec<&VoteMsg> = tick.votes.values().collect();
        let all = sight::ballots(&votes, |r| self.trust.weight(r));
        let trusted = |b: &&Ballot<'_>| self.trust.counts(b.robot);
        let members = || std::iter::once(&self.cfg.robot).chain(self.live.iter());
        let anyone_trusted = all.iter().any(|b| trusted(&b)) || members().any(|r| self.trust.counts(r));
        let mut counted: Vec<Ballot<'_>> = all.iter().filter(|b| !anyone_trusted || trusted(b)).copied().collect();
        self.metrics.doubted_only_ticks += u64::from(counted.is_empty() && !all.is_empty());
        // Nor does a voter not yet established decide a tick alone while another
        // member we trust is live: the tick goes without a class until the team has
        // judged it.
        if let [alone] = counted[..] {
            let others_trusted = members().any(|m| m != alone.robot && self.trust.counts(m));
            if others_trusted && !self.trust.established(alone.robot) {
                counted.clear();
                self.metrics.lone_stranger_ticks += 1;
            }
        }
        let steps = consensus::decide(&mut counted, self.cfg.consensus);
        let digest = consensus::digest(&counted);
        let voters: Vec<RobotId> = counted.iter().map(|b| b.robot.clone()).collect();
        self.metrics.votes_set_aside += (all.len() - counted.len()) as u64;
        self.lessons.insert(t, tick.votes.clone());
        self.first_decided.get_or_insert(t);
        self.metrics.observe(Stage::Consensus, t0.elapsed());
        if let Some(arrived) = tick.own_frame {
            self.metrics.observe(Stage::FrameToDecision, now.saturating_sub(arrived));
        }
        let d = DecisionMsg {
            robot: self.cfg.robot.clone(),
            instance: self.cfg.instance,
            tick: t,
            steps: steps.clone(),
            voters,
            live_members: self.live.len() as u32 + 1,
            decided_by: by,
            digest,
        };
        let ours = Verdict::of(&d);
        let withheld = self.catching_up(now);
        let peer_verdicts = std::mem::take(&mut tick.peer_verdicts);
        self.settled.insert(t, tick);
        while self.settled.len() > ANSWERED_TICKS {
            self.settled.pop_first();
        }
        // While we catch up with the team's history, the tick is closed (its lesson
        // learned later, late messages for it refused) but not published, nor compared.
        if withheld {
            self.metrics.decisions_withheld += 1;
            self.withheld_through = Some(t);
            self.decided.insert(t, ours);
            return;
        }
        for theirs in peer_verdicts.values() {
            record_agreement(&mut self.metrics, &ours, theirs);
        }
        self.metrics.decisions += 1;
        if by == DecidedBy::Deadline {
            self.metrics.decisions_by_deadline += 1;
        }
        self.unshared_verdict = Some(ours.clone());
        self.decided.insert(t, ours);
        self.last_decision = Some(d.clone());
        out.push(Output::Decision(d));
    }

    /// Learns, in tick order, every lesson [`LESSON_LAG`] or more ticks before tick `t`:
    /// each voter judged against the others ([`crate::trust`]), its ballot weighing the
    /// trust held now, the same on every robot that learned the same lessons.
    fn learn_lessons_before(&mut self, t: u64) {
        while let Some(entry) = self.lessons.first_entry().filter(|e| e.key() + LESSON_LAG <= t) {
            let (tick, votes) = entry.remove_entry();
            self.learn(&votes);
            self.keep_learned(tick, votes);
        }
    }

    /// Learns one tick's votes: each voter judged against the others, its estimate
    /// against theirs, and its vote, later, by where the worker stays.
    pub(super) fn learn(&mut self, votes: &VotesHeld) {
        // A map by robot: the ballots are in robot order, as learning wants them.
        let ballots: Vec<Ballot<'_>> = votes.values().map(|v| Ballot::of(v, self.trust.weight(&v.robot))).collect();
        self.trust.learn(&ballots);
        let estimates: Vec<(&RobotId, &WorkerEstimate)> =
            votes.values().filter_map(|v| Some((&v.robot, v.worker.as_ref()?))).collect();
        self.trust.learn_tracks(&estimates);
        // Where the voters we believe put the worker, for hindsight.
        let worker: Vec<&WorkerEstimate> =
            estimates.iter().filter(|(r, _)| self.trust.fuses(r)).map(|(_, e)| *e).collect();
        let named = votes.values().filter_map(|v| Some((v.robot.clone(), v.steps.first()?.class))).collect();
        let judged = self.hindsight.learn(named, &worker, &self.floor.team_map.stations());
        self.trust.learn_hindsight(&judged);
    }

    /// A vote for a tick we decided already: it joins the tick's lesson if it has none
    /// from its voter yet.
    pub(super) fn late_vote(&mut self, v: VoteMsg) {
        if let Some(lesson) = self.lessons.get_mut(&v.tick) {
            lesson.entry(v.robot.clone()).or_insert(v);
        }
    }

    /// A peer's verdict against ours for its tick, now or when we decide it.
    pub(super) fn compare(&mut self, peer: &RobotId, theirs: Verdict) {
        if self.withheld_through.is_some_and(|w| theirs.tick <= w) {
            return; // we published no decision of it
        }
        if let Some(ours) = self.decided.get(&theirs.tick) {
            record_agreement(&mut self.metrics, ours, &theirs);
        } else if let Some(tick) = self.open.get_mut(&theirs.tick) {
            tick.peer_verdicts.insert(peer.clone(), theirs);
        }
    }
}

/// Counts one comparison of our verdict of a tick with a peer's.
fn record_agreement(m: &mut Metrics, ours: &Verdict, theirs: &Verdict) {
    m.agreement_compared += 1;
    m.agreement_same += u64::from(ours.class == theirs.class);
    if ours.digest != theirs.digest {
        m.ballot_sets_differ += 1;
        let theirs_has_ours = ours.voters.iter().all(|v| theirs.voters.binary_search(v).is_ok());
        if theirs_has_ours && theirs.voters.len() > ours.voters.len() {
            m.decided_on_fewer_ballots += 1;
        }
    }
}
