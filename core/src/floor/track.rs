//! The worker's track on the floor: a constant-velocity Kalman filter per axis, and
//! the fusion of the estimates the robots share into the team's track.
//!
//! The filter runs on tick numbers (10 Hz), so the same frames give the same track in
//! the daemon, a replay and the evaluation. A gap longer than [`MAX_GAP_TICKS`] starts
//! the track afresh; an estimate is shared only while the worker was measured within
//! [`FRESH_TICKS`].

use spwi_proto::WorkerEstimate;

/// Seconds per tick.
pub const TICK_S: f32 = spwi_proto::TICK_PERIOD.as_secs_f32();
/// A gap longer than this (2 s) restarts the track.
pub const MAX_GAP_TICKS: u64 = 20;
/// An estimate is shared, and the robot votes from it, while the last measurement is
/// at most this old (3 s): its covariance grows meanwhile, so the team's fusion weighs
/// it down against any fresh view, and the team keeps an answer through a few seconds
/// in which nobody sees the worker (tracking cameras turn away).
pub const FRESH_TICKS: u64 = 30;
/// Process noise: the worker's acceleration spectral density, (m/s²)² per s.
const Q: f32 = 0.5;
/// Velocity variance of a new track (m²/s²): walking speed is unknown at first.
const INITIAL_VELOCITY_VAR: f32 = 1.0;
/// What two robots' estimates of the same worker differ by beyond their filters'
/// covariances (m² per axis): calibration, detection lag, the worker's width.
const MODEL_VAR: f32 = 0.25;
/// χ² with 2 degrees of freedom at 99.9 %: two estimates farther apart than this,
/// in units of their combined variance, are not of the same place.
const SAME_PLACE_GATE: f32 = 13.82;

/// One axis: state (position, velocity) and its covariance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Axis {
    pub x: [f32; 2],
    pub p: [[f32; 2]; 2],
}

impl Axis {
    pub fn new(z: f32, var: f32) -> Self {
        Axis { x: [z, 0.0], p: [[var, 0.0], [0.0, INITIAL_VELOCITY_VAR]] }
    }

    pub fn predict(&mut self, dt: f32, q: f32) {
        let [x, v] = self.x;
        self.x = [x + v * dt, v];
        let p = self.p;
        let p00 = p[0][0] + dt * (p[1][0] + p[0][1]) + dt * dt * p[1][1] + q * dt.powi(3) / 3.0;
        let p01 = p[0][1] + dt * p[1][1] + q * dt * dt / 2.0;
        let p11 = p[1][1] + q * dt;
        self.p = [[p00, p01], [p01, p11]];
    }

    pub fn update(&mut self, z: f32, r: f32) {
        let s = self.p[0][0] + r;
        let k = [self.p[0][0] / s, self.p[1][0] / s];
        let y = z - self.x[0];
        self.x = [self.x[0] + k[0] * y, self.x[1] + k[1] * y];
        let p = self.p;
        self.p =
            [[(1.0 - k[0]) * p[0][0], (1.0 - k[0]) * p[0][1]], [p[1][0] - k[1] * p[0][0], p[1][1] - k[1] * p[0][1]]];
    }
}

/// One robot's track of the worker from its own measurements.
#[derive(Debug, Clone, Default)]
pub struct Track {
    axes: Option<[Axis; 2]>,
    /// Tick the state is at.
    at: u64,
    /// Tick of the last measurement.
    measured: u64,
}

impl Track {
    /// A floor measurement `z` with standard deviation `sigma` (m) at `tick`.
    pub fn observe(&mut self, tick: u64, z: [f32; 2], sigma: f32) {
        let r = sigma * sigma;
        match self.axes.as_mut() {
            Some(axes) if tick >= self.at && tick - self.measured <= MAX_GAP_TICKS => {
                let dt = (tick - self.at) as f32 * TICK_S;
                for (a, z) in axes.iter_mut().zip(z) {
                    a.predict(dt, Q);
                    a.update(z, r);
                }
            }
            _ => self.axes = Some([Axis::new(z[0], r), Axis::new(z[1], r)]),
        }
        self.at = tick;
        self.measured = tick;
    }

