//! Who was right, in hindsight: the station a worker stops at is the answer every vote
//! of its way there should have given.
//!
//! Ballots judged against each other ([`crate::trust`]) cannot tell who is wrong when
//! two voters disagree and nobody else votes: a confident liar beside one honest
//! camera, or a camera replaying an old clip beside one that sees the worker, stays
//! unjudged for as long as the two vote alone. The worker settles it. A worker walks to
//! a station and stays there to work; the station it stays at is what every vote since
//! it left its previous station should have named at its first step (the goal it walks
//! to), and what every vote should name while it stays. So once the team's track holds
//! the worker still beside one mapped station for a second, each vote since the
//! last judged tick is judged right or wrong, and each vote while it stays is judged as
//! it comes.
//!
//! It is fed what trust is learned from — each decided tick's votes, some ticks later,
//! and where those votes place the worker — so robots that learned the same lessons judge
//! alike; where the worker stands comes from the voters whose estimates the robot fuses,
//! and which station that is from its team map, which the robots share.
//!
//! A tick on which no voter named the station is not judged: the worker changed its
//! mind on the way (its early votes were right by the old goal), or nobody could know
//! yet. What is judged is who was right when someone was, so an honest camera's bad
//! trip, shared by every honest camera, costs none of them anything.

use crate::floor::fuse;
use crate::floor::stations::{at_one_station, Dwell};
use spwi_proto::{RobotId, Station, WorkerEstimate, NUM_CLASSES};
use std::collections::VecDeque;

/// The most ticks kept waiting for a stay (60 s): older votes go unjudged.
pub const MAX_PENDING: usize = 600;

/// One decided tick's votes: each voter's class at the tick itself.
type Named = Vec<(RobotId, Station)>;

/// Whether the worker stays somewhere, and the votes waiting for it to.
#[derive(Debug, Clone, Default)]
pub struct Hindsight {
    pending: VecDeque<Named>,
    dwell: Dwell,
}

