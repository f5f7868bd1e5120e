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
//!   for [`YOUNG_TICKS`] after, a smaller id its peers place there (and no peer lists
//!   beside it) replaces it, so two robots that minted at once agree within a tick;
//! - a track the team names otherwise takes the team's name: each robot that places
//!   someone there has a word on who it is (a peer, the id its list gives the track by
//!   least total distance over the robot's tracks), the id most robots give wins, of
//!   ids given by as many the one the first-ranked robot gives; after
//!   [`CONFORM_TICKS`] ticks in a row against it, a robot renames its track, and a
//!   track of its own that held the new id takes the old one. So two people whom one
//!   robot's tracker swapped where they crossed are swapped back, and two ids that two
//!   robots gave one person become one, within a third of a second. Two people side by
//!   side keep their ids as long as one robot sees both (its list gives them apart).
//!
//! A person whom two robots' tracks confused and who then steps away is handed over
//! the same way: the track that follows them on keeps its id, the other one is new
//! and takes the id its peers give that person, or a fresh one. A robot that leaves
//! takes nothing with it: its ids live on in its peers' tracks.
//!
//! Every peer whose feed does not repeat itself names people here (the engine leaves
//! out the others); the trust votes earn does not filter them, since with several
//! workers two honest robots following different people disagree on votes while they
//! place everyone alike, and a robot that doubted its peers this way forgot where they
//! last placed a worker it lost. An admitted robot that lies about people can give a
//! person an id of its choosing where it is the only one to name them, and wins a tie
//! of words where it ranks first; it cannot outvote two honest robots. Ids are names
//! only, and nothing is decided by them yet.

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
/// For how many ticks a freshly minted id yields at once to a smaller one its peers
/// place there (1 s).
pub const YOUNG_TICKS: u32 = 10;
/// How many ticks longer each robot, by its place among the members, waits before it
/// mints an id for a person nobody names: one tick for a peer's share to arrive, one
/// to spare.
pub const MINT_STAGGER_TICKS: u64 = 2;
/// For how long an id nobody names any more may be taken again (10 s), and the
/// farthest from where it was last placed that it is taken, metres.
pub const RECALL_TICKS: u64 = 100;
pub const RECALL_M: f32 = 4.0;
/// For how many ticks in a row the team must name one of a robot's tracks otherwise
/// before the robot takes the team's name for it (0.3 s: a person placed between two
/// others for a tick or two does not change names).
pub const CONFORM_TICKS: u32 = 3;
/// A robot shares the people it saw within the last half second; a track kept longer
/// on prediction alone keeps its id but is not shared.
pub const SHARE_TICKS: u64 = 5;

