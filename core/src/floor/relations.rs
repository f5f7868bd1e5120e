//! The worker's relation to every mapped station: what the temporal model reads
//! beside the embedding and the keypoints. Relative quantities only — distance,
//! closing and sideways speed, bearing relative to the worker's motion — so nothing
//! depends on where on the floor a station stands.
//!
//! Layout of the [`RELATION_DIM`] values:
//! `[track present, speed (m/s), position sigma (m)]`, then per station (class order)
//! `[known, distance / 10 m, closing speed (m/s), sideways speed (m/s), cos bearing,
//! sin bearing]`. Absent parts are zeros; the bearing is zero below
//! [`MOVING`] (a standing worker has no direction).
//!
//! A set whose rows also read where the worker faces (`"row": "relations_facing"` in
//! its manifest) gets a second block per row ([`facing`], [`FACING_DIM`] values):
//! `[facing known]`, then per station `[cos, sin]` of its bearing relative to where the
//! worker's body faces. A person turns to where they go before the walk shows it: in
//! the tick they commit to a new goal their body faces its way, while a track needs a
//! few noisy positions to find the new direction.
//!
//! A set that fuses its peers with a learned set model (`peer_slots` in its manifest)
//! also reads one such block per peer ([`peer_set`]): the relations of that peer's own
//! estimate of the worker to the robot's team map. Its track values carry the peer's
//! view quality (position sigma), and a slot whose first value is zero is empty, so
//! the model also knows how many peers it heard.

use spwi_proto::{WorkerEstimate, NUM_CLASSES};

/// Values per station.
pub const PER_STATION: usize = 6;
/// Values about the track itself.
pub const TRACK_VALUES: usize = 3;
/// Width of the relation block of a temporal row.
pub const RELATION_DIM: usize = TRACK_VALUES + NUM_CLASSES * PER_STATION;
/// Values of the facing block before its stations' (whether the facing is known).
pub const FACING_HEAD: usize = 1;
/// Values per station in the facing block (cosine and sine of its bearing).
pub const FACING_PER_STATION: usize = 2;
/// Width of the facing block of a temporal row.
pub const FACING_DIM: usize = FACING_HEAD + NUM_CLASSES * FACING_PER_STATION;
/// Below this speed (m/s) the worker has no direction of motion.
pub const MOVING: f32 = 0.2;

/// The relation features of a worker estimate to the stations of a map, into `out`
/// (length [`RELATION_DIM`]).
pub fn relations(worker: Option<&WorkerEstimate>, stations: &[Option<[f32; 2]>; NUM_CLASSES], out: &mut [f32]) {
    assert_eq!(out.len(), RELATION_DIM);
    out.fill(0.0);
    let Some(w) = worker else { return };
    track_values(w, &mut out[..TRACK_VALUES]);
    for (s, at) in stations.iter().enumerate() {
        if let Some(at) = at {
            relation_to(w, *at, &mut out[TRACK_VALUES + s * PER_STATION..TRACK_VALUES + (s + 1) * PER_STATION]);
        }
    }
}

/// The track values of a worker estimate into `out` (length [`TRACK_VALUES`]):
/// `[1, speed (m/s), position sigma (m)]`.
pub fn track_values(w: &WorkerEstimate, out: &mut [f32]) {
    out.copy_from_slice(&[1.0, w.velocity[0].hypot(w.velocity[1]), w.covariance[0].max(0.0).sqrt()]);
}

/// The worker's relation to one point of the floor into `out` (length
/// [`PER_STATION`]): `[1, distance / 10 m, closing speed, sideways speed, cos bearing,
/// sin bearing]`, the bearing relative to the worker's motion (zero below [`MOVING`]).
pub fn relation_to(w: &WorkerEstimate, at: [f32; 2], out: &mut [f32]) {
    let v = w.velocity;
    let speed = v[0].hypot(v[1]);
    let d = [at[0] - w.position[0], at[1] - w.position[1]];
    let dist = d[0].hypot(d[1]);
    let u = if dist > 1e-3 { [d[0] / dist, d[1] / dist] } else { [0.0, 0.0] };
    out.fill(0.0);
    out[0] = 1.0;
    out[1] = dist / 10.0;
    out[2] = u[0] * v[0] + u[1] * v[1]; // rate at which the distance shrinks
    out[3] = u[0] * v[1] - u[1] * v[0];
    if speed >= MOVING && dist > 1e-3 {
        out[4] = (u[0] * v[0] + u[1] * v[1]) / speed;
        out[5] = (v[0] * u[1] - v[1] * u[0]) / speed;
    }
}

