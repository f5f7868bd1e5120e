//! Who is who across the team: one id per person, the same on every robot.
//!
//! Each robot tracks everyone it sees under track ids of its own ([`super::people`]),
//! which mean nothing to a peer. For the team to say anything of one worker among
//! several, every robot must name each person alike. No robot hands the ids out (a
//! robot that did would be one the team could not do without): each derives them by
//! the same rules from what the others share — every embedding message lists the
//! people its robot tracks, each under the id the robot gives it:
//!
//! - a track keeps its id for as long as the robot holds it;
//! - a new track takes the id under which the peers place someone there: nearest
//!   within a gate as wide as the places are unsure ([`ADOPT_M`]–[`ADOPT_MAX_M`]), by
//!   least total distance over all new tracks, never an id the robot gives another
//!   track it sees;
//! - a new track no peer names now takes an id nobody names any more, if one was last
//!   placed near enough for a walk since ([`ADOPT_M`] plus [`WALK_M_PER_TICK`] a tick,
//!   at most [`RECALL_M`]; ids named in the last [`RECALL_TICKS`]): a worker lost from
//!   every view for a while and found again is the same worker;
//! - a new track nobody names is given a fresh id, minted from the robot's id, its
//!   instance and the track — not at once, but after a wait that grows with the
//!   robot's place among the members ([`MINT_STAGGER_TICKS`] each), so that robots
//!   that see a newcomer together take the first one's id rather than each mint one;
//!   for [`MERGE_TICKS`] after, a smaller id its peers place there (and no peer lists
//!   beside it) replaces it, so two robots that minted at once agree within a tick;
//! - two ids that name one person — their places within [`MERGE_M`] of each other (more
//!   when they are unsure, up to [`MERGE_MAX_M`]) for [`MERGE_TICKS`] ticks in a row,
//!   and no robot listing both at once — become one:
//!   the id more robots name (a robot's fresh id yields to the one its team has used),
//!   of two named alike the smaller. Two people side by side keep their ids as long
//!   as one robot sees both.
//!
//! A person whom two robots' tracks confused and who then steps away is handed over
//! the same way: the track that follows them on keeps its id, the other one is new
//! and takes the id its peers give that person, or a fresh one. A robot that leaves
//! takes nothing with it: its ids live on in its peers' tracks.
//!
//! Only the peers whose word the robot fuses into its track of the worker name people
//! here (the engine filters them): a robot it doubts, or whose feed repeats itself,
//! cannot rename anyone. An admitted robot that lies about people can still give a
//! person an id of its choosing where it is the only one to name them, or delay a
//! merge; ids are names only, and nothing is decided by them yet.

use super::people::{nearest_within, People, WALK_M_PER_TICK};
use crate::hash::Fnv1a;
use spwi_proto::{PersonShare, RobotId, WorkerEstimate, WorkerId, MAX_HUMANS};
use std::collections::{BTreeMap, BTreeSet};

/// How far from where its peers place a person a new track may start and still be
/// that person, metres: three standard deviations of the two places' difference, at
/// least [`ADOPT_M`] and at most [`ADOPT_MAX_M`] (a person seen far off is placed less
/// surely).
pub const ADOPT_M: f32 = 1.0;
pub const ADOPT_MAX_M: f32 = 2.5;
/// How close two ids' people stand, metres, to be one person: two standard deviations
/// of the places' difference, at least [`MERGE_M`] and at most [`MERGE_MAX_M`] (two
/// workers side by side at a station stand a metre apart or more).
pub const MERGE_M: f32 = 0.5;
pub const MERGE_MAX_M: f32 = 0.9;
/// For how many ticks in a row two ids' people must stand that close (1 s: people who
/// pass each other do not stay within half a metre for a second).
pub const MERGE_TICKS: u32 = 10;
/// How many ticks longer each robot, by its place among the members, waits before it
/// mints an id for a person nobody names: one tick for a peer's share to arrive, one
/// to spare.
pub const MINT_STAGGER_TICKS: u64 = 2;
/// For how long an id nobody names any more may be taken again (10 s), and the
/// farthest from where it was last placed that it is taken, metres.
pub const RECALL_TICKS: u64 = 100;
pub const RECALL_M: f32 = 4.0;
/// A robot shares the people it saw within the last half second; a track kept longer
/// on prediction alone keeps its id but is not shared.
pub const SHARE_TICKS: u64 = 5;

