//! Everyone a robot sees, tracked on the floor.
//!
//! A frame lists every person the detector found (up to eight). To know who is who
//! from one tick to the next, also while the detector's own track ids are missing or
//! change, a robot keeps a floor track per person: each tick the people of its frame,
//! placed on the floor, are assigned to the tracks it holds by least total distance
//! from where each track predicts its person, within [`GATE_M`] (the Hungarian method,
//! `pathfinding`'s Kuhn–Munkres). A person left unassigned starts a track; a track not
//! seen for [`MAX_GAP_TICKS`] ends. The detector's id, when it has one, is a cue: a
//! person keeping the id a track last had is assigned to it before distance counts.
//!
//! Track ids are this robot's own: they mean nothing to a peer.

use super::track::{Track, MAX_GAP_TICKS};
use pathfinding::kuhn_munkres::kuhn_munkres;
use pathfinding::matrix::Matrix;
use spwi_proto::WorkerEstimate;

/// How far from where its track predicts a person a detection may be and still be
/// that person, metres (a person walks ≈ 1.3 m/s; detections on the floor are ± 0.3 m).
pub const GATE_M: f32 = 1.5;
/// How far a person may walk in a tick, metres (a brisk 1.5 m/s): the gate of a track
/// not seen for a while grows by this much a tick, since its prediction may have
/// walked on while its person stopped, or the other way round.
pub const WALK_M_PER_TICK: f32 = 0.15;

/// One person in view: where the detector's person stands on the floor, how sure
/// that place is (standard deviation, m), and the detector's track id if any.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Seen {
    pub floor: [f32; 2],
    pub sigma: f32,
    pub detector_id: Option<u32>,
}

/// One tracked person.
#[derive(Debug, Clone)]
struct Person {
    id: u32,
    track: Track,
    last_seen: u64,
    detector_id: Option<u32>,
}

/// The people one robot tracks.
#[derive(Debug, Clone, Default)]
pub struct People {
    people: Vec<Person>,
    next_id: u32,
}

impl People {
    /// Which held track each of `seen` at `tick` belongs to (`None`: nobody's yet),
    /// without changing anything: what [`People::observe`] would assign.
    pub fn assign(&self, tick: u64, seen: &[Seen]) -> Vec<Option<u32>> {
        let live: Vec<(&Person, WorkerEstimate)> =
            self.people.iter().filter_map(|p| Some((p, p.track.estimate(tick)?))).collect();
        let mut out = vec![None; seen.len()];
        let mut taken = vec![false; live.len()];
        // The detector's word first: the id a track last had, kept, is the same person
        // (while it stands within the gate: ids are reused after a person leaves).
        for (s, o) in seen.iter().zip(out.iter_mut()) {
            let Some(d) = s.detector_id else { continue };
            if let Some(i) = (0..live.len())
                .find(|&i| !taken[i] && live[i].0.detector_id == Some(d) && distance(&live[i].1, s.floor) <= GATE_M)
            {
                taken[i] = true;
                *o = Some(live[i].0.id);
            }
        }
        // Then the least total distance over the rest.
        let rows: Vec<usize> = (0..seen.len()).filter(|&j| out[j].is_none()).collect();
        let cols: Vec<usize> = (0..live.len()).filter(|&i| !taken[i]).collect();
        let places: Vec<[f32; 2]> = rows.iter().map(|&j| seen[j].floor).collect();
        let tracks: Vec<[f32; 2]> = cols.iter().map(|&i| live[i].1.position).collect();
        // A detection far off is placed less surely: the gate is at least three of its
        // standard deviations wide.
        let gate = |r: usize, c: usize| {
            let unseen = tick.saturating_sub(live[cols[c]].0.last_seen) as f32;
            GATE_M.max(3.0 * seen[rows[r]].sigma) + WALK_M_PER_TICK * unseen
        };
        for (&j, a) in rows.iter().zip(nearest_within(&places, &tracks, gate)) {
            out[j] = a.map(|c| live[cols[c]].0.id);
        }
        out
    }

    /// Takes in the people of `tick`; returns the track id of each.
    pub fn observe(&mut self, tick: u64, seen: &[Seen]) -> Vec<u32> {
        let assigned = self.assign(tick, seen);
        let ids = assigned
            .iter()
            .zip(seen)
            .map(|(a, s)| {
                let id = a.unwrap_or_else(|| {
                    let id = self.next_id;
                    self.next_id = self.next_id.wrapping_add(1);
                    self.people.push(Person { id, track: Track::default(), last_seen: tick, detector_id: None });
                    id
                });
                let p = self.people.iter_mut().find(|p| p.id == id).expect("assigned or just made");
                p.track.observe(tick, s.floor, s.sigma);
                (p.last_seen, p.detector_id) = (tick, s.detector_id);
                id
            })
            .collect();
        self.people.retain(|p| tick.saturating_sub(p.last_seen) <= MAX_GAP_TICKS);
        ids
    }

    /// Where track `id` puts its person at `tick`, while it is fresh.
    pub fn estimate(&self, id: u32, tick: u64) -> Option<WorkerEstimate> {
        self.people.iter().find(|p| p.id == id)?.track.estimate(tick)
    }

    /// Every person tracked whom this robot saw within the last `within` ticks of
    /// `tick`: (track id, where the track puts the person at `tick`).
    pub fn seen_within(&self, tick: u64, within: u64) -> Vec<(u32, WorkerEstimate)> {
        self.people
            .iter()
            .filter(|p| p.last_seen <= tick && tick - p.last_seen <= within)
            .filter_map(|p| Some((p.id, p.track.estimate(tick)?)))
            .collect()
    }

    /// Whether track `id` is still held.
    pub fn holds(&self, id: u32) -> bool {
        self.people.iter().any(|p| p.id == id)
    }

