//! Whether the team names each worker alike, and keeps the name.
//!
//! Every robot names the people it tracks with the team's ids
//! (`spwi_core::floor::worker_ids`) and shares them. Against the truth, each tick: a
//! robot names a true worker when one of the people it shared of the tick stands within
//! [`MATCH_M`] of the worker (each person matched to one worker at most, nearest pairs
//! first). Two figures follow, as multi-object tracking counts them:
//!
//! - *identity switches*: a robot's id for a worker changes from one tick it names the
//!   worker to the next (`robot_switches`), and the team's id — the id most robots
//!   naming the worker use; on a tie the one it was, else the smaller — changes
//!   (`switches`); per minute the worker is named;
//! - *same id*: of the worker-ticks on which two robots or more name the worker, those
//!   on which all of them use one id.

use serde::Serialize;
use spwi_proto::{PersonShare, WorkerId, TICKS_PER_SECOND};
use std::collections::BTreeMap;

/// How far from a worker a robot's person may stand and be taken for the worker, metres.
pub const MATCH_M: f32 = 1.0;

/// Counts over worker-ticks, pooled over episodes.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct IdentityTally {
    pub worker_ticks: u64,
    /// Worker-ticks some robot named the worker on, and the team's id switches.
    pub named: u64,
    pub switches: u64,
    /// Robot-worker-ticks a robot named the worker on, and that robot's id switches.
    pub robot_named: u64,
    pub robot_switches: u64,
    /// Worker-ticks two robots or more named the worker on, and those with one id.
    pub compared: u64,
    pub same: u64,
}

impl IdentityTally {
    pub fn merge(&mut self, o: &IdentityTally) {
        self.worker_ticks += o.worker_ticks;
        self.named += o.named;
        self.switches += o.switches;
        self.robot_named += o.robot_named;
        self.robot_switches += o.robot_switches;
        self.compared += o.compared;
        self.same += o.same;
    }
}

/// The identity figures of an evaluation (`identity` in its JSON).
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Identity {
    /// The team's id switches per minute a worker is named.
    pub switches_per_worker_minute: f64,
    /// One robot's id switches per minute it names a worker.
    pub robot_switches_per_minute: f64,
    /// Share of worker-ticks named by two robots or more on which all used one id.
    pub same_id: f64,
    /// Share of worker-ticks some robot named the worker on.
    pub named: f64,
}

impl Identity {
    pub fn of(t: &IdentityTally) -> Identity {
        let per_minute = |n: u64, ticks: u64| n as f64 * 60.0 * f64::from(TICKS_PER_SECOND) / ticks.max(1) as f64;
        Identity {
            switches_per_worker_minute: per_minute(t.switches, t.named),
            robot_switches_per_minute: per_minute(t.robot_switches, t.robot_named),
            same_id: t.same as f64 / t.compared.max(1) as f64,
            named: t.named as f64 / t.worker_ticks.max(1) as f64,
        }
    }
}

/// One episode's identities, tick after tick.
#[derive(Debug, Clone)]
pub struct IdentityTracker {
    /// Each robot's id for each worker, when it last named the worker.
    robot: Vec<Vec<Option<WorkerId>>>,
    /// The team's id for each worker, when some robot last named it.
    team: Vec<Option<WorkerId>>,
    pub tally: IdentityTally,
}

impl IdentityTracker {
    pub fn new(robots: usize, workers: usize) -> Self {
        IdentityTracker {
            robot: vec![vec![None; workers]; robots],
            team: vec![None; workers],
            tally: Default::default(),
        }
    }

    /// One tick: where each worker truly stands, and the people each robot shared of
    /// the tick (`None`: the robot shared nothing of it, or is not live).
    pub fn tick(&mut self, workers: &[[f32; 2]], shared: &[Option<&[PersonShare]>]) {
        let mut named: Vec<Vec<WorkerId>> = vec![Vec::new(); workers.len()];
        for (r, people) in shared.iter().enumerate() {
            let Some(people) = people else { continue };
            for (w, id) in match_people(workers, people) {
                named[w].push(id);
                self.tally.robot_named += 1;
                let last = &mut self.robot[r][w];
                self.tally.robot_switches += u64::from(last.is_some_and(|l| l != id));
                *last = Some(id);
            }
        }
        for (w, ids) in named.iter().enumerate() {
            self.tally.worker_ticks += 1;
            let Some(team) = most_used(ids, self.team[w]) else { continue };
            self.tally.named += 1;
            self.tally.switches += u64::from(self.team[w].is_some_and(|l| l != team));
            self.team[w] = Some(team);
            if ids.len() >= 2 {
                self.tally.compared += 1;
                self.tally.same += u64::from(ids.iter().all(|i| *i == ids[0]));
            }
        }
    }
}

