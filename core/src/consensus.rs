//! Votes → the team's decision, for t and each forecast step. Pure.
//!
//! Two rules, chosen by `[tick] consensus`. For the votes counted at a step, with c_i
//! robot i's confidence in its class k_i:
//!
//! **paper** (paper III-E), with N_i robot i's visibility count:
//!
//! ```text
//! v_i = N_i / Σ N        ṽ_i = v_i / Σ v        c̃_i = c_i / Σ c
//! V_i = α ṽ_i + β c̃_i    score(a) = Σ_{i : k_i = a} V_i    decision = argmax score
//! ```
//!
//! Shares sum to one, so a lone voter counts fully whatever its confidence, and
//! nothing remembers who has been wrong.
//!
//! **trust**: each vote is evidence, weighed by how far the voter's record and view
//! let it be believed:
//!
//! ```text
//! e_i = ln(c_i (K−1) / (1 − c_i))     (the log-likelihood ratio of "k_i" for a voter
//!                                       right with probability c_i, wrong evenly)
//! w_i = trust_i · quality_i · e_i
//! score(a) = Σ_{i : k_i = a} w_i / Σ w     decision = argmax score
//! ```
//!
//! with c_i clamped to [1/K, 0.99] (no vote is negative evidence, none is proof, so one
//! sure voter outweighs at most a few unsure ones), trust_i what the *receiver* has
//! learned of the voter — the share of its recent votes that agreed with the decision
//! of the others, times the share of its worker estimates that agreed with theirs, in
//! [floor, 1] ([`crate::trust`]) — and quality_i how well the voter says it sees the
//! worker (at most 1: it can lower a vote's weight, never raise it above a full view).
//!
//! Ballots are summed in robot-id order and ties go to the lowest class id, so every
//! robot holding the same votes and weights reaches the same decision, bit for bit,
//! whatever order the votes arrived in.

use crate::hash::Fnv1a;
use crate::vote::argmax;
use spwi_proto::{RobotId, Station, StepVote, TeamStep, VoteMsg, NUM_CLASSES};

/// One robot's vote as the consensus sees it.
#[derive(Debug, Clone, Copy)]
pub struct Ballot<'a> {
    pub robot: &'a RobotId,
    pub visibility: u32,
    pub trust: f32,
    pub quality: f32,
    pub steps: &'a [StepVote],
}

impl<'a> Ballot<'a> {
    /// Vote `v` weighed by `trust`, what its receiver learned of the voter.
    pub fn of(v: &'a VoteMsg, trust: f32) -> Self {
        Ballot { robot: &v.robot, visibility: v.visibility, trust, quality: v.quality, steps: &v.steps }
    }
}

/// Weights of visibility (α) and confidence (β) in the paper's rule.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Weights {
    pub alpha: f32,
    pub beta: f32,
}

/// Which rule turns ballots into the decision.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum Rule {
    /// The paper's normalised shares of visibility and confidence.
    Paper(Weights),
    /// Evidence weighted by the voters' trust and view quality.
    Trust,
}

/// Highest confidence taken at its word: no vote is proof.
const MAX_CONFIDENCE: f32 = 0.99;
/// Least evidence a vote carries, so that weights never all vanish.
const MIN_EVIDENCE: f32 = 1e-3;

/// The log-likelihood ratio of a vote for its class at confidence `c`.
fn evidence(c: f32) -> f32 {
    let k = NUM_CLASSES as f32;
    let c = c.clamp(1.0 / k, MAX_CONFIDENCE);
    (c * (k - 1.0) / (1.0 - c)).ln().max(MIN_EVIDENCE)
}

fn shares(xs: impl Iterator<Item = f32> + Clone, n: usize) -> impl Iterator<Item = f32> + Clone {
    let sum: f32 = xs.clone().sum();
    xs.map(move |x| if sum > 0.0 { x / sum } else { 1.0 / n as f32 })
}

