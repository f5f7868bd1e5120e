//! What a receiver can check of a vote's view: whether the voter places the worker, and
//! where the other voters of the tick do.
//!
//! A vote says how well its voter sees the worker (`quality`), and that is the voter's
//! word. What the receiver can check is the worker estimate the vote carries: a camera
//! that sees the worker can say where it stands. So a vote that places the worker
//! nowhere while another vote of the tick places it, or places it where most of the
//! others do not ([`crate::floor::agrees_with_most`], three or more estimates), weighs
//! [`UNCHECKED`] of what it claims: a liar that names a station without showing where
//! it sees the worker, a camera replaying an old clip, a robot lost on the floor. The
//! check reads the tick's ballots alone, so every robot that holds the same ballots
//! weighs them alike. It lowers a vote's weight; it never raises one above its claim.

use crate::consensus::Ballot;
use crate::floor::agrees_with_most;
use spwi_proto::{RobotId, VoteMsg, WorkerEstimate};

/// What a vote's view quality is scaled by when the tick's estimates do not bear it out.
pub const UNCHECKED: f32 = 0.1;

/// The ballots of one tick's votes (in their order), each weighing `trust` of its voter
/// and its view quality as checked against the others.
pub fn ballots<'a>(votes: &[&'a VoteMsg], trust: impl Fn(&RobotId) -> f32) -> Vec<Ballot<'a>> {
    let placed: Vec<&WorkerEstimate> = votes.iter().filter_map(|v| v.worker.as_ref()).collect();
    let mut agrees = agrees_with_most(&placed).map(Vec::into_iter);
    votes
        .iter()
        .map(|v| {
            let borne_out = match &v.worker {
                None => placed.is_empty(),
                Some(_) => agrees.as_mut().and_then(Iterator::next).unwrap_or(true),
            };
            let check = if borne_out { 1.0 } else { UNCHECKED };
            Ballot { quality: v.quality.clamp(0.0, 1.0) * check, ..Ballot::of(v, trust(&v.robot)) }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use spwi_proto::{Station, StepVote};

    fn vote(robot: &str, worker: Option<[f32; 2]>) -> VoteMsg {
        VoteMsg {
            robot: RobotId::new(robot).unwrap(),
            instance: 1,
            tick: 7,
            steps: vec![StepVote { class: Station::Assembly, confidence: 0.9 }],
            visibility: 3,
            quality: 0.8,
            worker: worker.map(|p| WorkerEstimate { position: p, velocity: [0.0; 2], covariance: [0.01, 0.0, 0.01] }),
            signature: Vec::new(),
        }
    }

    fn qualities(votes: &[VoteMsg]) -> Vec<f32> {
        let votes: Vec<&VoteMsg> = votes.iter().collect();
        ballots(&votes, |_| 1.0).iter().map(|b| b.quality).collect()
    }

    #[test]
    fn a_vote_that_places_no_worker_beside_one_that_does_weighs_little() {
        let q = qualities(&[vote("a", Some([1.0, 1.0])), vote("liar", None)]);
        assert_eq!(q, vec![0.8, 0.8 * UNCHECKED]);
        assert_eq!(
            qualities(&[vote("a", None), vote("b", None)]),
            vec![0.8, 0.8],
            "nobody places it: nothing to check"
        );
    }

    #[test]
    fn a_vote_that_places_the_worker_where_most_do_not_weighs_little() {
        let q = qualities(&[
            vote("a", Some([1.0, 1.0])),
            vote("b", Some([1.1, 1.0])),
            vote("far", Some([6.0, 1.0])),
            vote("c", None),
        ]);
        assert_eq!(q, vec![0.8, 0.8, 0.8 * UNCHECKED, 0.8 * UNCHECKED]);
        let two = qualities(&[vote("a", Some([1.0, 1.0])), vote("far", Some([6.0, 1.0]))]);
        assert_eq!(two, vec![0.8, 0.8], "of two that disagree, neither can be told wrong");
    }
}
