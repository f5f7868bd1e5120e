//! Votes → the team's decision (paper III-E), for t and each forecast step. Pure.
//!
//! For the votes counted at a step, with N_i robot i's visibility count and c_i its
//! confidence:
//!
//! ```text
//! v_i = N_i / Σ N        ṽ_i = v_i / Σ v        c̃_i = c_i / Σ c
//! V_i = α ṽ_i + β c̃_i    score(a) = Σ_{i : k_i = a} V_i    decision = argmax score
//! ```
//!
//! When every visibility (or every confidence) is zero, its normalised share is uniform
//! rather than undefined. Ballots are summed in robot-id order and ties go to the lowest
//! class id, so every robot holding the same votes reaches the same decision, bit for
//! bit, whatever order the votes arrived in.

use crate::vote::argmax;
use spwi_proto::{RobotId, StepVote, TeamStep, NUM_CLASSES};

/// One robot's vote as the consensus sees it.
#[derive(Debug, Clone, Copy)]
pub struct Ballot<'a> {
    pub robot: &'a RobotId,
    pub visibility: u32,
    pub steps: &'a [StepVote],
}

/// Weights of visibility (α) and confidence (β).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Weights {
    pub alpha: f32,
    pub beta: f32,
}

fn shares(xs: impl Iterator<Item = f32> + Clone, n: usize) -> impl Iterator<Item = f32> + Clone {
    let sum: f32 = xs.clone().sum();
    xs.map(move |x| if sum > 0.0 { x / sum } else { 1.0 / n as f32 })
}