/// Each ballot's weight at step `h` under `rule` (in the ballots' order).
fn weights(at_h: &[&Ballot<'_>], h: usize, rule: Rule) -> Vec<f32> {
    let n = at_h.len();
    match rule {
        Rule::Paper(w) => {
            let v = shares(at_h.iter().map(|b| b.visibility as f32), n);
            let v_tilde = shares(v, n); // ṽ: as in the paper, though Σ v is already 1
            let c_tilde = shares(at_h.iter().map(|b| b.steps[h].confidence), n);
            v_tilde.zip(c_tilde).map(|(vt, ct)| w.alpha * vt + w.beta * ct).collect()
        }
        Rule::Trust => {
            let mut w: Vec<f32> = at_h.iter().map(|b| trust_weight(b, h)).collect();
            normalise(&mut w);
            w
        }
    }
}

/// A ballot's weight at step `h` under the trust rule, before a step's weights are
/// normalised: it depends on no other ballot.
fn trust_weight(b: &Ballot<'_>, h: usize) -> f32 {
    b.trust.max(0.0) * b.quality.max(0.0) * evidence(b.steps[h].confidence)
}

/// Scales trust-rule weights to sum to one; when every voter's trust or quality is
/// zero, the votes count alike.
fn normalise(w: &mut [f32]) {
    let sum: f32 = w.iter().sum();
    let n = w.len() as f32;
    for x in w {
        *x = if sum > 0.0 { *x / sum } else { 1.0 / n };
    }
}

/// The team decision: one [`TeamStep`] per step that any ballot covers; empty when
/// there are no ballots. Leaves `ballots` sorted by robot.
pub fn decide(ballots: &mut [Ballot<'_>], rule: Rule) -> Vec<TeamStep> {
    ballots.sort_by(|a, b| a.robot.cmp(b.robot));
    decide_sorted(ballots, rule)
}

/// [`decide`] for ballots already sorted by robot.
pub fn decide_sorted(ballots: &[Ballot<'_>], rule: Rule) -> Vec<TeamStep> {
    let steps = ballots.iter().map(|b| b.steps.len()).max().unwrap_or(0);
    (0..steps)
        .map(|h| {
            let at_h: Vec<_> = ballots.iter().filter(|b| h < b.steps.len()).collect();
            let mut score = [0.0f32; NUM_CLASSES];
            for (b, w) in at_h.iter().zip(weights(&at_h, h, rule)) {
                score[b.steps[h].class.index()] += w;
            }
            let k = argmax(&score);
            TeamStep { class: Station::ALL[k], score: score[k] }
        })
        .collect()
}

/// A digest of the ballots, sorted by robot as [`decide`] leaves them: FNV-1a over each
/// origin, visibility, trust, quality and step, so that it is the same on every robot
/// and every build. Two robots that name the same digest for a tick decided on the
/// same ballots.
pub fn digest(ballots: &[Ballot<'_>]) -> u64 {
    let mut h = Fnv1a::default();
    for b in ballots {
        h.eat(b.robot.as_str().as_bytes());
        h.eat(&[0xff]); // ids hold no 0xff byte: the id ends here
        h.eat(&b.visibility.to_le_bytes());
        h.eat(&b.trust.to_bits().to_le_bytes());
        h.eat(&b.quality.to_bits().to_le_bytes());
        h.eat(&(b.steps.len() as u32).to_le_bytes());
        for s in b.steps {
            h.eat(&[s.class.into()]);
            h.eat(&s.confidence.to_bits().to_le_bytes());
        }
    }
    h.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use spwi_proto::Station::*;

    fn id(s: &str) -> RobotId {
        RobotId::new(s).unwrap()
    }

    fn sv(class: Station, confidence: f32) -> StepVote {
        StepVote { class, confidence }
    }

    fn ballot<'a>(robot: &'a RobotId, visibility: u32, steps: &'a [StepVote]) -> Ballot<'a> {
        Ballot { robot, visibility, trust: 1.0, quality: 1.0, steps }
    }

    const PAPER: Rule = Rule::Paper(Weights { alpha: 0.5, beta: 0.5 });

    #[test]
    fn hand_computed_three_robots() {
        // r1: class 2, conf .9, sees 6; r2: class 3, conf .6, sees 3; r3: class 3, conf .5, sees 1
        // v = (.6, .3, .1); c̃ = (.9, .6, .5)/2 = (.45, .3, .25)
        // α=β=.5: V = (.525, .3, .175) → score(2) = .525, score(3) = .475 → 2
        let (a, b, c) = (id("r1"), id("r2"), id("r3"));
        let (s1, s2, s3) = ([sv(Assembly, 0.9)], [sv(Manufacturing, 0.6)], [sv(Manufacturing, 0.5)]);
        let mut ballots = [ballot(&c, 1, &s3), ballot(&a, 6, &s1), ballot(&b, 3, &s2)];
        let d = decide(&mut ballots, PAPER);
        assert_eq!(d[0].class, Assembly);
        assert!((d[0].score - 0.525).abs() < 1e-6, "{}", d[0].score);
        // visibility alone flips nothing; confidence alone: (.45) vs (.55) → 3
        let d = decide(&mut ballots, Rule::Paper(Weights { alpha: 0.0, beta: 1.0 }));
        assert_eq!(d[0].class, Manufacturing);
        assert!((d[0].score - 0.55).abs() < 1e-6);
    }

    #[test]
    fn the_paper_rule_ignores_trust_and_quality() {
        let (a, b) = (id("a"), id("b"));
        let (sa, sb) = ([sv(Workstation, 0.9)], [sv(Assembly, 0.6)]);
        let mut trusted = [ballot(&a, 2, &sa), ballot(&b, 2, &sb)];
        let mut doubted = [Ballot { trust: 0.05, quality: 0.1, ..trusted[0] }, trusted[1]];
        assert_eq!(decide(&mut trusted, PAPER), decide(&mut doubted, PAPER));
    }

    #[test]
    fn trust_weighs_evidence_by_record_and_view() {
        // K = 4: e(.9) = ln(.9·3/.1) = ln 27 = 3.296; e(.6) = ln(.6·3/.4) = ln 4.5 = 1.504
        let (a, b, c) = (id("a"), id("b"), id("c"));
        let (sa, sb, sc) = ([sv(Workstation, 0.9)], [sv(Assembly, 0.6)], [sv(Assembly, 0.6)]);
        let mut ballots = [ballot(&a, 1, &sa), ballot(&b, 1, &sb), ballot(&c, 1, &sc)];
        // 3.296 against 2 × 1.504 = 3.008: the sure voter wins, with its share of the weight
        let d = decide(&mut ballots, Rule::Trust);
        assert_eq!(d[0].class, Workstation);
        assert!((d[0].score - 27f32.ln() / (27f32.ln() + 2.0 * 4.5f32.ln())).abs() < 1e-5, "{}", d[0].score);
        // a record of being wrong halves its weight: the two unsure voters win
        ballots[0].trust = 0.5;
        assert_eq!(decide(&mut ballots, Rule::Trust)[0].class, Assembly);
        // as does a poor view of the worker
        ballots[0].trust = 1.0;
        ballots[0].quality = 0.5;
        assert_eq!(decide(&mut ballots, Rule::Trust)[0].class, Assembly);
    }

    #[test]
    fn no_vote_is_proof_and_none_is_negative_evidence() {
        // e(.99) = ln 297 = 5.69 (a confidence of .99999 counts as .99): four voters at
        // .8 (e = ln 12 = 2.48 each) outweigh it, two do not
        let ids: Vec<RobotId> = ["a", "b", "c", "d", "e"].into_iter().map(id).collect();
        let (sure, unsure) = ([sv(Manufacturing, 0.99999)], [sv(Workstation, 0.8)]);
        let mut five: Vec<Ballot<'_>> =
            ids.iter().enumerate().map(|(i, r)| ballot(r, 1, if i == 0 { &sure } else { &unsure })).collect();
        assert_eq!(decide(&mut five, Rule::Trust)[0].class, Workstation);
        assert_eq!(decide(&mut five[..3], Rule::Trust)[0].class, Manufacturing);
        let d = decide(&mut five[..2], Rule::Trust);
        assert!((d[0].score - 297f32.ln() / (297f32.ln() + 12f32.ln())).abs() < 1e-5, "{}", d[0].score);
        // alone, a voter decides whatever its confidence
        let (a, b) = (id("a"), id("b"));
        let sb = [sv(Workstation, 0.3)];
        let d = decide(&mut [ballot(&a, 1, &sb)], Rule::Trust);
        assert_eq!((d[0].class, d[0].score), (Workstation, 1.0));
        // below chance a vote is no evidence, yet the votes are still counted
        let (s1, s2, s3) = ([sv(Manufacturing, 0.1)], [sv(Storage, 0.1)], [sv(Storage, 0.1)]);
        let c = id("c");
        let d = decide(&mut [ballot(&a, 1, &s1), ballot(&b, 1, &s2), ballot(&c, 1, &s3)], Rule::Trust);
        assert_eq!(d[0].class, Storage);
    }

    #[test]
    fn every_step_is_decided_and_order_does_not_matter() {
        let (a, b) = (id("a"), id("b"));
        let sa = [sv(Storage, 0.9), sv(Workstation, 0.9)];
        let sb = [sv(Storage, 0.2), sv(Assembly, 0.3)];
        for rule in [PAPER, Rule::Trust] {
            let one = decide(&mut [ballot(&a, 2, &sa), ballot(&b, 2, &sb)], rule);
            let two = decide(&mut [ballot(&b, 2, &sb), ballot(&a, 2, &sa)], rule);
            assert_eq!(one, two);
            assert_eq!(one.iter().map(|s| s.class).collect::<Vec<_>>(), vec![Storage, Workstation]);
        }
    }

    #[test]
    fn ties_go_to_the_lowest_class_and_zero_visibility_is_uniform() {
        let (a, b) = (id("a"), id("b"));
        let (sa, sb) = ([sv(Manufacturing, 0.5)], [sv(Workstation, 0.5)]);
        let d = decide(&mut [ballot(&a, 0, &sa), ballot(&b, 0, &sb)], PAPER);
        assert_eq!(d[0].class, Workstation);
        assert!((d[0].score - 0.5).abs() < 1e-6);
        let untrusted = [Ballot { trust: 0.0, ..ballot(&a, 1, &sa) }, Ballot { trust: 0.0, ..ballot(&b, 1, &sb) }];
        let d = decide(&mut untrusted.clone(), Rule::Trust);
        assert_eq!((d[0].class, d[0].score), (Workstation, 0.5), "no trust anywhere: votes count alike");
    }

    #[test]
    fn the_digest_names_the_ballot_set_whatever_the_order() {
        let (a, b) = (id("a"), id("b"));
        let (sa, sb) = ([sv(Manufacturing, 0.5)], [sv(Workstation, 0.5)]);
        let mut ab = [ballot(&a, 2, &sa), ballot(&b, 1, &sb)];
        let mut ba = [ab[1], ab[0]];
        decide(&mut ab, PAPER);
        decide(&mut ba, PAPER);
        assert_eq!(digest(&ab), digest(&ba));
        assert_ne!(digest(&ab), digest(&ab[..1]), "one ballot fewer, another digest");
        let sb2 = [sv(Workstation, 0.50001)];
        let other = [ab[0], Ballot { steps: &sb2, ..ab[1] }];
        assert_ne!(digest(&ab), digest(&other), "a confidence that differs, another digest");
        let less_trusted = [ab[0], Ballot { trust: 0.5, ..ab[1] }];
        assert_ne!(digest(&ab), digest(&less_trusted), "a trust that differs, another digest");
        assert_eq!(digest(&[]), 0xcbf2_9ce4_8422_2325, "FNV-1a's offset basis: fixed across builds");
    }

    #[test]
    fn no_ballots_no_decision() {
        assert!(decide(&mut [], PAPER).is_empty());
        assert!(decide(&mut [], Rule::Trust).is_empty());
    }
}
