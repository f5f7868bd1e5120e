//! Who has been right lately: each robot's trust, learned from what it shared.
//!
//! Two records per robot, each a moving average over about `window` judgements, both
//! learned from the ballots of each decided tick and nothing else:
//! - **votes**: every voter is judged, step by step, against the *other* voters of
//!   the tick: where most of their trust (more than half) names one class and that
//!   trust outweighs the voter's own, its vote agrees or not; where their trust is
//!   split, or less than its own, the step tells nothing and is not judged. Trust,
//!   not confidence, weighs the others here: a voter sure of itself cannot make the
//!   honest look wrong — two honest voters and one confident liar judge the liar wrong
//!   (both others name another class) and neither honest voter (its others are
//!   split), so only the liar loses trust;
//! - **track**: when at least three ballots place the worker on the floor, each
//!   estimate is judged against the others (`floor::agrees_with_most`): 1 when it
//!   puts the worker where most of them do, else 0. A camera replaying old frames
//!   votes much like its peers — they all read the same team track — but places the
//!   worker somewhere else.
//!
//! - **hindsight**: once the worker stays at a station, each vote of its way there is
//!   judged right or wrong by that station ([`crate::hindsight`]), where some voter
//!   named it. This judges a voter even when nobody else voted beside it (a confident
//!   liar beside one honest camera), which the other two records cannot. It counts
//!   only against a voter right less often than [`RIGHT_ENOUGH`] (by its moving
//!   average): an honest camera's mistakes are no reason to weigh it less.
//!
//! Trust is the product of the three, never below `floor`, so a robot that was wrong for
//! a while still counts a little and, being judged all the while, earns its trust back
//! once its camera recovers. A judgement that lowers a record moves it twice as far as
//! one that raises it: trust is lost faster than it is earned. A robot starts at
//! [`UNJUDGED`], counted but outweighed by any robot the team has seen agree, and a
//! record outlives a robot's leaving: one that comes back is still known.
//!
//! What a ballot weighs is the trust its *receiver* learned of the voter
//! ([`TrustBook::weight`]), never anything the voter says of itself. The team's
//! agreement needs every robot to weigh a ballot alike: since trust is learned from the
//! ballots decided on alone, robots that counted the same ballots hold the same trust,
//! and the weight is rounded to [`WEIGHT_STEPS`] levels so that a rare tick counted
//! differently (a vote lost on a link) seldom moves it. Voters trusted below
//! `count_above` are not counted while a trusted voter is ([`TrustBook::counts`]): a
//! confident liar stops deciding once the others have seen it disagree for a few
//! seconds. The same trust decides whose embeddings and worker estimates a robot fuses;
//! `/status` shows it.

use crate::consensus::Ballot;
use crate::floor::agrees_with_most;
use crate::vote::argmax;
use spwi_proto::{RobotId, WorkerEstimate, NUM_CLASSES};
use std::collections::BTreeMap;

/// How trust is learned (from `[tick]`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TrustConfig {
    /// Decided ticks over which agreement is averaged.
    pub window: u32,
    /// Least trust a voter keeps.
    pub floor: f32,
    /// Peers trusted less than this leave our embedding and worker-track fusion.
    pub fuse_above: f32,
    /// Voters trusted less than this are not counted while a voter trusted more is.
    #[serde(default)]
    pub count_above: f32,
}

impl Default for TrustConfig {
    fn default() -> Self {
        TrustConfig { window: 100, floor: 0.1, fuse_above: 0.5, count_above: 0.5 }
    }
}

/// Levels a ballot's weight is rounded to (in (0, 1]).
pub const WEIGHT_STEPS: f32 = 16.0;

/// What a voter's record of votes starts at, before anyone has judged it: enough to
/// be counted, half of what a voter that keeps agreeing earns. A member that has just
/// joined — or just begun to lie — has no say over one the team has seen agree, and
/// its first judged disagreement sets it aside.
pub const UNJUDGED: f32 = 0.5;

/// Down to this record of being right in hindsight (a moving average in which a wrong
/// vote weighs twice a right one, so about two right in three), a voter keeps its full
/// weight; below, its weight falls in proportion. A voter that names one station
/// whatever the worker does is right about one time in four.
pub const RIGHT_ENOUGH: f32 = 0.5;

/// Moving averages of one robot's agreement with the others, and with hindsight.
#[derive(Debug, Clone, Copy)]
struct Record {
    votes: f32,
    track: f32,
    hindsight: f32,
    /// Votes judged in hindsight so far.
    hindsight_judged: u32,
}

impl Default for Record {
    fn default() -> Self {
        Record { votes: UNJUDGED, track: 1.0, hindsight: 1.0, hindsight_judged: 0 }
    }
}

/// Votes judged in hindsight, right often enough, before a voter counts as established
/// by hindsight alone (a second of votes).
pub const PROVEN_IN_HINDSIGHT: u32 = 10;