/// Which worker each of `people` is, if any: nearest pairs first, within [`MATCH_M`],
/// each worker and each person once. Returns (worker index, the person's id).
fn match_people(workers: &[[f32; 2]], people: &[PersonShare]) -> Vec<(usize, WorkerId)> {
    let mut pairs: Vec<(f32, usize, usize)> = workers
        .iter()
        .enumerate()
        .flat_map(|(w, at)| {
            people.iter().enumerate().map(move |(p, s)| {
                let d = ((s.estimate.position[0] - at[0]).powi(2) + (s.estimate.position[1] - at[1]).powi(2)).sqrt();
                (d, w, p)
            })
        })
        .filter(|(d, _, _)| *d <= MATCH_M)
        .collect();
    pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
    let (mut worker_done, mut person_done) = (vec![false; workers.len()], vec![false; people.len()]);
    let mut out = Vec::new();
    for (_, w, p) in pairs {
        if !worker_done[w] && !person_done[p] {
            (worker_done[w], person_done[p]) = (true, true);
            out.push((w, people[p].worker));
        }
    }
    out
}

/// The id most of `ids` are; of ids used alike, the team's id so far (`before`) if it
/// is one of them, else the smaller. The team's id changes when more robots use
/// another, not when as many do.
fn most_used(ids: &[WorkerId], before: Option<WorkerId>) -> Option<WorkerId> {
    let mut count: BTreeMap<WorkerId, usize> = BTreeMap::new();
    for id in ids {
        *count.entry(*id).or_default() += 1;
    }
    let most = count.values().copied().max()?;
    let tied: Vec<WorkerId> = count.into_iter().filter(|(_, n)| *n == most).map(|(id, _)| id).collect();
    before.filter(|b| tied.contains(b)).or(tied.first().copied())
}

#[cfg(test)]
mod tests {
    use super::*;
    use spwi_proto::WorkerEstimate;

    fn person(id: u64, at: [f32; 2]) -> PersonShare {
        PersonShare {
            worker: WorkerId(id),
            estimate: WorkerEstimate { position: at, velocity: [0.0; 2], covariance: [0.1, 0.0, 0.1] },
        }
    }

    #[test]
    fn switches_and_agreement_are_counted_against_the_truth() {
        let workers = [[0.0, 0.0], [5.0, 0.0]];
        let mut t = IdentityTracker::new(2, 2);
        // Both robots name worker 0 as 1 and worker 1 as 2; robot 1 then calls worker
        // 1 by 3 for a tick, and back (two switches of its own, none of the team's: the
        // tie of 2 and 3 goes to 2).
        let a = [person(1, [0.1, 0.0]), person(2, [5.2, 0.0])];
        let b = [person(1, [0.0, 0.2]), person(2, [4.9, 0.0])];
        let b_odd = [person(1, [0.0, 0.2]), person(3, [4.9, 0.0])];
        t.tick(&workers, &[Some(&a), Some(&b)]);
        t.tick(&workers, &[Some(&a), Some(&b_odd)]);
        t.tick(&workers, &[Some(&a), Some(&b)]);
        // A person 3 m from every worker names nobody; a robot that shared nothing
        // names nobody either.
        t.tick(&workers, &[Some(&[person(9, [2.5, 0.0])]), None]);
        assert_eq!(
            t.tally,
            IdentityTally {
                worker_ticks: 8,
                named: 6,
                switches: 0,
                robot_named: 12,
                robot_switches: 2,
                compared: 6,
                same: 5
            }
        );
        // Now every robot calls worker 0 by 4: the team's id switches once.
        let c = [person(4, [0.0, 0.0])];
        t.tick(&workers, &[Some(&c), Some(&c)]);
        assert_eq!((t.tally.switches, t.tally.robot_switches), (1, 4));
        let id = Identity::of(&t.tally);
        assert!((id.same_id - 6.0 / 7.0).abs() < 1e-9 && (id.named - 7.0 / 10.0).abs() < 1e-9, "{id:?}");
        assert!((id.switches_per_worker_minute - 600.0 / 7.0).abs() < 1e-9);
    }

    #[test]
    fn each_person_names_one_worker_and_the_nearest_pair_wins() {
        let workers = [[0.0, 0.0], [0.8, 0.0]];
        // One person between them, nearer worker 1: worker 1's; worker 0 unnamed.
        assert_eq!(match_people(&workers, &[person(7, [0.5, 0.0])]), vec![(1, WorkerId(7))]);
        let tie = [WorkerId(3), WorkerId(2), WorkerId(3), WorkerId(2)];
        assert_eq!(most_used(&tie, None), Some(WorkerId(2)));
        assert_eq!(most_used(&tie, Some(WorkerId(3))), Some(WorkerId(3)), "a tie keeps the team's id");
        assert_eq!(most_used(&tie[..3], Some(WorkerId(2))), Some(WorkerId(3)), "more robots use 3");
    }
}