    /// The estimate predicted to `tick`, if the worker was measured recently.
    pub fn estimate(&self, tick: u64) -> Option<WorkerEstimate> {
        let axes = self.axes.as_ref()?;
        if tick < self.measured || tick - self.measured > FRESH_TICKS {
            return None;
        }
        let mut axes = *axes;
        let dt = tick.saturating_sub(self.at) as f32 * TICK_S;
        for a in axes.iter_mut() {
            a.predict(dt, Q);
        }
        // The covariance shared is the mean of the two axes' (they see the same noise).
        let p = |i: usize, j: usize| (axes[0].p[i][j] + axes[1].p[i][j]) / 2.0;
        Some(WorkerEstimate {
            position: [axes[0].x[0], axes[1].x[0]],
            velocity: [axes[0].x[1], axes[1].x[1]],
            covariance: [p(0, 0), p(0, 1), p(1, 1)],
        })
    }
}

/// The team's track from the estimates the robots hold for one tick: inverse-variance
/// weighting of positions and of velocities (the robots' measurement noise is
/// independent). `None` without estimates. Order does not matter.
pub fn fuse<'a>(estimates: impl IntoIterator<Item = &'a WorkerEstimate>) -> Option<WorkerEstimate> {
    let (mut wp, mut wv, mut pos, mut vel, mut rho) = (0.0f64, 0.0f64, [0.0f64; 2], [0.0f64; 2], 0.0f64);
    let mut n = 0;
    for e in estimates {
        let [pp, pv, vv] = e.covariance.map(f64::from);
        let (a, b) = (1.0 / pp, 1.0 / vv);
        wp += a;
        wv += b;
        for k in 0..2 {
            pos[k] += a * e.position[k] as f64;
            vel[k] += b * e.velocity[k] as f64;
        }
        rho += a * pv / (pp * vv).sqrt();
        n += 1;
    }
    if n == 0 {
        return None;
    }
    let (pp, vv) = (1.0 / wp, 1.0 / wv);
    let pv = (rho / wp) * (pp * vv).sqrt();
    Some(WorkerEstimate {
        position: pos.map(|p| (p / wp) as f32),
        velocity: vel.map(|v| (v / wv) as f32),
        covariance: [pp as f32, pv as f32, vv as f32],
    })
}

/// An estimate carried `ticks` forward under the filter's motion model: a peer's
/// estimate of an earlier tick, read for this one. Its uncertainty grows with the wait.
pub fn predict(e: &WorkerEstimate, ticks: u64) -> WorkerEstimate {
    if ticks == 0 {
        return *e;
    }
    let [pp, pv, vv] = e.covariance;
    let mut out = *e;
    for k in 0..2 {
        let mut axis = Axis { x: [e.position[k], e.velocity[k]], p: [[pp, pv], [pv, vv]] };
        axis.predict(ticks as f32 * TICK_S, Q);
        out.position[k] = axis.x[0];
        out.covariance = [axis.p[0][0], axis.p[0][1], axis.p[1][1]]; // the same on both axes
    }
    out
}

/// Whether two estimates put the worker at the same place, given their uncertainty.
pub fn same_place(a: &WorkerEstimate, b: &WorkerEstimate) -> bool {
    let d2 = (a.position[0] - b.position[0]).powi(2) + (a.position[1] - b.position[1]).powi(2);
    d2 <= SAME_PLACE_GATE * (a.covariance[0] + b.covariance[0] + MODEL_VAR)
}