    /// How many people are tracked.
    pub fn len(&self) -> usize {
        self.people.len()
    }

    pub fn is_empty(&self) -> bool {
        self.people.is_empty()
    }
}

/// Which of `to` each of `from` is, by least total distance, a pair never made farther
/// apart than its gate (`gate(j, i)` for `from[j]` and `to[i]`, metres): the Hungarian
/// method (`pathfinding`'s Kuhn–Munkres), each of `to` given at most once.
pub(super) fn nearest_within(
    from: &[[f32; 2]],
    to: &[[f32; 2]],
    gate: impl Fn(usize, usize) -> f32,
) -> Vec<Option<usize>> {
    let mut out = vec![None; from.len()];
    if from.is_empty() || to.is_empty() {
        return out;
    }
    // Kuhn–Munkres maximises integer weights and wants no more rows than columns: the
    // weight of a pair is how much nearer than the widest gate it is, in millimetres
    // (the same for every pair, so that a wide gate lets a pair be made but does not
    // favour it); pairs outside their gate weigh nothing and are not kept.
    let widest = (0..from.len())
        .flat_map(|j| (0..to.len()).map(move |i| (j, i)))
        .map(|(j, i)| gate(j, i))
        .fold(0.0f32, f32::max);
    let weight = |j: usize, i: usize| -> i64 {
        let d = ((from[j][0] - to[i][0]).powi(2) + (from[j][1] - to[i][1]).powi(2)).sqrt();
        if d <= gate(j, i) {
            ((widest - d) * 1000.0) as i64 + 1
        } else {
            0
        }
    };
    let transposed = from.len() > to.len();
    let (n_rows, n_cols) = if transposed { (to.len(), from.len()) } else { (from.len(), to.len()) };
    let pair = |r: usize, c: usize| if transposed { (c, r) } else { (r, c) };
    let mut m = Matrix::new(n_rows, n_cols, 0i64);
    for r in 0..n_rows {
        for c in 0..n_cols {
            let (j, i) = pair(r, c);
            m[(r, c)] = weight(j, i);
        }
    }
    let (_, assigned) = kuhn_munkres(&m);
    for (r, c) in assigned.into_iter().enumerate() {
        let (j, i) = pair(r, c);
        if weight(j, i) > 0 {
            out[j] = Some(i);
        }
    }
    out
}

fn distance(e: &WorkerEstimate, z: [f32; 2]) -> f32 {
    ((e.position[0] - z[0]).powi(2) + (e.position[1] - z[1]).powi(2)).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn seen(x: f32, y: f32) -> Seen {
        Seen { floor: [x, y], sigma: 0.2, detector_id: None }
    }

    #[test]
    fn two_people_walking_past_each_other_keep_their_tracks() {
        // A walks east along y = 0, B west along y = 0.6: they pass within 0.6 m, and
        // the nearest-detection rule would swap them at the crossing.
        let mut people = People::default();
        let mut first = None;
        for t in 0..40u64 {
            let x = t as f32 * 0.12;
            let (a, b) = (seen(x, 0.0), seen(4.8 - x, 0.6));
            // the detector lists them in either order
            let ids = if t % 2 == 0 {
                people.observe(t, &[a, b])
            } else {
                people.observe(t, &[b, a]).into_iter().rev().collect()
            };
            let first = first.get_or_insert_with(|| ids.clone());
            assert_eq!(&ids, first, "tick {t}: A and B keep their own tracks");
        }
        assert_eq!(people.len(), 2);
    }

    #[test]
    fn a_newcomer_gets_a_new_track_and_a_person_gone_for_two_seconds_ends_hers() {
        let mut people = People::default();
        let a = people.observe(0, &[seen(0.0, 0.0)])[0];
        let ids = people.observe(1, &[seen(0.1, 0.0), seen(5.0, 5.0)]);
        assert_eq!(ids[0], a);
        assert_ne!(ids[1], a, "someone 7 m away is somebody else");
        for t in 2..=(2 + MAX_GAP_TICKS) {
            people.observe(t, &[seen(5.0, 5.0)]);
        }
        assert_eq!(people.len(), 1, "A, unseen for 2 s, is no longer tracked");
        assert_eq!(people.estimate(a, 2 + MAX_GAP_TICKS), None);
    }

    #[test]
    fn the_detectors_id_keeps_a_person_whom_distance_alone_would_hand_to_another() {
        let mut people = People::default();
        let with = |x: f32, id: u32| Seen { floor: [x, 0.0], sigma: 0.2, detector_id: Some(id) };
        let ids = people.observe(0, &[with(0.0, 7), with(1.0, 9)]);
        // Both step to about where the other was: distance alone would swap them.
        let next = people.observe(1, &[with(0.9, 7), with(0.1, 9)]);
        assert_eq!(next, ids, "the detector's ids decide");
        // Without ids, distance decides.
        let next = people.observe(2, &[seen(0.95, 0.0), seen(0.05, 0.0)]);
        assert_eq!(next, ids);
    }

    #[test]
    fn more_people_than_tracks_and_more_tracks_than_people_are_both_assigned() {
        let mut people = People::default();
        let ids = people.observe(0, &[seen(0.0, 0.0), seen(3.0, 0.0), seen(6.0, 0.0)]);
        let one = people.observe(1, &[seen(3.1, 0.0)]);
        assert_eq!(one, vec![ids[1]]);
        let again = people.observe(2, &[seen(6.1, 0.0), seen(0.1, 0.0), seen(3.1, 0.0), seen(9.0, 0.0)]);
        assert_eq!(&again[..3], &[ids[2], ids[0], ids[1]]);
        assert!(!ids.contains(&again[3]), "the fourth is new");
    }
}