/// The facing block: where the worker at `worker` faces (`facing`, radians, floor
/// frame) against the stations of a map, into `out` (length [`FACING_DIM`]); zeros
/// when either is unknown, and for the stations not mapped.
pub fn facing(
    worker: Option<&WorkerEstimate>,
    facing: Option<f32>,
    stations: &[Option<[f32; 2]>; NUM_CLASSES],
    out: &mut [f32],
) {
    assert_eq!(out.len(), FACING_DIM);
    out.fill(0.0);
    let (Some(w), Some(facing)) = (worker, facing) else { return };
    out[0] = 1.0;
    for (s, at) in stations.iter().enumerate() {
        let Some(at) = at else { continue };
        let d = [at[0] - w.position[0], at[1] - w.position[1]];
        if d[0].hypot(d[1]) > 1e-3 {
            let relative = d[1].atan2(d[0]) - facing;
            let o = FACING_HEAD + s * FACING_PER_STATION;
            out[o] = relative.cos();
            out[o + 1] = relative.sin();
        }
    }
}

/// The team's facing from the facings its robots saw for one tick: their circular
/// mean (radians, in (−π, π]). `None` without facings, or when they cancel out (two
/// robots that saw the body face opposite ways tell nothing). Order does not matter.
pub fn fuse_facings(facings: impl IntoIterator<Item = f32>) -> Option<f32> {
    let (mut c, mut s) = (0.0f32, 0.0f32);
    for f in facings {
        c += f.cos();
        s += f.sin();
    }
    (c.hypot(s) > 1e-3).then(|| s.atan2(c))
}