/// For each of the estimates held for one tick, whether it puts the worker where most
/// of the others do ([`same_place`] with at least half of them); `None` with fewer
/// than three, when no majority tells which of two is wrong.
pub fn agrees_with_most(estimates: &[&WorkerEstimate]) -> Option<Vec<bool>> {
    let n = estimates.len();
    (n >= 3).then(|| {
        (0..n)
            .map(|i| {
                let agree = (0..n).filter(|&j| j != i && same_place(estimates[i], estimates[j])).count();
                2 * agree >= n - 1
            })
            .collect()
    })
}

/// What one robot holds of the worker for a tick: its estimate, and where its frame
/// showed the body facing.
#[derive(Debug, Clone, Copy)]
pub struct Sighting<'a> {
    pub estimate: &'a WorkerEstimate,
    pub facing: Option<f32>,
}

/// The estimates a robot holds for `tick`, its own first — the order in which the
/// engine and the training rows alike hand them to [`team_worker`]: its own of the
/// tick, then each peer's latest share (of the tick given with it) carried forward to
/// `tick` ([`predict`]). Each comes with whose it is and the facing that robot saw.
pub fn held_at<R>(
    tick: u64,
    own: Option<(R, WorkerEstimate, Option<f32>)>,
    peers: impl IntoIterator<Item = (R, u64, Option<WorkerEstimate>, Option<f32>)>,
) -> Vec<(R, WorkerEstimate, Option<f32>)> {
    let carried = peers
        .into_iter()
        .filter_map(|(r, then, estimate, facing)| Some((r, predict(&estimate?, tick.saturating_sub(then)), facing)));
    own.into_iter().chain(carried).collect()
}

/// The [`Sighting`]s of estimates [`held_at`] a tick, and whose each is.
pub fn sightings<R: Copy>(held: &[(R, WorkerEstimate, Option<f32>)]) -> (Vec<R>, Vec<Sighting<'_>>) {
    held.iter().map(|(r, estimate, facing)| (*r, Sighting { estimate, facing: *facing })).unzip()
}

/// The team's worker for one tick, from the robots' [`Sighting`]s.
#[derive(Debug, Clone)]
pub struct TeamWorker {
    /// The fused track of the sightings kept.
    pub track: Option<WorkerEstimate>,
    /// The circular mean of their facings ([`super::fuse_facings`]).
    pub facing: Option<f32>,
    /// Per sighting: whether it is in the fusion.
    pub kept: Vec<bool>,
    /// Per sighting: whether it agrees with most ([`agrees_with_most`]).
    pub agrees: Option<Vec<bool>>,
}

/// The one rule of who makes the team's view of the worker, for the engine and the
/// training data alike: a sighting is kept when most others do not contradict its
/// estimate and `trusted` says so; the kept ones' estimates make the track and their
/// facings the facing.
pub fn team_worker(sightings: &[Sighting], trusted: impl Fn(usize) -> bool) -> TeamWorker {
    let estimates: Vec<&WorkerEstimate> = sightings.iter().map(|s| s.estimate).collect();
    let agrees = agrees_with_most(&estimates);
    let kept: Vec<bool> = (0..sightings.len()).map(|i| agrees.as_ref().is_none_or(|a| a[i]) && trusted(i)).collect();
    let kept_sightings = || sightings.iter().zip(&kept).filter(|(_, &k)| k).map(|(s, _)| s);
    TeamWorker {
        track: fuse(kept_sightings().map(|s| s.estimate)),
        facing: super::fuse_facings(kept_sightings().filter_map(|s| s.facing)),
        kept,
        agrees,
    }
}

