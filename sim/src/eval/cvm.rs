//! The constant-velocity baseline (paper IV, after Schöller et al. 2020), as a robot
//! would run it from its own camera: the worker's head keypoint is back-projected onto
//! the plane at head height (the robot knows its pose and camera), a Kalman filter
//! with a constant-velocity model tracks the floor position, the velocity is the mean
//! of the filter's 12 latest states, and the predicted station is the one the
//! extrapolated straight line reaches — or, when the worker stands still, the nearest.
//! The prediction is the same for t and every future step: the model has no notion of
//! a goal changing.

use spwi_core::floor::track::Axis;
use spwi_world::geometry::P2;
use std::collections::VecDeque;

/// Height of the nose keypoint of the simulated worker (skeleton.rs), metres.
pub const HEAD_HEIGHT: f32 = 1.62;
/// States averaged for the velocity.
const VELOCITY_STATES: usize = 12;
/// Below this speed (m/s) the worker is taken to be standing.
const STANDING: f32 = 0.15;
/// How far ahead the motion is extrapolated (s).
const LOOKAHEAD_S: f32 = 15.0;

/// One robot's constant-velocity predictor.
#[derive(Debug, Clone)]
pub struct Cvm {
    axes: Option<[Axis; 2]>,
    velocities: VecDeque<P2>,
    last_tick: u64,
    dt: f32,
}

impl Cvm {
    /// `dt`: seconds per tick.
    pub fn new(dt: f32) -> Self {
        Cvm { axes: None, velocities: VecDeque::new(), last_tick: 0, dt }
    }

    /// Feeds a measured floor position at `tick`; a gap of more than 2 s restarts the track.
    pub fn observe(&mut self, tick: u64, z: P2) {
        const Q: f32 = 0.5; // process noise (m/s²)² per s
        const R: f32 = 0.09; // measurement noise, (0.3 m)²
        let gap = tick.saturating_sub(self.last_tick);
        match self.axes.as_mut() {
            Some(axes) if gap as f32 * self.dt <= 2.0 => {
                for (a, z) in axes.iter_mut().zip(z) {
                    a.predict(gap as f32 * self.dt, Q);
                    a.update(z, R);
                }
            }
            _ => {
                self.axes = Some([Axis::new(z[0], 1.0), Axis::new(z[1], 1.0)]);
                self.velocities.clear();
            }
        }
        self.last_tick = tick;
        let axes = self.axes.as_ref().expect("set above");
        self.velocities.push_back([axes[0].x[1], axes[1].x[1]]);
        if self.velocities.len() > VELOCITY_STATES {
            self.velocities.pop_front();
        }
    }

    /// The station (index into `spots`, each a station's floor position) the worker is
    /// heading to, or `None` before any observation.
    pub fn predict(&self, spots: &[P2]) -> Option<usize> {
        let axes = self.axes.as_ref()?;
        let position = [axes[0].x[0], axes[1].x[0]];
        let n = self.velocities.len() as f32;
        let v = self.velocities.iter().fold([0.0, 0.0], |s, v| [s[0] + v[0] / n, s[1] + v[1] / n]);
        let speed = v[0].hypot(v[1]);
        let dist = |a: P2, b: P2| (a[0] - b[0]).hypot(a[1] - b[1]);
        if speed < STANDING {
            return nearest(spots, |s| dist(position, s));
        }
        // Distance from each station to the extrapolated segment, ahead of the worker only.
        let dir = [v[0] / speed, v[1] / speed];
        let reach = speed * LOOKAHEAD_S;
        nearest(spots, |s| {
            let d = [s[0] - position[0], s[1] - position[1]];
            let along = (d[0] * dir[0] + d[1] * dir[1]).clamp(0.0, reach);
            let closest = [position[0] + dir[0] * along, position[1] + dir[1] * along];
            dist(closest, s) + if along <= 0.0 { dist(position, s) } else { 0.0 }
        })
    }
}

fn nearest(spots: &[P2], cost: impl Fn(P2) -> f32) -> Option<usize> {
    spots.iter().enumerate().min_by(|a, b| cost(*a.1).total_cmp(&cost(*b.1))).map(|(i, _)| i)
}

#[cfg(test)]
mod tests {
    use super::*;

    const SPOTS: [P2; 4] = [[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]];

    #[test]
    fn a_straight_constant_speed_walk_predicts_the_station_ahead() {
        let mut cvm = Cvm::new(0.1);
        // from (2, 2) towards station 2 at (10, 10), 1.2 m/s, slightly noisy
        for t in 0..30u64 {
            let s = 1.2 * 0.1 * t as f32 / std::f32::consts::SQRT_2;
            let noise = if t % 2 == 0 { 0.05 } else { -0.05 };
            cvm.observe(t, [2.0 + s + noise, 2.0 + s - noise]);
        }
        assert_eq!(cvm.predict(&SPOTS), Some(2));
    }

    #[test]
    fn a_worker_standing_still_is_at_the_nearest_station() {
        let mut cvm = Cvm::new(0.1);
        for t in 0..20 {
            cvm.observe(t, [9.5, 0.4]);
        }
        assert_eq!(cvm.predict(&SPOTS), Some(1));
        assert_eq!(Cvm::new(0.1).predict(&SPOTS), None);
    }
}