/// One relation block per peer estimate into `out` (`slots` × [`RELATION_DIM`],
/// empty slots zero), against the same map. With more peers than slots, those whose
/// position is known best are kept. The order of the blocks carries no meaning: the
/// model that reads them pools over the slots.
pub fn peer_set(peers: &[&WorkerEstimate], stations: &[Option<[f32; 2]>; NUM_CLASSES], slots: usize, out: &mut [f32]) {
    assert_eq!(out.len(), slots * RELATION_DIM);
    let mut best: Vec<&WorkerEstimate> = peers.to_vec();
    best.sort_by(|a, b| a.covariance[0].total_cmp(&b.covariance[0]));
    for (i, block) in out.chunks_exact_mut(RELATION_DIM).enumerate() {
        relations(best.get(i).copied(), stations, block);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn walker(position: [f32; 2], velocity: [f32; 2]) -> WorkerEstimate {
        WorkerEstimate { position, velocity, covariance: [0.04, 0.0, 0.1] }
    }

    #[test]
    fn the_station_ahead_closes_and_the_one_behind_recedes() {
        let stations = [Some([10.0, 0.0]), Some([-10.0, 0.0]), None, Some([0.0, 5.0])];
        let mut out = [0.0; RELATION_DIM];
        relations(Some(&walker([0.0, 0.0], [1.0, 0.0])), &stations, &mut out);
        let st = |s: usize| &out[TRACK_VALUES + s * PER_STATION..TRACK_VALUES + (s + 1) * PER_STATION];
        assert_eq!(&out[..2], &[1.0, 1.0]);
        assert_eq!(st(0), &[1.0, 1.0, 1.0, 0.0, 1.0, 0.0]);
        assert_eq!(st(1), &[1.0, 1.0, -1.0, 0.0, -1.0, 0.0]);
        assert!(st(2).iter().all(|&x| x == 0.0), "unmapped station: zeros");
        assert!(
            st(3)[2].abs() < 1e-6 && st(3)[4].abs() < 1e-6 && st(3)[5] > 0.99,
            "to the left, neither closing nor receding"
        );
    }

    #[test]
    fn features_do_not_depend_on_where_the_scene_stands() {
        let (mut a, mut b) = ([0.0; RELATION_DIM], [0.0; RELATION_DIM]);
        relations(Some(&walker([1.0, 2.0], [0.6, 0.8])), &[Some([4.0, 6.0]), None, None, None], &mut a);
        relations(Some(&walker([101.0, -48.0], [0.6, 0.8])), &[Some([104.0, -44.0]), None, None, None], &mut b);
        assert_eq!(a, b);
        relations(None, &[Some([4.0, 6.0]), None, None, None], &mut a);
        assert!(a.iter().all(|&x| x == 0.0), "no track: zeros");
    }

    #[test]
    fn the_station_the_worker_faces_is_ahead_whatever_the_floor() {
        let stations = [Some([3.0, 4.0]), None, Some([-1.0, 4.0]), Some([0.0, -5.0])];
        let still = walker([0.0, 4.0], [0.0, 0.0]); // standing: no direction of motion
        let mut out = [0.0; FACING_DIM];
        facing(Some(&still), Some(0.0), &stations, &mut out); // facing east
        assert_eq!(out[0], 1.0);
        assert!((out[1] - 1.0).abs() < 1e-6 && out[2].abs() < 1e-6, "station 0 straight ahead: {out:?}");
        assert_eq!(&out[3..5], &[0.0, 0.0], "unmapped station: zeros");
        assert!((out[5] + 1.0).abs() < 1e-6, "station 2 behind");
        assert!(out[7].abs() < 1e-6 && (out[8] + 1.0).abs() < 1e-6, "station 3 to the right");
        // The same scene moved and turned a quarter: the same values.
        let turned = [Some([-4.0, 13.0]), None, Some([-4.0, 9.0]), Some([5.0, 10.0])];
        let mut moved = [0.0; FACING_DIM];
        facing(Some(&walker([-4.0, 10.0], [0.0, 0.0])), Some(std::f32::consts::FRAC_PI_2), &turned, &mut moved);
        assert!(out.iter().zip(&moved).all(|(a, b)| (a - b).abs() < 1e-5), "{out:?} vs {moved:?}");
        facing(Some(&still), None, &stations, &mut out);
        assert!(out.iter().all(|&x| x == 0.0), "facing unknown: zeros");
    }

    #[test]
    fn the_team_facing_is_the_circular_mean_of_its_robots() {
        use std::f32::consts::PI;
        assert_eq!(fuse_facings([]), None);
        assert_eq!(fuse_facings([0.4]), Some(0.4));
        assert!(fuse_facings([0.3, -0.1]).is_some_and(|f| (f - 0.1).abs() < 1e-6));
        // Across the ±π seam: the mean is west, not east.
        let west = fuse_facings([PI - 0.1, -PI + 0.1]).unwrap();
        assert!((west.abs() - PI).abs() < 1e-5, "{west}");
        let (a, b) = (fuse_facings([PI - 0.1, -PI + 0.1, 0.5]), fuse_facings([0.5, -PI + 0.1, PI - 0.1]));
        assert!((a.unwrap() - b.unwrap()).abs() < 1e-6, "order: {a:?} {b:?}");
        assert_eq!(fuse_facings([0.0, PI]), None, "opposite views tell nothing");
    }

    #[test]
    fn a_peer_set_keeps_the_best_placed_peers_and_leaves_the_rest_of_its_slots_empty() {
        let stations = [Some([10.0, 0.0]), None, None, None];
        let wide = WorkerEstimate { covariance: [4.0, 0.0, 1.0], ..walker([0.0, 0.0], [1.0, 0.0]) };
        let sharp = WorkerEstimate { covariance: [0.01, 0.0, 1.0], ..walker([1.0, 0.0], [1.0, 0.0]) };
        let mut out = vec![7.0; 3 * RELATION_DIM];
        peer_set(&[&wide, &sharp], &stations, 3, &mut out);
        assert_eq!(out[0], 1.0);
        assert_eq!(out[2], 0.1, "the sharper estimate first");
        assert_eq!(out[RELATION_DIM + 2], 2.0);
        assert!(out[2 * RELATION_DIM..].iter().all(|&x| x == 0.0), "an empty slot is zeros");
        let mut one = vec![0.0; RELATION_DIM];
        peer_set(&[&wide, &sharp], &stations, 1, &mut one);
        assert_eq!(one[2], 0.1, "more peers than slots: the best placed kept");
    }
}