/// Who is minting: this robot, its instance, and its place among the live members.
#[derive(Debug, Clone, Copy)]
pub struct Minter<'a> {
    pub robot: &'a RobotId,
    pub instance: u64,
    pub rank: usize,
}

impl Minter<'_> {
    fn mint(&self, track: u32) -> WorkerId {
        let mut h = Fnv1a::default();
        h.eat(self.robot.as_str().as_bytes());
        h.eat(&[0]);
        h.eat(&self.instance.to_le_bytes());
        h.eat(&track.to_le_bytes());
        WorkerId(h.0)
    }
}

/// The team's id of each person one robot tracks.
#[derive(Debug, Clone, Default)]
pub struct WorkerIds {
    /// Track id → team id.
    named: BTreeMap<u32, WorkerId>,
    /// Tracks nobody has named yet, since the tick they were first seen.
    unnamed: BTreeMap<u32, u64>,
    /// Tracks this robot minted an id for, and when: for [`MERGE_TICKS`] the id yields
    /// at once to a smaller one its peers place there.
    minted: BTreeMap<u32, u64>,
    /// Pairs of ids (smaller first) whose people stood within [`MERGE_M`], and for how
    /// many ticks in a row.
    close: BTreeMap<(WorkerId, WorkerId), u32>,
    /// What the robot last shared, and of which tick.
    shared: (u64, Vec<PersonShare>),
    /// Where each id named in the last [`RECALL_TICKS`] was last placed, and when.
    recent: BTreeMap<WorkerId, (u64, [f32; 2])>,
}

impl WorkerIds {
    /// Names the people of `tick`: `people`, this robot's tracks; `peers`, each peer's
    /// latest list, predicted to `tick`. Returns what this robot shares: each person it
    /// saw within [`SHARE_TICKS`] and has named, with its estimate (at most
    /// [`MAX_HUMANS`]).
    pub fn name(&mut self, tick: u64, me: Minter, people: &People, peers: &[Vec<PersonShare>]) -> Vec<PersonShare> {
        self.named.retain(|t, _| people.holds(*t));
        self.unnamed.retain(|t, _| people.holds(*t));
        self.minted.retain(|t, at| people.holds(*t) && tick.saturating_sub(*at) < u64::from(MERGE_TICKS));
        let seen = people.seen_within(tick, SHARE_TICKS);
        let mine: Vec<PersonShare> =
            seen.iter().filter_map(|(t, e)| Some(PersonShare { worker: *self.named.get(t)?, estimate: *e })).collect();
        self.merge(&mine, peers);
        self.adopt(&seen, peers);
        self.recall(tick, &seen, peers);
        for (t, _) in &seen {
            if self.named.contains_key(t) {
                continue;
            }
            let since = *self.unnamed.entry(*t).or_insert(tick);
            if tick - since >= me.rank as u64 * MINT_STAGGER_TICKS {
                self.unnamed.remove(t);
                self.named.insert(*t, me.mint(*t));
                self.minted.insert(*t, tick);
            }
        }
        let shared: Vec<PersonShare> = seen
            .iter()
            .filter_map(|(t, e)| Some(PersonShare { worker: *self.named.get(t)?, estimate: *e }))
            .take(MAX_HUMANS)
            .collect();
        self.shared = (tick, shared.clone());
        let lists: Vec<&[PersonShare]> = std::iter::once(&shared[..]).chain(peers.iter().map(Vec::as_slice)).collect();
        for p in places(&lists) {
            self.recent.insert(p.id, (tick, p.at));
        }
        self.recent.retain(|_, (t, _)| tick.saturating_sub(*t) <= RECALL_TICKS);
        shared
    }

    /// The people this robot last shared, and the tick it shared them for.
    pub fn shared(&self) -> (u64, &[PersonShare]) {
        (self.shared.0, &self.shared.1)
    }