#[derive(Debug, Clone)]
pub struct TrustBook {
    cfg: TrustConfig,
    /// Per robot (absent: never judged).
    records: BTreeMap<RobotId, Record>,
}

impl TrustBook {
    pub fn new(cfg: TrustConfig) -> Self {
        TrustBook { cfg, records: BTreeMap::new() }
    }

    /// The trust of `robot`: [`UNJUDGED`] until it has been judged.
    pub fn of(&self, robot: &RobotId) -> f32 {
        let r = self.records.get(robot).copied().unwrap_or_default();
        let hindsight = (r.hindsight / RIGHT_ENOUGH).min(1.0);
        (r.votes * r.track * hindsight).max(self.cfg.floor)
    }

    /// A peer we fuse the embeddings and worker estimates of.
    pub fn fuses(&self, robot: &RobotId) -> bool {
        self.of(robot) >= self.cfg.fuse_above
    }

    /// What a ballot of `robot` weighs: its trust rounded to one of [`WEIGHT_STEPS`]
    /// levels (never zero).
    pub fn weight(&self, robot: &RobotId) -> f32 {
        ((self.of(robot) * WEIGHT_STEPS).round() / WEIGHT_STEPS).max(1.0 / WEIGHT_STEPS)
    }

    /// A voter the team has seen agree more than disagree — trusted above
    /// [`UNJUDGED`] (by its rounded weight) — or seen right in hindsight
    /// ([`PROVEN_IN_HINDSIGHT`] votes judged, right often enough). Only such a voter
    /// decides a tick alone while another trusted member is live: a newcomer — or a
    /// member that turned liar before anyone judged it — has no such say.
    pub fn established(&self, robot: &RobotId) -> bool {
        let r = self.records.get(robot).copied().unwrap_or_default();
        let proven = r.hindsight_judged >= PROVEN_IN_HINDSIGHT && r.hindsight >= RIGHT_ENOUGH && self.counts(robot);
        self.weight(robot) > UNJUDGED || proven
    }

    /// A voter whose ballot is counted while a trusted voter's is: its rounded
    /// [`TrustBook::weight`] is at least `count_above`, so that robots whose records
    /// differ by a hair (a tick counted differently) still count the same voters.
    pub fn counts(&self, robot: &RobotId) -> bool {
        self.weight(robot) >= self.cfg.count_above
    }

    /// Every robot that voted or was judged so far, and its trust.
    pub fn all(&self) -> BTreeMap<RobotId, f32> {
        self.records.keys().map(|r| (r.clone(), self.of(r))).collect()
    }

    /// Moves a record towards the judgement `x`: by 1/window of the way when it
    /// raises it, twice that when it lowers it — trust is lost faster than it is
    /// earned, so a member that turns on the team loses its weight within seconds
    /// while a robot that keeps agreeing stays near 1.
    fn judged(window: u32, record: &mut f32, x: f32) {
        let rate = 1.0 / window.max(1) as f32;
        let rate = if x < *record { (2.0 * rate).min(1.0) } else { rate };
        *record += rate * (x - *record);
    }

    /// The record of `robot`, started on first use (no id copied once it exists).
    fn record(&mut self, robot: &RobotId) -> &mut Record {
        if !self.records.contains_key(robot) {
            self.records.insert(robot.clone(), Record::default());
        }
        self.records.get_mut(robot).expect("just inserted")
    }

    /// Judges one robot's estimate of the worker for a tick: `agrees` when it put the
    /// worker where most of the others did.
    pub fn learn_track(&mut self, robot: &RobotId, agrees: bool) {
        let window = self.cfg.window;
        Self::judged(window, &mut self.record(robot).track, f32::from(u8::from(agrees)));
    }

    /// Sets the record of `robot`'s votes, as if judged so (tests that need a robot
    /// the team has seen agree).
    #[cfg(test)]
    pub(crate) fn set_votes_record(&mut self, robot: &RobotId, votes: f32) {
        self.record(robot).votes = votes;
    }

    /// Takes what hindsight judged ([`crate::hindsight::Hindsight::learn`]): whether
    /// each vote named the station the worker then stayed at.
    pub fn learn_hindsight(&mut self, judged: &[(RobotId, bool)]) {
        let window = self.cfg.window;
        for (robot, right) in judged {
            let record = self.record(robot);
            Self::judged(window, &mut record.hindsight, f32::from(u8::from(*right)));
            record.hindsight_judged = record.hindsight_judged.saturating_add(1);
        }
    }

    /// Judges the worker estimates of a decided tick's ballots against each other, when
    /// at least three place the worker.
    pub fn learn_tracks(&mut self, estimates: &[(&RobotId, &WorkerEstimate)]) {
        let places: Vec<&WorkerEstimate> = estimates.iter().map(|(_, e)| *e).collect();
        if let Some(agrees) = agrees_with_most(&places) {
            for ((robot, _), ok) in estimates.iter().zip(agrees) {
                self.learn_track(robot, ok);
            }
        }
    }