/// The team decision: one [`TeamStep`] per step that any ballot covers; empty when
/// there are no ballots.
pub fn decide(ballots: &mut [Ballot<'_>], w: Weights) -> Vec<TeamStep> {
    ballots.sort_by(|a, b| a.robot.cmp(b.robot));
    let steps = ballots.iter().map(|b| b.steps.len()).max().unwrap_or(0);
    (0..steps)
        .map(|h| {
            let at_h: Vec<_> = ballots.iter().filter(|b| h < b.steps.len()).collect();
            let n = at_h.len();
            let v = shares(at_h.iter().map(|b| b.visibility as f32), n);
            let v_tilde = shares(v, n); // ṽ: as in the paper, though Σ v is already 1
            let c_tilde = shares(at_h.iter().map(|b| b.steps[h].confidence), n);
            let mut score = [0.0f32; NUM_CLASSES];
            for ((b, vt), ct) in at_h.iter().zip(v_tilde).zip(c_tilde) {
                score[b.steps[h].class as usize] += w.alpha * vt + w.beta * ct;
            }
            let k = argmax(&score);
            TeamStep { class: k as u8, score: score[k] }
        })
        .collect()
}

/// A digest of the ballots, sorted by robot as [`decide`] leaves them: FNV-1a over each
/// origin, visibility and step, so that it is the same on every robot and every build.
/// Two robots that name the same digest for a tick decided on the same ballots.
pub fn digest(ballots: &[Ballot<'_>]) -> u64 {
    const OFFSET: u64 = 0xcbf2_9ce4_8422_2325;
    const PRIME: u64 = 0x0100_0000_01b3;
    let mut h = OFFSET;
    let mut eat = |bytes: &[u8]| {
        for &b in bytes {
            h = (h ^ u64::from(b)).wrapping_mul(PRIME);
        }
    };
    for b in ballots {
        eat(b.robot.as_str().as_bytes());
        eat(&[0xff]); // ids hold no 0xff byte: the id ends here
        eat(&b.visibility.to_le_bytes());
        eat(&(b.steps.len() as u32).to_le_bytes());
        for s in b.steps {
            eat(&[s.class]);
            eat(&s.confidence.to_bits().to_le_bytes());
        }
    }
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    fn id(s: &str) -> RobotId {
        RobotId::new(s).unwrap()
    }

    fn sv(class: u8, confidence: f32) -> StepVote {
        StepVote { class, confidence }
    }

    #[test]
    fn hand_computed_three_robots() {
        // r1: class 2, conf .9, sees 6; r2: class 3, conf .6, sees 3; r3: class 3, conf .5, sees 1
        // v = (.6, .3, .1); c̃ = (.9, .6, .5)/2 = (.45, .3, .25)
        // α=β=.5: V = (.525, .3, .175) → score(2) = .525, score(3) = .475 → 2
        let (a, b, c) = (id("r1"), id("r2"), id("r3"));
        let (s1, s2, s3) = ([sv(2, 0.9)], [sv(3, 0.6)], [sv(3, 0.5)]);
        let mut ballots = [
            Ballot { robot: &c, visibility: 1, steps: &s3 },
            Ballot { robot: &a, visibility: 6, steps: &s1 },
            Ballot { robot: &b, visibility: 3, steps: &s2 },
        ];
        let d = decide(&mut ballots, Weights { alpha: 0.5, beta: 0.5 });
        assert_eq!(d[0].class, 2);
        assert!((d[0].score - 0.525).abs() < 1e-6, "{}", d[0].score);
        // visibility alone flips nothing; confidence alone: (.45) vs (.55) → 3
        let d = decide(&mut ballots, Weights { alpha: 0.0, beta: 1.0 });
        assert_eq!(d[0].class, 3);
        assert!((d[0].score - 0.55).abs() < 1e-6);
    }

    #[test]
    fn every_step_is_decided_and_order_does_not_matter() {
        let (a, b) = (id("a"), id("b"));
        let sa = [sv(0, 0.9), sv(1, 0.9)];
        let sb = [sv(0, 0.2), sv(2, 0.3)];
        let w = Weights { alpha: 0.5, beta: 0.5 };
        let one = decide(
            &mut [Ballot { robot: &a, visibility: 2, steps: &sa }, Ballot { robot: &b, visibility: 2, steps: &sb }],
            w,
        );
        let two = decide(
            &mut [Ballot { robot: &b, visibility: 2, steps: &sb }, Ballot { robot: &a, visibility: 2, steps: &sa }],
            w,
        );
        assert_eq!(one, two);
        assert_eq!(one.iter().map(|s| s.class).collect::<Vec<_>>(), vec![0, 1]);
    }

    #[test]
    fn ties_go_to_the_lowest_class_and_zero_visibility_is_uniform() {
        let (a, b) = (id("a"), id("b"));
        let (sa, sb) = ([sv(3, 0.5)], [sv(1, 0.5)]);
        let d = decide(
            &mut [Ballot { robot: &a, visibility: 0, steps: &sa }, Ballot { robot: &b, visibility: 0, steps: &sb }],
            Weights { alpha: 0.5, beta: 0.5 },
        );
        assert_eq!(d[0].class, 1);
        assert!((d[0].score - 0.5).abs() < 1e-6);
    }

    #[test]
    fn the_digest_names_the_ballot_set_whatever_the_order() {
        let (a, b) = (id("a"), id("b"));
        let (sa, sb) = ([sv(3, 0.5)], [sv(1, 0.5)]);
        let mut ab = [Ballot { robot: &a, visibility: 2, steps: &sa }, Ballot { robot: &b, visibility: 1, steps: &sb }];
        let mut ba = [ab[1], ab[0]];
        let w = Weights { alpha: 0.5, beta: 0.5 };
        decide(&mut ab, w);
        decide(&mut ba, w);
        assert_eq!(digest(&ab), digest(&ba));
        assert_ne!(digest(&ab), digest(&ab[..1]), "one ballot fewer, another digest");
        let sb2 = [sv(1, 0.50001)];
        let other = [ab[0], Ballot { steps: &sb2, ..ab[1] }];
        assert_ne!(digest(&ab), digest(&other), "a confidence that differs, another digest");
        assert_eq!(digest(&[]), 0xcbf2_9ce4_8422_2325, "FNV-1a's offset basis: fixed across builds");
    }

    #[test]
    fn no_ballots_no_decision() {
        assert!(decide(&mut [], Weights { alpha: 0.5, beta: 0.5 }).is_empty());
    }
}