    /// The team id this robot gives track `track`, if any.
    pub fn of_track(&self, track: u32) -> Option<WorkerId> {
        self.named.get(&track).copied()
    }

    /// Counts the ticks each pair of ids has stood together, and renames this robot's
    /// tracks under an id that has stood long enough beside a smaller one.
    fn merge(&mut self, mine: &[PersonShare], peers: &[Vec<PersonShare>]) {
        let lists: Vec<&[PersonShare]> = std::iter::once(mine).chain(peers.iter().map(Vec::as_slice)).collect();
        let places = places(&lists);
        let listed_together = listed_together(&lists);
        let mut close = BTreeMap::new();
        for (i, a) in places.iter().enumerate() {
            for b in &places[i + 1..] {
                let near = distance(a.at, b.at) <= gate(2.0, a.var + b.var, MERGE_M, MERGE_MAX_M);
                if near && !listed_together.contains(&(a.id, b.id)) {
                    close.insert((a.id, b.id), self.close.get(&(a.id, b.id)).copied().unwrap_or(0) + 1);
                }
            }
        }
        self.close = close;
        // Of two ids that stood together long enough, the one more robots name stays
        // (a robot's fresh id yields to the one its team has used), else the smaller.
        let naming = |id: WorkerId| lists.iter().filter(|l| l.iter().any(|p| p.worker == id)).count();
        let mut into: BTreeMap<WorkerId, WorkerId> = BTreeMap::new();
        let settled = |into: &BTreeMap<WorkerId, WorkerId>, mut id: WorkerId| {
            while let Some(&to) = into.get(&id) {
                id = to;
            }
            id
        };
        for (&(a, b), &n) in &self.close {
            if n >= MERGE_TICKS {
                let (gone, kept) = if naming(b) > naming(a) { (a, b) } else { (b, a) };
                let (gone, kept) = (settled(&into, gone), settled(&into, kept));
                if gone != kept {
                    into.insert(gone, kept);
                }
            }
        }
        let held: BTreeSet<WorkerId> = self.named.values().copied().collect();
        for id in self.named.values_mut() {
            let to = settled(&into, *id);
            if to != *id && !held.contains(&to) {
                *id = to;
            }
        }
    }

    /// Gives each of this robot's unnamed tracks the id its peers place there, if any;
    /// and each track whose id it minted lately a smaller id its peers place there (two
    /// robots that minted for one person at once agree within a tick or two, rather
    /// than after [`MERGE_TICKS`]).
    fn adopt(&mut self, seen: &[(u32, WorkerEstimate)], peers: &[Vec<PersonShare>]) {
        let new: Vec<&(u32, WorkerEstimate)> =
            seen.iter().filter(|(t, _)| !self.named.contains_key(t) || self.minted.contains_key(t)).collect();
        if new.is_empty() {
            return;
        }
        let held = self.held_by(seen);
        let lists: Vec<&[PersonShare]> = peers.iter().map(Vec::as_slice).collect();
        let free: Vec<Place> = places(&lists).into_iter().filter(|p| !held.contains(&p.id)).collect();
        let from: Vec<[f32; 2]> = new.iter().map(|(_, e)| e.position).collect();
        let to: Vec<[f32; 2]> = free.iter().map(|p| p.at).collect();
        // Only a smaller id replaces a young one, and only one no peer lists beside it
        // (a peer that lists both sees two people).
        let apart = listed_together(&lists);
        let reach = |j: usize, i: usize| match self.named.get(&new[j].0) {
            Some(&young) if free[i].id > young || apart.contains(&(free[i].id, young)) => -1.0,
            _ => gate(3.0, new[j].1.covariance[0] + free[i].var, ADOPT_M, ADOPT_MAX_M),
        };
        for ((t, _), a) in new.iter().zip(nearest_within(&from, &to, reach)) {
            if let Some(i) = a {
                self.give(*t, free[i].id);
            }
        }
    }
}