/// One peer's latest list of the people it tracks, predicted to the tick named.
#[derive(Debug, Clone)]
pub struct PeerList<'a> {
    pub robot: &'a RobotId,
    pub people: Vec<PersonShare>,
}

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
    /// Tracks this robot minted an id for, and when: for [`YOUNG_TICKS`] the id yields
    /// at once to a smaller one its peers place there.
    minted: BTreeMap<u32, u64>,
    /// Tracks the team names otherwise: the id it gives, for how many ticks in a row.
    contradicted: BTreeMap<u32, (WorkerId, u32)>,
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
    pub fn name(&mut self, tick: u64, me: Minter, people: &People, peers: &[PeerList]) -> Vec<PersonShare> {
        self.named.retain(|t, _| people.holds(*t));
        self.contradicted.retain(|t, _| people.holds(*t));
        self.unnamed.retain(|t, _| people.holds(*t));
        self.minted.retain(|t, at| people.holds(*t) && tick.saturating_sub(*at) < u64::from(YOUNG_TICKS));
        let seen = people.seen_within(tick, SHARE_TICKS);
        self.conform(&seen, me.robot, peers);
        let peers: Vec<&[PersonShare]> = peers.iter().map(|p| p.people.as_slice()).collect();
        let peers = &peers[..];
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
        let lists: Vec<&[PersonShare]> = std::iter::once(&shared[..]).chain(peers.iter().copied()).collect();
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

    /// Gives each of this robot's unnamed tracks the id its peers place there, if any;
    /// and each track whose id it minted lately a smaller id its peers place there (two
    /// robots that minted for one person at once agree within a tick or two, rather
    /// than after [`YOUNG_TICKS`]).
    fn adopt(&mut self, seen: &[(u32, WorkerEstimate)], peers: &[&[PersonShare]]) {
        let new: Vec<&(u32, WorkerEstimate)> =
            seen.iter().filter(|(t, _)| !self.named.contains_key(t) || self.minted.contains_key(t)).collect();
        if new.is_empty() {
            return;
        }
        let held = self.held_by(seen);
        let free: Vec<Place> = places(peers).into_iter().filter(|p| !held.contains(&p.id)).collect();
        let from: Vec<[f32; 2]> = new.iter().map(|(_, e)| e.position).collect();
        let to: Vec<[f32; 2]> = free.iter().map(|p| p.at).collect();
        // Only a smaller id replaces a young one, and only one no peer lists beside it
        // (a peer that lists both sees two people).
        let apart = listed_together(peers);
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
    fn recall(&mut self, tick: u64, seen: &[(u32, WorkerEstimate)], peers: &[&[PersonShare]]) {
        let new: Vec<&(u32, WorkerEstimate)> = seen.iter().filter(|(t, _)| !self.named.contains_key(t)).collect();
        if new.is_empty() {
            return;
        }
        let mut named_now = self.held_by(seen);
        named_now.extend(peers.iter().flat_map(|l| l.iter()).map(|p| p.worker));
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

    /// Takes the team's name for each of this robot's tracks that the team has named
    /// otherwise for [`CONFORM_TICKS`] ticks in a row. Each robot that places someone
    /// where the track is has a word on who it is: this robot its own id, a peer the id
    /// its list gives the track when its people are assigned to all of this robot's
    /// tracks by least total distance, each pair within the adoption gate (so that of
    /// two people side by side each is given its own). The id most robots give wins; of ids given by as many, the one the first-ranked
    /// robot gives (robots ranked by id). A track renamed to an id another track of
    /// ours holds hands that track its old id: two people swapped on one robot's
    /// tracks are swapped back.
    fn conform(&mut self, seen: &[(u32, WorkerEstimate)], me: &RobotId, peers: &[PeerList]) {
        let mine: Vec<(u32, WorkerId, WorkerEstimate)> =
            seen.iter().filter_map(|(t, e)| Some((*t, *self.named.get(t)?, *e))).collect();
        let reach = |e: &WorkerEstimate, p: &PersonShare| {
            gate(3.0, e.covariance[0] + p.estimate.covariance[0], ADOPT_M, ADOPT_MAX_M)
        };
        // Each robot's word on each of our tracks: (robot, id), ours first.
        let mut words: Vec<Vec<(&RobotId, WorkerId)>> = mine.iter().map(|&(_, id, _)| vec![(me, id)]).collect();
        let from: Vec<[f32; 2]> = mine.iter().map(|(_, _, e)| e.position).collect();
        for peer in peers {
            let to: Vec<[f32; 2]> = peer.people.iter().map(|p| p.estimate.position).collect();
            let given = nearest_within(&from, &to, |j, i| reach(&mine[j].2, &peer.people[i]));
            for (j, word) in given.into_iter().enumerate() {
                words[j].extend(word.map(|i| (peer.robot, peer.people[i].worker)));
            }
        }
        let mut renames = Vec::new();
        for (&(t, id, _), words) in mine.iter().zip(&words) {
            let team = team_word(words);
            if team == id {
                self.contradicted.remove(&t);
                continue;
            }
            let streak = match self.contradicted.get(&t) {
                Some(&(w, n)) if w == team => n + 1,
                _ => 1,
            };
            self.contradicted.insert(t, (team, streak));
            if streak >= CONFORM_TICKS {
                renames.push((t, team));
            }
        }
        for (t, to) in renames {
            let Some(&from) = self.named.get(&t) else { continue };
            if let Some((&other, _)) = self.named.iter().find(|(_, w)| **w == to) {
                self.named.insert(other, from);
                self.contradicted.remove(&other);
            }
            self.named.insert(t, to);
            self.contradicted.remove(&t);
            self.minted.remove(&t);
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

/// The id most of `words` give; of ids given by as many, the one the first-ranked robot
/// giving any of them gives.
fn team_word(words: &[(&RobotId, WorkerId)]) -> WorkerId {
    let mut count: BTreeMap<WorkerId, (usize, &RobotId)> = BTreeMap::new();
    for &(robot, id) in words {
        let c = count.entry(id).or_insert((0, robot));
        c.0 += 1;
        c.1 = c.1.min(robot);
    }
    let best = count.iter().max_by(|a, b| a.1 .0.cmp(&b.1 .0).then_with(|| b.1 .1.cmp(a.1 .1)));
    *best.expect("a robot's own word at least").0
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

#[cfg(test)]
mod tests {
    use super::super::people::Seen;
    use super::*;

    fn distance(a: [f32; 2], b: [f32; 2]) -> f32 {
        ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt()
    }

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
        let before: Vec<(RobotId, Vec<PersonShare>)> =
            robots.iter().map(|r| (r.id.clone(), r.shared.clone())).collect();
        let mut ranks: Vec<&RobotId> = robots.iter().map(|r| &r.id).collect();
        ranks.sort();
        let ranks: Vec<usize> = robots.iter().map(|r| ranks.iter().position(|x| **x == r.id).unwrap()).collect();
        for (i, r) in robots.iter_mut().enumerate() {
            let places: Vec<Seen> = sees[i].iter().map(|&p| seen(p)).collect();
            r.people.observe(t, &places);
            let peers: Vec<PeerList> = before
                .iter()
                .enumerate()
                .filter(|(j, _)| heard && *j != i)
                .map(|(_, (robot, people))| PeerList { robot, people: people.clone() })
                .collect();
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
    fn two_settled_ids_for_one_person_become_the_first_ranked_robots_on_every_robot() {
        // Unheard for longer than an id stays young: the ids are settled, and become
        // one only after CONFORM_TICKS ticks of words against one of them.
        let mut robots = [Robot::new("a"), Robot::new("b")];
        let at = [2.0, 2.0];
        let quiet = u64::from(YOUNG_TICKS) + 5;
        for t in 0..quiet {
            tick_heard(&mut robots, t, &[vec![at], vec![at]], false);
        }
        let (ia, ib) = (robots[0].id_at(at).unwrap(), robots[1].id_at(at).unwrap());
        assert_ne!(ia, ib);
        let heard = quiet + u64::from(CONFORM_TICKS) - 1;
        for t in quiet..heard {
            tick(&mut robots, t, &[vec![at], vec![at]]);
        }
        assert_eq!((robots[0].id_at(at), robots[1].id_at(at)), (Some(ia), Some(ib)), "settled ids wait");
        tick(&mut robots, heard, &[vec![at], vec![at]]);
        assert_eq!((robots[0].id_at(at), robots[1].id_at(at)), (Some(ia), Some(ia)), "b took a's id");
    }

    #[test]
    fn two_people_side_by_side_keep_their_ids_while_one_robot_sees_both() {
        // p and q stand 0.4 m apart: a sees both, b only q, c
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

    /// Swaps the names of the two people robot `r` sees nearest `p` and `q`, as its own
    /// tracker would when they cross close to its camera.
    fn swap_names(r: &mut Robot, p: [f32; 2], q: [f32; 2]) {
        let (ip, iq) = (r.id_at(p).unwrap(), r.id_at(q).unwrap());
        for id in r.team.named.values_mut() {
            if *id == ip {
                *id = iq;
            } else if *id == iq {
                *id = ip;
            }
        }
    }

    /// Robots `names` (ranked by name) that have seen two people, p and q, 3 m apart
    /// for 2 s: the robots, the places and the names of p and q that robot `of` gives.
    #[allow(clippy::type_complexity)]
    fn settled_on_two(names: &[&str], of: usize) -> (Vec<Robot>, [[f32; 2]; 2], (Option<WorkerId>, Option<WorkerId>)) {
        let mut robots: Vec<Robot> = names.iter().map(|n| Robot::new(n)).collect();
        let (p, q) = ([2.0, 0.0], [2.0, 3.0]);
        for t in 0..20 {
            tick(&mut robots, t, &vec![vec![p, q]; names.len()]);
        }
        let team = (robots[of].id_at(p), robots[of].id_at(q));
        (robots, [p, q], team)
    }

    #[test]
    fn a_robot_whose_tracks_swapped_two_people_takes_the_teams_names_back() {
        let (mut robots, [p, q], team) = settled_on_two(&["a", "b", "c"], 0);
        let both = || vec![p, q];
        let names = |r: &Robot| (r.id_at(p), r.id_at(q));
        // a, ranked first, swaps: the other two outnumber it, and it takes their names.
        swap_names(&mut robots[0], p, q);
        for t in 20..20 + u64::from(CONFORM_TICKS) {
            tick(&mut robots, t, &[both(), both(), both()]);
            assert!(robots[1..].iter().all(|r| names(r) == team), "tick {t}: the others kept their names");
            if t == 20 {
                assert_eq!(names(&robots[0]), (team.1, team.0), "a shares the swapped names at first");
            }
        }
        assert_eq!(names(&robots[0]), team, "a took the team's names back");
    }

    #[test]
    fn of_two_robots_that_name_two_people_crosswise_the_second_ranked_takes_the_firsts_names() {
        let (mut robots, [p, q], team) = settled_on_two(&["a", "b"], 0);
        let both = || vec![p, q];
        let names = |r: &Robot| (r.id_at(p), r.id_at(q));
        swap_names(&mut robots[1], p, q);
        for t in 20..20 + u64::from(CONFORM_TICKS) + 2 {
            tick(&mut robots, t, &[both(), both()]);
            assert_eq!(names(&robots[0]), team, "tick {t}: a, ranked first, keeps its names");
            if t == 20 {
                assert_eq!(names(&robots[1]), (team.1, team.0), "b shares the swapped names at first");
            }
        }
        assert_eq!(names(&robots[1]), team, "b took a's names");
    }

    #[test]
    fn a_peer_that_lists_two_people_crosswise_cannot_outvote_two_honest_robots() {
        // "0z" ranks first and, from tick 20 on, lists p under q's id and q under p's.
        let (mut robots, [p, q], team) = settled_on_two(&["0z", "a", "b"], 1);
        let both = || vec![p, q];
        let names = |r: &Robot| (r.id_at(p), r.id_at(q));
        for t in 20..60 {
            tick(&mut robots, t, &[both(), both(), both()]);
            for s in robots[0].shared.iter_mut() {
                s.worker = if Some(s.worker) == team.0 { team.1.unwrap() } else { team.0.unwrap() };
            }
            assert!(robots[1..].iter().all(|r| names(r) == team), "tick {t}: the liar renamed them");
        }
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