impl TeamWorker {
    /// The estimates of the kept `sightings` (those this was made from) that `mine`
    /// does not claim: the peers' views in the team's track.
    pub fn kept_peers<'a>(&self, sightings: &[Sighting<'a>], mine: impl Fn(usize) -> bool) -> Vec<&'a WorkerEstimate> {
        sightings.iter().enumerate().filter(|&(i, _)| self.kept[i] && !mine(i)).map(|(_, s)| s.estimate).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_estimate_most_others_disagree_with_is_the_odd_one_out() {
        let at =
            |x: f32, var: f32| WorkerEstimate { position: [x, 2.0], velocity: [0.0; 2], covariance: [var, 0.0, 1.0] };
        let (a, b, c, far) = (at(5.0, 0.04), at(5.6, 0.04), at(4.7, 0.1), at(9.0, 0.04));
        assert!(same_place(&a, &b), "0.6 m apart: within 3.7 σ of 0.33 m² combined");
        assert!(!same_place(&a, &far), "4 m apart");
        assert!(same_place(&at(9.0, 2.0), &a), "a wide estimate reaches far");
        assert_eq!(agrees_with_most(&[&a, &far]), None, "two: no majority");
        assert_eq!(agrees_with_most(&[&a, &b, &far]), Some(vec![true, true, false]));
        assert_eq!(agrees_with_most(&[&far, &a, &c, &b]), Some(vec![false, true, true, true]));
    }

    #[test]
    fn the_team_is_made_of_the_sightings_neither_contradicted_nor_distrusted() {
        let at = |x: f32| WorkerEstimate { position: [x, 2.0], velocity: [0.0; 2], covariance: [0.04, 0.0, 1.0] };
        let (a, b, c, far) = (at(5.0), at(5.3), at(5.1), at(9.0));
        let seen = |estimate, facing| Sighting { estimate, facing: Some(facing) };
        let sightings = [seen(&a, 0.1), seen(&b, 0.3), seen(&far, 3.0), seen(&c, 1.5)];
        let team = team_worker(&sightings, |i| i != 3); // the fourth is distrusted
        assert_eq!(team.agrees, Some(vec![true, true, false, true]));
        assert_eq!(team.kept, vec![true, true, false, false]);
        assert_eq!(team.track, fuse([&a, &b]));
        assert_eq!(team.kept_peers(&sightings, |i| i == 0), vec![&b], "kept, not ours");
        assert!(team.facing.is_some_and(|f| (f - 0.2).abs() < 1e-6), "{:?}: a's and b's only", team.facing);
        let unseen = team_worker(&[Sighting { estimate: &a, facing: None }], |_| true);
        assert_eq!((unseen.track, unseen.facing, unseen.agrees), (Some(a), None, None), "alone: its own track");
    }

    #[test]
    fn a_peers_estimate_read_later_has_moved_on_and_grown_less_sure() {
        let e = WorkerEstimate { position: [1.0, 2.0], velocity: [1.2, -0.4], covariance: [0.04, 0.01, 0.2] };
        assert_eq!(predict(&e, 0), e);
        let later = predict(&e, 2);
        assert!((later.position[0] - 1.24).abs() < 1e-6 && (later.position[1] - 1.92).abs() < 1e-6, "{later:?}");
        assert_eq!(later.velocity, e.velocity);
        assert!(later.covariance[0] > e.covariance[0] && later.covariance[2] > e.covariance[2], "{later:?}");
        // Carried forward as the filter itself would: the same as its own prediction.
        let mut tr = Track::default();
        for t in 0..10 {
            tr.observe(t, truth(t), 0.1);
        }
        let (now, then) = (tr.estimate(9).unwrap(), tr.estimate(12).unwrap());
        let carried = predict(&now, 3);
        assert!(carried.position.iter().zip(then.position).all(|(a, b)| (a - b).abs() < 1e-5), "{carried:?} {then:?}");
        assert!((carried.covariance[0] - then.covariance[0]).abs() < 1e-5);
    }

    #[test]
    fn a_robot_holds_its_own_estimate_first_and_its_peers_latest_carried_to_the_tick() {
        let at = |x: f32| WorkerEstimate { position: [x, 0.0], velocity: [1.0, 0.0], covariance: [0.04, 0.0, 0.2] };
        let peers = [("b", 9, Some(at(3.0)), Some(0.5)), ("c", 10, None, Some(1.0)), ("d", 10, Some(at(7.0)), None)];
        let held = held_at(10, Some(("a", at(5.0), None)), peers);
        let order: Vec<&str> = held.iter().map(|h| h.0).collect();
        assert_eq!(order, ["a", "b", "d"], "ours first; a peer without an estimate holds none");
        assert_eq!(held[1], ("b", predict(&at(3.0), 1), Some(0.5)), "b's of tick 9, a tick on");
        assert_eq!(held[2], ("d", at(7.0), None), "d's of this very tick, as it is");
        let (robots, sightings) = sightings(&held);
        assert_eq!((robots, sightings[1].estimate, sightings[1].facing), (order, &held[1].1, Some(0.5)));
    }

    /// A deterministic standard normal from a counter (Box–Muller over a hash).
    fn noise(k: u64) -> f32 {
        let h = |x: u64| ((x.wrapping_mul(0x9e37_79b9_7f4a_7c15) >> 11) as f64 + 0.5) / (1u64 << 53) as f64;
        ((-2.0 * h(2 * k + 1).ln()).sqrt() * (std::f64::consts::TAU * h(2 * k + 2)).cos()) as f32
    }

    fn truth(t: u64) -> [f32; 2] {
        [1.0 + 1.2 * TICK_S * t as f32, 2.0 + 0.4 * TICK_S * t as f32]
    }

    #[test]
    fn a_straight_walk_is_tracked_with_its_velocity() {
        let mut tr = Track::default();
        for t in 0..40 {
            let z = truth(t);
            tr.observe(t, [z[0] + 0.1 * noise(t), z[1] + 0.1 * noise(t + 1000)], 0.1);
        }
        let e = tr.estimate(40).unwrap();
        let z = truth(40);
        assert!((e.position[0] - z[0]).hypot(e.position[1] - z[1]) < 0.2, "{e:?}");
        assert!((e.velocity[0] - 1.2).abs() < 0.3 && (e.velocity[1] - 0.4).abs() < 0.3, "{e:?}");
        assert!(tr.estimate(40 + FRESH_TICKS + 1).is_none(), "an old track is not shared");
    }

    #[test]
    fn two_robots_fused_track_better_than_either() {
        // Two robots, each with its own noise, far (0.5 m) and near (0.3 m).
        let (mut a, mut b) = (Track::default(), Track::default());
        let (mut err_a, mut err_b, mut err_f) = (0.0, 0.0, 0.0);
        for t in 0..600u64 {
            let z = truth(t % 100);
            if t % 100 == 0 {
                (a, b) = (Track::default(), Track::default()); // a new walk every 10 s
            }
            a.observe(t, [z[0] + 0.5 * noise(t), z[1] + 0.5 * noise(t + 7000)], 0.5);
            b.observe(t, [z[0] + 0.3 * noise(t + 3000), z[1] + 0.3 * noise(t + 9000)], 0.3);
            if t % 100 < 20 {
                continue; // let the filters settle
            }
            let (ea, eb) = (a.estimate(t).unwrap(), b.estimate(t).unwrap());
            let f = fuse([&ea, &eb]).unwrap();
            let err = |e: &WorkerEstimate| (e.position[0] - z[0]).powi(2) + (e.position[1] - z[1]).powi(2);
            err_a += err(&ea);
            err_b += err(&eb);
            err_f += err(&f);
            assert!(f.covariance[0] < ea.covariance[0].min(eb.covariance[0]));
        }
        assert!(err_f < err_a && err_f < err_b, "fused {err_f}, a {err_a}, b {err_b}");
        let (ea, eb) = (a.estimate(599).unwrap(), b.estimate(599).unwrap());
        assert_eq!(fuse([&ea, &eb]), fuse([&eb, &ea]), "order does not matter");
        assert!(fuse([]).is_none());
    }
}