impl WorkerIds {
    /// Gives each of this robot's tracks still unnamed an id nobody names now, if one
    /// was last placed near enough for the person to have walked here since.
    fn recall(&mut self, tick: u64, seen: &[(u32, WorkerEstimate)], peers: &[Vec<PersonShare>]) {
        let new: Vec<&(u32, WorkerEstimate)> = seen.iter().filter(|(t, _)| !self.named.contains_key(t)).collect();
        if new.is_empty() {
            return;
        }
        let mut named_now = self.held_by(seen);
        named_now.extend(peers.iter().flatten().map(|p| p.worker));
        let gone: Vec<(WorkerId, u64, [f32; 2])> =
            self.recent.iter().filter(|(id, _)| !named_now.contains(id)).map(|(id, (t, at))| (*id, *t, *at)).collect();
        let from: Vec<[f32; 2]> = new.iter().map(|(_, e)| e.position).collect();
        let to: Vec<[f32; 2]> = gone.iter().map(|(_, _, at)| *at).collect();
        let reach =
            |_: usize, i: usize| (ADOPT_M + WALK_M_PER_TICK * tick.saturating_sub(gone[i].1) as f32).min(RECALL_M);
        for ((t, _), a) in new.iter().zip(nearest_within(&from, &to, reach)) {
            if let Some(i) = a {
                self.give(*t, gone[i].0);
            }
        }
    }

    /// The ids of the tracks among `seen`: a track kept on prediction alone, not seen
    /// lately, holds its id only until a track that sees the person takes it.
    fn held_by(&self, seen: &[(u32, WorkerEstimate)]) -> BTreeSet<WorkerId> {
        seen.iter().filter_map(|(t, _)| self.named.get(t).copied()).collect()
    }

    /// Names `track` `id`, taking the id from a track of ours that held it unseen.
    fn give(&mut self, track: u32, id: WorkerId) {
        self.named.retain(|_, w| *w != id);
        self.named.insert(track, id);
        self.unnamed.remove(&track);
        self.minted.remove(&track);
    }
}

/// Where the lists place one id: on average, and how surely (the position variance of
/// the surest list, m²).
#[derive(Debug, Clone, Copy)]
struct Place {
    id: WorkerId,
    at: [f32; 2],
    var: f32,
}

/// Where the lists place each id, sorted by id.
fn places(lists: &[&[PersonShare]]) -> Vec<Place> {
    let mut sum: BTreeMap<WorkerId, ([f32; 2], f32, f32)> = BTreeMap::new();
    for p in lists.iter().flat_map(|l| l.iter()) {
        let s = sum.entry(p.worker).or_insert(([0.0; 2], 0.0, f32::INFINITY));
        s.0[0] += p.estimate.position[0];
        s.0[1] += p.estimate.position[1];
        s.1 += 1.0;
        s.2 = s.2.min(p.estimate.covariance[0]);
    }
    sum.into_iter().map(|(id, (p, n, var))| Place { id, at: [p[0] / n, p[1] / n], var }).collect()
}

/// The pairs of ids some list names both of (smaller first): two people.
fn listed_together(lists: &[&[PersonShare]]) -> BTreeSet<(WorkerId, WorkerId)> {
    lists
        .iter()
        .flat_map(|l| l.iter().flat_map(move |a| l.iter().map(move |b| (a.worker, b.worker))))
        .filter(|(a, b)| a < b)
        .collect()
}

/// How far apart two places of one person may be, given how surely each is placed:
/// `k` standard deviations of their difference, within `[least, most]` metres.
fn gate(k: f32, var: f32, least: f32, most: f32) -> f32 {
    (k * var.sqrt()).clamp(least, most)
}

fn distance(a: [f32; 2], b: [f32; 2]) -> f32 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt()
}

#[cfg(test)]
mod tests {
    use super::super::people::Seen;
    use super::*;

    /// One robot of a simulated team: its tracks and its names for them.
    struct Robot {
        id: RobotId,
        people: People,
        team: WorkerIds,
        shared: Vec<PersonShare>,
    }

    impl Robot {
        fn new(name: &str) -> Robot {
            Robot {
                id: RobotId::new(name).unwrap(),
                people: People::default(),
                team: WorkerIds::default(),
                shared: Vec::new(),
            }
        }