    /// Judges every voter of a decided tick against the others (counted or set aside
    /// alike, each weighing its `trust`). `ballots` sorted by robot, as
    /// [`crate::consensus::decide`] leaves them.
    pub fn learn(&mut self, ballots: &[Ballot<'_>]) {
        let window = self.cfg.window;
        for (b, (agreed, judged)) in ballots.iter().zip(judge(ballots)) {
            let record = self.record(b.robot); // every voter is known from its first ballot
            if judged > 0 {
                Self::judged(window, &mut record.votes, agreed as f32 / judged as f32);
            }
        }
    }
}

/// Per ballot: (its steps whose class most of the others' trust names, its steps on
/// which most of the others' trust names one class *and* that trust outweighs the
/// judged voter's own). So two voters that disagree judge each other only when one has
/// earned more trust than the other: a newcomer (or a member that turned liar) is
/// judged by a robot the team has seen agree, never the other way round, and two
/// strangers judge neither. Sums run in ballot order, so the result is the same on
/// every robot.
pub fn judge(ballots: &[Ballot<'_>]) -> Vec<(usize, usize)> {
    ballots
        .iter()
        .enumerate()
        .map(|(i, b)| {
            let mut tally = (0, 0);
            for (h, s) in b.steps.iter().enumerate() {
                let mut score = [0.0f32; NUM_CLASSES];
                let others = ballots.iter().enumerate().filter(|&(j, o)| j != i && h < o.steps.len());
                for (_, o) in others {
                    score[o.steps[h].class.index()] += o.trust.max(0.0);
                }
                let total: f32 = score.iter().sum();
                let k = argmax(&score);
                if score[k] > 0.5 * total && score[k] > b.trust.max(0.0) {
                    tally.1 += 1;
                    tally.0 += usize::from(s.class.index() == k);
                }
            }
            tally
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use spwi_proto::Station::{self, *};
    use spwi_proto::StepVote;

    fn id(s: &str) -> RobotId {
        RobotId::new(s).unwrap()
    }

    /// `class_of[i]` is what robot i votes, every step at confidence .8.
    fn tick(book: &mut TrustBook, ids: &[RobotId], class_of: &[Station]) {
        let steps: Vec<Vec<StepVote>> =
            class_of.iter().map(|&c| vec![StepVote { class: c, confidence: 0.8 }; 3]).collect();
        let ballots: Vec<Ballot<'_>> = ids
            .iter()
            .zip(&steps)
            .map(|(r, s)| Ballot { robot: r, visibility: 1, trust: book.weight(r), quality: 1.0, steps: s })
            .collect();
        book.learn(&ballots);
    }

    #[test]
    fn a_voter_that_keeps_disagreeing_loses_trust_down_to_the_floor_and_earns_it_back() {
        let cfg = TrustConfig { window: 10, floor: 0.1, fuse_above: 0.5, count_above: 0.5 };
        let mut book = TrustBook::new(cfg);
        let ids = [id("a"), id("b"), id("c")];
        assert_eq!(book.of(&ids[2]), UNJUDGED, "half trusted until judged");
        assert!(book.counts(&ids[2]) && book.fuses(&ids[2]));
        tick(&mut book, &ids, &[Workstation, Workstation, Manufacturing]);
        // judged by a and b together (their trust outweighs its own): lowered by 2/10
        assert!((book.of(&ids[2]) - 0.4).abs() < 1e-6, "{}", book.of(&ids[2]));
        assert!(!book.fuses(&ids[2]) && !book.counts(&ids[2]), "0.4, weighing 6/16: set aside");
        for _ in 0..60 {
            tick(&mut book, &ids, &[Workstation, Workstation, Manufacturing]);
        }
        assert_eq!(book.of(&ids[2]), 0.1, "floored");
        // a and b are never judged: for each, the other alone does not outweigh it
        assert_eq!((book.of(&ids[0]), book.of(&ids[1])), (UNJUDGED, UNJUDGED));
        for _ in 0..30 {
            tick(&mut book, &ids, &[Workstation, Workstation, Workstation]);
        }
        assert!(book.of(&ids[2]) > 0.9, "recovered: {}", book.of(&ids[2]));
        assert!(book.of(&ids[0]) > 0.9, "now judged agreeing: {}", book.of(&ids[0]));
        assert_eq!(book.all().len(), 3);
    }

    #[test]
    fn a_lone_voter_or_a_pair_is_not_judged_and_agreement_counts_step_by_step() {
        let mut book = TrustBook::new(TrustConfig { window: 1, ..TrustConfig::default() });
        let ids = [id("a"), id("b"), id("c")];
        tick(&mut book, &ids[..1], &[Assembly]);
        tick(&mut book, &ids[..2], &[Assembly, Manufacturing]);
        assert!(book.all().values().all(|&t| t == UNJUDGED), "of two that disagree, neither can tell who is wrong");
        assert_eq!(book.all().len(), 2, "both are known as voters");
        // a says 2 at every step, b and c 2, 3, 3
        let (sa, sb) = (vec![StepVote { class: Assembly, confidence: 0.8 }; 3], {
            let mut s = vec![StepVote { class: Manufacturing, confidence: 0.8 }; 3];
            s[0].class = Assembly;
            s
        });
        let ballots = [
            Ballot { robot: &ids[0], visibility: 1, trust: 1.0, quality: 1.0, steps: &sa },
            Ballot { robot: &ids[1], visibility: 1, trust: 1.0, quality: 1.0, steps: &sb },
            Ballot { robot: &ids[2], visibility: 1, trust: 1.0, quality: 1.0, steps: &sb },
        ];
        book.learn(&ballots);
        // a: agrees at t, not at t+1 and t+2; b: agrees at t, split (a against c) after
        assert!((book.of(&ids[0]) - 1.0 / 3.0).abs() < 1e-6);
        assert_eq!(book.of(&ids[1]), 1.0);
    }

    #[test]
    fn a_sure_liar_cannot_make_the_honest_look_wrong() {
        // b and c vote workstation at .6, d manufacturing at 1.0: a confidence-weighted
        // judge would find b and c each outvoted by d (and so all three losing trust
        // alike); the others' trust finds only d wrong.
        let mut book = TrustBook::new(TrustConfig::default());
        let ids = [id("b"), id("c"), id("d")];
        let (honest, sure) = (
            vec![StepVote { class: Workstation, confidence: 0.6 }; 3],
            vec![StepVote { class: Manufacturing, confidence: 1.0 }; 3],
        );
        for _ in 0..100 {
            let ballots: Vec<Ballot<'_>> = ids
                .iter()
                .zip([&honest, &honest, &sure])
                .map(|(r, s)| Ballot { robot: r, visibility: 1, trust: book.weight(r), quality: 1.0, steps: s })
                .collect();
            book.learn(&ballots);
        }
        // b and c judge d (together they outweigh it); neither is judged (of its
        // others, one agrees and one, d, disagrees: split) — they keep what they had
        assert_eq!((book.of(&ids[0]), book.of(&ids[1])), (UNJUDGED, UNJUDGED));
        assert_eq!(book.of(&ids[2]), 0.1, "0.5 × 0.98^100 = 0.07, floored");
        assert!(!book.counts(&ids[2]) && book.counts(&ids[0]));
        assert_eq!(book.weight(&ids[2]), 0.125, "0.1 rounded to sixteenths");
    }

    #[test]
    fn a_voter_wrong_in_hindsight_loses_weight_only_once_it_is_right_less_than_enough() {
        let mut book = TrustBook::new(TrustConfig { window: 10, ..TrustConfig::default() });
        let (honest, liar) = (id("honest"), id("liar"));
        // One wrong in four: its record stays above 0.5, full weight.
        for _ in 0..30 {
            let (right, wrong) = ((honest.clone(), true), (honest.clone(), false));
            book.learn_hindsight(&[right.clone(), right.clone(), right, wrong]);
            book.learn_hindsight(&[(liar.clone(), false)]);
        }
        assert_eq!(book.of(&honest), UNJUDGED, "votes unjudged, hindsight at full weight");
        assert!(book.counts(&honest));
        assert_eq!(book.of(&liar), 0.1, "always wrong: floored");
        assert!(!book.counts(&liar));
    }

    #[test]
    fn trust_is_the_product_of_the_vote_and_track_records() {
        let mut book = TrustBook::new(TrustConfig { window: 4, floor: 0.1, fuse_above: 0.5, count_above: 0.5 });
        let ids = [id("a"), id("b"), id("c")];
        book.learn_track(&ids[0], false); // lowered by 2/4: 1 → 0.5; votes unjudged, 0.5
        assert_eq!(book.of(&ids[0]), 0.25);
        tick(&mut book, &ids, &[Manufacturing, Workstation, Workstation]); // a's votes: 0.5 → 0.25
        assert_eq!(book.of(&ids[0]), 0.125);
        book.learn_track(&ids[0], true); // raised by 1/4: 0.5 → 0.625
        assert_eq!(book.of(&ids[0]), 0.15625);
        book.learn_track(&ids[1], true);
        assert_eq!(book.of(&ids[1]), UNJUDGED, "its track 1, its votes not judged yet");
        for _ in 0..10 {
            book.learn_track(&ids[2], false);
        }
        assert_eq!(book.of(&ids[2]), 0.1, "floored");
    }
}
