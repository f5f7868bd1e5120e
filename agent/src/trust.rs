//! Who has been right lately: each robot's trust, learned from what it shared.
//!
//! Two records per robot, each a moving average over about `window` judgements:
//! - **votes**: after each decision, every voter that was not alone is judged against
//!   the decision the *other* voters reach without it (same rule, same ballots less
//!   its own): the share of its steps that agree;
//! - **track**: each tick at least three robots place the worker on the floor, each
//!   estimate is judged against the others (`floor::agrees_with_most`): 1 when it
//!   puts the worker where most of them do, else 0. A camera replaying old frames
//!   votes much like its peers — they all read the same team track — but places the
//!   worker somewhere else.
//!
//! Trust is the product of the two, never below `floor`, so a robot that was wrong for
//! a while still counts a little and, being judged all the while, earns its trust back
//! once its camera recovers. A robot starts trusted, and a record outlives a robot's
//! leaving: one that comes back is still known.
//!
//! A robot puts its own trust into its vote ([`spwi_proto::VoteMsg::trust`]): every
//! robot then weighs a ballot alike, which the team's agreement needs. The trust this
//! robot learns of its peers decides whose embeddings and worker estimates it fuses;
//! `/status` shows both.

use crate::consensus::{self, Ballot, Rule};
use spwi_proto::RobotId;
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
}

impl Default for TrustConfig {
    fn default() -> Self {
        TrustConfig { window: 100, floor: 0.1, fuse_above: 0.5 }
    }
}

/// Moving averages of one robot's agreement with the others.
#[derive(Debug, Clone, Copy)]
struct Record {
    votes: f32,
    track: f32,
}

impl Default for Record {
    fn default() -> Self {
        Record { votes: 1.0, track: 1.0 }
    }
}

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

    /// The trust of `robot`: 1 until it has been judged.
    pub fn of(&self, robot: &RobotId) -> f32 {
        self.records.get(robot).map_or(1.0, |r| (r.votes * r.track).max(self.cfg.floor))
    }

    /// A peer we fuse the embeddings and worker estimates of.
    pub fn fuses(&self, robot: &RobotId) -> bool {
        self.of(robot) >= self.cfg.fuse_above
    }

    /// Every robot judged so far and its trust.
    pub fn all(&self) -> BTreeMap<RobotId, f32> {
        self.records.keys().map(|r| (r.clone(), self.of(r))).collect()
    }

    fn rate(&self) -> f32 {
        1.0 / self.cfg.window.max(1) as f32
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
        let rate = self.rate();
        let r = self.record(robot);
        r.track += rate * (f32::from(u8::from(agrees)) - r.track);
    }

    /// Judges each voter of a decided tick against the others' decision under `rule`.
    /// `ballots` sorted by robot, as [`consensus::decide`] leaves them.
    pub fn learn(&mut self, ballots: &[Ballot<'_>], rule: Rule) {
        if ballots.len() < 2 {
            return;
        }
        let rate = self.rate();
        for (b, (agreed, judged)) in ballots.iter().zip(consensus::agreement_with_the_others(ballots, rule)) {
            if judged == 0 {
                continue;
            }
            let x = agreed as f32 / judged as f32;
            let r = self.record(b.robot);
            r.votes += rate * (x - r.votes);
        }
    }
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
            .map(|(r, s)| Ballot { robot: r, visibility: 1, trust: book.of(r), quality: 1.0, steps: s })
            .collect();
        book.learn(&ballots, Rule::Trust);
    }

    #[test]
    fn a_voter_that_keeps_disagreeing_loses_trust_down_to_the_floor_and_earns_it_back() {
        let cfg = TrustConfig { window: 10, floor: 0.1, fuse_above: 0.5 };
        let mut book = TrustBook::new(cfg);
        let ids = [id("a"), id("b"), id("c")];
        assert_eq!(book.of(&ids[2]), 1.0, "trusted until judged");
        for _ in 0..5 {
            tick(&mut book, &ids, &[Workstation, Workstation, Manufacturing]);
        }
        let after5 = book.of(&ids[2]);
        assert!((after5 - 0.9f32.powi(5)).abs() < 1e-5, "{after5}"); // (1 − 1/10)^5
        assert!(book.fuses(&ids[2]), "0.59: still fused");
        for _ in 0..60 {
            tick(&mut book, &ids, &[Workstation, Workstation, Manufacturing]);
        }
        assert_eq!(book.of(&ids[2]), 0.1, "floored");
        assert!(!book.fuses(&ids[2]));
        assert_eq!(book.of(&ids[0]), 1.0, "the two that agree keep their trust");
        for _ in 0..30 {
            tick(&mut book, &ids, &[Workstation, Workstation, Workstation]);
        }
        assert!(book.of(&ids[2]) > 0.9, "recovered: {}", book.of(&ids[2]));
        assert_eq!(book.all().len(), 3);
    }

    #[test]
    fn a_lone_voter_is_not_judged_and_agreement_counts_step_by_step() {
        let mut book = TrustBook::new(TrustConfig { window: 1, ..TrustConfig::default() });
        let ids = [id("a"), id("b")];
        tick(&mut book, &ids[..1], &[Assembly]);
        assert!(book.all().is_empty());
        // two voters, each judged against the other: a says 2 at every step, b 2, 3, 3
        let (sa, sb) = (vec![StepVote { class: Assembly, confidence: 0.8 }; 3], {
            let mut s = vec![StepVote { class: Manufacturing, confidence: 0.8 }; 3];
            s[0].class = Assembly;
            s
        });
        let ballots = [
            Ballot { robot: &ids[0], visibility: 1, trust: 1.0, quality: 1.0, steps: &sa },
            Ballot { robot: &ids[1], visibility: 1, trust: 1.0, quality: 1.0, steps: &sb },
        ];
        book.learn(&ballots, Rule::Trust);
        assert!((book.of(&ids[0]) - 1.0 / 3.0).abs() < 1e-6);
        assert!((book.of(&ids[1]) - 1.0 / 3.0).abs() < 1e-6);
    }

    #[test]
    fn trust_is_the_product_of_the_vote_and_track_records() {
        let mut book = TrustBook::new(TrustConfig { window: 2, floor: 0.1, fuse_above: 0.5 });
        let ids = [id("a"), id("b"), id("c")];
        book.learn_track(&ids[0], false); // 1 → 0.5
        assert_eq!(book.of(&ids[0]), 0.5);
        tick(&mut book, &ids, &[Manufacturing, Workstation, Workstation]); // a's votes: 1 → 0.5
        assert_eq!(book.of(&ids[0]), 0.25);
        book.learn_track(&ids[0], true); // 0.5 → 0.75
        assert_eq!(book.of(&ids[0]), 0.375);
        book.learn_track(&ids[1], true);
        assert_eq!(book.of(&ids[1]), 1.0);
        for _ in 0..10 {
            book.learn_track(&ids[2], false);
        }
        assert_eq!(book.of(&ids[2]), 0.1, "floored");
    }
}