        /// This robot's id for whoever stands nearest `at`.
        fn id_at(&self, at: [f32; 2]) -> Option<WorkerId> {
            self.shared
                .iter()
                .min_by(|a, b| distance(a.estimate.position, at).total_cmp(&distance(b.estimate.position, at)))
                .map(|p| p.worker)
        }
    }

    fn seen(at: [f32; 2]) -> Seen {
        Seen { floor: at, sigma: 0.1, detector_id: None }
    }

    /// One tick of a team: each robot sees `sees[r]` and names them from the others'
    /// lists of the tick before (one tick of delay, as on the wire).
    fn tick(robots: &mut [Robot], t: u64, sees: &[Vec<[f32; 2]>]) {
        tick_heard(robots, t, sees, true)
    }

    /// [`tick`], the robots hearing each other (`heard`) or not.
    fn tick_heard(robots: &mut [Robot], t: u64, sees: &[Vec<[f32; 2]>], heard: bool) {
        let before: Vec<Vec<PersonShare>> = robots.iter().map(|r| r.shared.clone()).collect();
        let mut ranks: Vec<&RobotId> = robots.iter().map(|r| &r.id).collect();
        ranks.sort();
        let ranks: Vec<usize> = robots.iter().map(|r| ranks.iter().position(|x| **x == r.id).unwrap()).collect();
        for (i, r) in robots.iter_mut().enumerate() {
            let places: Vec<Seen> = sees[i].iter().map(|&p| seen(p)).collect();
            r.people.observe(t, &places);
            let peers: Vec<Vec<PersonShare>> =
                before.iter().enumerate().filter(|(j, _)| heard && *j != i).map(|(_, l)| l.clone()).collect();
            let me = Minter { robot: &r.id, instance: 1, rank: ranks[i] };
            r.shared = r.team.name(t, me, &r.people, &peers);
        }
    }

    #[test]
    fn robots_that_see_the_same_two_people_name_them_alike_and_keep_the_names() {
        let mut robots = [Robot::new("a"), Robot::new("b"), Robot::new("c")];
        let p = |t: u64| [1.0 + 0.1 * t as f32, 0.0];
        let q = |t: u64| [5.0, 3.0 - 0.05 * t as f32];
        let mut first = None;
        for t in 0..60 {
            let both = vec![p(t), q(t)];
            tick(&mut robots, t, &[both.clone(), both.clone(), both.clone()]);
            if t >= 10 {
                let ids: Vec<(Option<WorkerId>, Option<WorkerId>)> =
                    robots.iter().map(|r| (r.id_at(p(t)), r.id_at(q(t)))).collect();
                assert!(ids.iter().all(|x| *x == ids[0]), "tick {t}: {ids:?}");
                assert_ne!(ids[0].0, ids[0].1, "two people, two ids");
                assert_eq!(*first.get_or_insert(ids[0]), ids[0], "tick {t}: the ids changed");
            }
        }
        // The first robot minted both; the others took its ids without minting.
        let minted_by_a = |t: u32| Minter { robot: &robots[0].id, instance: 1, rank: 0 }.mint(t);
        let (ip, iq) = first.unwrap();
        assert!([ip, iq].iter().all(|i| i.is_some_and(|i| i == minted_by_a(0) || i == minted_by_a(1))));
    }

    #[test]
    fn two_ids_minted_for_one_person_at_once_become_the_smaller_within_two_ticks() {
        // a and b see the person while their messages are lost: each mints an id.
        let mut robots = [Robot::new("a"), Robot::new("b")];
        let at = [2.0, 2.0];
        for t in 0..4 {
            tick_heard(&mut robots, t, &[vec![at], vec![at]], false);
        }
        let (ia, ib) = (robots[0].id_at(at).unwrap(), robots[1].id_at(at).unwrap());
        assert_ne!(ia, ib);
        // Young ids yield to a smaller one at once.
        for t in 4..6 {
            tick(&mut robots, t, &[vec![at], vec![at]]);
        }
        let smaller = Some(ia.min(ib));
        assert_eq!((robots[0].id_at(at), robots[1].id_at(at)), (smaller, smaller));
    }