impl Hindsight {
    /// Takes one decided tick, in tick order: `named`, each voter's class at the tick;
    /// `worker`, the estimates of the voters whose word on the worker counts; `stations`,
    /// the team map. Returns each judgement it can make now: (voter, right).
    ///
    /// The worker stays at a station when the fused estimates have held it still for a
    /// second ([`Dwell`]) beside one station of the map ([`at_one_station`]): the rule
    /// by which the map learns where the worker works.
    pub fn learn(
        &mut self,
        named: Named,
        worker: &[&WorkerEstimate],
        stations: &[Option<[f32; 2]>; NUM_CLASSES],
    ) -> Vec<(RobotId, bool)> {
        self.pending.push_back(named);
        if self.pending.len() > MAX_PENDING {
            self.pending.pop_front();
        }
        // A tick nobody placed the worker on neither breaks a stay nor makes one.
        let Some(w) = fuse(worker.iter().copied()) else { return Vec::new() };
        let places = Station::ALL.into_iter().zip(stations).filter_map(|(s, p)| Some(((*p)?, s)));
        let Some(station) = self.dwell.observe(w.position).and_then(|still| at_one_station(still, places)) else {
            return Vec::new();
        };
        self.pending
            .drain(..)
            .filter(|named| named.iter().any(|(_, class)| *class == station))
            .flatten()
            .map(|(robot, class)| (robot, class == station))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::floor::stations::DWELL_TICKS;
    use spwi_proto::Station::*;

    fn id(s: &str) -> RobotId {
        RobotId::new(s).unwrap()
    }

    /// The worker at (x, y): whether it stands still is read from where it is tick
    /// after tick, never from the track's velocity.
    fn at(x: f32, y: f32) -> WorkerEstimate {
        WorkerEstimate { position: [x, y], velocity: [0.0; 2], covariance: [0.04, 0.0, 0.04] }
    }

    /// Workstation at (0, 0), Assembly at (10, 0); the others not on the map.
    const MAP: [Option<[f32; 2]>; NUM_CLASSES] = [None, Some([0.0, 0.0]), Some([10.0, 0.0]), None];

    fn named(a: Station, b: Station) -> Named {
        vec![(id("a"), a), (id("b"), b)]
    }

    #[test]
    fn the_votes_of_a_walk_are_judged_by_the_station_the_worker_stays_at() {
        let mut h = Hindsight::default();
        // Walking from the workstation to assembly: a names assembly, b the workstation.
        for x in 1..9 {
            let w = at(x as f32, 0.0);
            assert!(h.learn(named(Assembly, Workstation), &[&w], &MAP).is_empty(), "not staying yet");
        }
        // Standing at assembly: judged once it has stood there for a second.
        let still = at(9.8, 0.1);
        for _ in 1..DWELL_TICKS {
            assert!(h.learn(named(Assembly, Assembly), &[&still], &MAP).is_empty());
        }
        let judged = h.learn(named(Assembly, Assembly), &[&still], &MAP);
        let wrong: Vec<&RobotId> = judged.iter().filter(|(_, ok)| !ok).map(|(r, _)| r).collect();
        assert_eq!(judged.len(), 2 * (8 + DWELL_TICKS), "every vote of the walk and the stay");
        assert_eq!(wrong, vec![&id("b"); 8], "b named the workstation all the way");
        // While it stays, each tick is judged as it comes.
        assert_eq!(h.learn(named(Assembly, Manufacturing), &[&still], &MAP), vec![(id("a"), true), (id("b"), false)]);
    }

    #[test]
    fn a_tick_on_which_nobody_named_the_station_is_not_judged() {
        let mut h = Hindsight::default();
        let walking = at(5.0, 0.0);
        for _ in 0..5 {
            h.learn(named(Workstation, Workstation), &[&walking], &MAP); // a change of mind
        }
        for _ in 0..3 {
            h.learn(named(Assembly, Workstation), &[&walking], &MAP);
        }
        let still = at(10.0, 0.0);
        let judged: Vec<_> =
            (0..DWELL_TICKS).flat_map(|_| h.learn(named(Assembly, Assembly), &[&still], &MAP)).collect();
        assert_eq!(judged.len(), 2 * (3 + DWELL_TICKS), "the five ticks nobody named assembly left out");
        assert_eq!(judged.iter().filter(|(_, ok)| !ok).count(), 3, "b, wrong while a was right");
    }

    #[test]
    fn a_pause_between_stations_or_an_unmapped_spot_judges_nothing() {
        let mut h = Hindsight::default();
        for _ in 0..3 * DWELL_TICKS {
            let between = at(5.0, 0.0); // standing still, 5 m from either station
            assert!(h.learn(named(Assembly, Workstation), &[&between], &MAP).is_empty());
        }
        let ambiguous = [Some([0.4, 0.0]), Some([0.0, 0.0]), None, None]; // storage beside the workstation
        for _ in 0..3 * DWELL_TICKS {
            assert!(h.learn(named(Assembly, Workstation), &[&at(0.2, 0.0)], &ambiguous).is_empty());
        }
    }

    #[test]
    fn a_tick_without_a_place_does_not_break_a_stay_and_a_step_away_does() {
        let mut h = Hindsight::default();
        let still = at(0.1, 0.0);
        for _ in 0..DWELL_TICKS - 1 {
            h.learn(named(Workstation, Workstation), &[&still], &MAP);
        }
        assert!(h.learn(named(Workstation, Workstation), &[], &MAP).is_empty(), "blind: kept, not judged");
        assert_eq!(h.learn(named(Workstation, Workstation), &[&still], &MAP).len(), 2 * (DWELL_TICKS + 1));
        let walking = at(0.8, 0.0);
        assert!(h.learn(named(Assembly, Workstation), &[&walking], &MAP).is_empty(), "left: a new walk");
    }

    #[test]
    fn votes_waiting_too_long_go_unjudged() {
        let mut h = Hindsight::default();
        let walking = at(5.0, 0.0);
        for _ in 0..MAX_PENDING + 50 {
            h.learn(named(Assembly, Workstation), &[&walking], &MAP);
        }
        let still = at(0.0, 0.0);
        let judged: Vec<_> =
            (0..DWELL_TICKS).flat_map(|_| h.learn(named(Workstation, Workstation), &[&still], &MAP)).collect();
        assert_eq!(judged.len(), 2 * MAX_PENDING);
    }
}