    #[test]
    fn two_ids_that_stand_together_for_a_second_become_one_on_every_robot() {
        // Unheard for longer than an id stays young: the ids are settled, and become
        // one only after standing together for MERGE_TICKS.
        let mut robots = [Robot::new("a"), Robot::new("b")];
        let at = [2.0, 2.0];
        let quiet = MERGE_TICKS as u64 + 5;
        for t in 0..quiet {
            tick_heard(&mut robots, t, &[vec![at], vec![at]], false);
        }
        let (ia, ib) = (robots[0].id_at(at).unwrap(), robots[1].id_at(at).unwrap());
        for t in quiet..quiet + 3 {
            tick(&mut robots, t, &[vec![at], vec![at]]);
        }
        assert_eq!((robots[0].id_at(at), robots[1].id_at(at)), (Some(ia), Some(ib)), "settled ids wait");
        for t in quiet + 3..quiet + MERGE_TICKS as u64 + 2 {
            tick(&mut robots, t, &[vec![at], vec![at]]);
        }
        let smaller = Some(ia.min(ib));
        assert_eq!((robots[0].id_at(at), robots[1].id_at(at)), (smaller, smaller));
    }

    #[test]
    fn two_people_side_by_side_keep_their_ids_while_one_robot_sees_both() {
        // p and q stand 0.4 m apart, closer than MERGE_M: a sees both, b only q, c
        // only p (so whichever id is the larger, one robot alone holds it).
        let mut robots = [Robot::new("a"), Robot::new("b"), Robot::new("c")];
        let (p, q) = ([3.0, 0.0], [3.0, 0.4]);
        for t in 0..40 {
            tick(&mut robots, t, &[vec![p, q], vec![q], vec![p]]);
        }
        let (ip, iq) = (robots[0].id_at(p), robots[0].id_at(q));
        assert_ne!(ip, iq, "a merged the two people it sees");
        assert_eq!((robots[1].id_at(q), robots[2].id_at(p)), (iq, ip), "b and c name them as a does");
    }

    #[test]
    fn a_robot_that_joins_takes_the_teams_ids_and_they_outlive_the_robot_that_minted_them() {
        let mut robots = vec![Robot::new("a"), Robot::new("b")];
        let at = |t: u64| [0.1 * t as f32, 1.0];
        for t in 0..10 {
            tick(&mut robots, t, &[vec![at(t)], vec![at(t)]]);
        }
        let id = robots[0].id_at(at(9)).unwrap();
        // c joins, ranked first among the members ("0c" < "a"): it still adopts.
        robots.push(Robot::new("0c"));
        for t in 10..20 {
            tick(&mut robots, t, &[vec![at(t)], vec![at(t)], vec![at(t)]]);
        }
        assert_eq!(robots[2].id_at(at(19)), Some(id), "the newcomer minted its own");
        // a, which minted the id, leaves; b and c keep it.
        robots.remove(0);
        for t in 20..40 {
            tick(&mut robots, t, &[vec![at(t)], vec![at(t)]]);
        }
        assert!(robots.iter().all(|r| r.id_at(at(39)) == Some(id)));
    }

    #[test]
    fn a_person_who_steps_away_from_a_confused_track_is_handed_the_id_the_team_gives_them() {
        // b sees p and q apart all along; a sees them as one (too close for its view),
        // then q steps away: a's new track takes q's id, not a new one.
        let mut robots = [Robot::new("a"), Robot::new("b")];
        let p = [4.0, 0.0];
        let q = |t: u64| if t < 20 { [4.0, 0.6] } else { [4.0, 0.6 + 0.1 * (t - 20) as f32] };
        for t in 0..40 {
            let a_sees = if t < 20 { vec![p] } else { vec![p, q(t)] };
            tick(&mut robots, t, &[a_sees, vec![p, q(t)]]);
        }
        assert_eq!(robots[0].id_at(q(39)), robots[1].id_at(q(39)));
        assert_eq!(robots[0].id_at(p), robots[1].id_at(p));
        assert_ne!(robots[0].id_at(p), robots[0].id_at(q(39)));
    }
}
