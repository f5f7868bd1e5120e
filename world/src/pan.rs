//! Where the pan units point the fleet's cameras under the `track` policy.
//!
//! Two jobs compete for the cameras: keeping the worker in view, and seeing the
//! stations the worker may head to next. A station no camera has seen is missing from
//! every robot's map, so no model can name it, however well it reads the worker. So
//! while the worker walks, every camera follows it; while it stands working at a
//! station, the robot with the nearest view keeps it in view and the others look round
//! the floor; when nobody has seen the worker for a while, every camera looks round.
//! Looking round means turning to the bearing over the floor that the camera looked
//! along least recently: a scan that needs no knowledge of where anything stands.
//!
//! The world hands the pan units what the team's shared track hands a real robot:
//! where and when the fleet saw the worker.

use crate::geometry::*;
use std::collections::VecDeque;
use std::f32::consts::TAU;

/// After this many ticks without a sighting every camera looks round.
pub const MEMORY_TICKS: u64 = 30;
/// Span of sightings over which the worker's speed is judged, ticks.
const SPEED_WINDOW_TICKS: u64 = 10;
/// Slower than this over the window, the worker stands (works at a station), m/s.
const STANDING_SPEED: f32 = 0.3;
/// A robot has the worker in view for this many ticks after its own camera showed it.
const IN_VIEW_TICKS: u64 = 5;
/// Bearings a camera remembers looking along: equal sectors of the full circle.
const SECTORS: usize = 12;
/// A bearing looks over the floor when the point this far along it is on the floor, m.
const LOOK_AHEAD: f32 = 2.0;

/// Where and when the fleet saw the worker lately.
#[derive(Debug, Clone, Default)]
pub struct Sightings {
    /// One position per tick with a sighting, oldest first: the speed window's, and
    /// always the last one.
    recent: VecDeque<(P2, u64)>,
}

impl Sightings {
    /// A robot of the fleet saw the worker at `position` on `tick`.
    pub fn record(&mut self, position: P2, tick: u64) {
        match self.recent.back_mut() {
            Some(last) if last.1 == tick => last.0 = position,
            _ => self.recent.push_back((position, tick)),
        }
        while self.recent.front().is_some_and(|&(_, t)| t + SPEED_WINDOW_TICKS < tick) {
            self.recent.pop_front();
        }
    }

    /// Where the worker was last seen, unless that is more than `MEMORY_TICKS` ago.
    pub fn fresh(&self, tick: u64) -> Option<P2> {
        self.recent.back().filter(|&&(_, t)| tick - t <= MEMORY_TICKS).map(|&(p, _)| p)
    }

    /// Whether the worker, seen just now and over most of the speed window, stands.
    pub fn standing(&self, tick: u64, dt: f32) -> bool {
        let (Some(&(first, t0)), Some(&(last, t1))) = (self.recent.front(), self.recent.back()) else {
            return false;
        };
        let span = t1 - t0;
        tick - t1 <= IN_VIEW_TICKS
            && span >= SPEED_WINDOW_TICKS / 2
            && dist(first, last) < STANDING_SPEED * span as f32 * dt
    }
}

/// One robot's pan unit: what its camera has shown and where it has looked.
#[derive(Debug, Clone, Default)]
pub struct PanUnit {
    /// The tick this robot's own camera last showed the worker.
    saw_worker: Option<u64>,
    /// The tick the camera last looked along each sector's bearing (0: never).
    looked: [u64; SECTORS],
}

fn sector_bearing(k: usize) -> f32 {
    k as f32 * TAU / SECTORS as f32
}

impl PanUnit {
    /// This robot's camera showed the worker on `tick`.
    pub fn saw_worker(&mut self, tick: u64) {
        self.saw_worker = Some(tick);
    }

    fn has_worker_in_view(&self, tick: u64) -> bool {
        self.saw_worker.is_some_and(|t| tick - t <= IN_VIEW_TICKS)
    }

    /// The camera, pointing along `heading` with half field of view `half_fov`, looked
    /// along every sector bearing within it on `tick`.
    pub fn looked_along(&mut self, heading: f32, half_fov: f32, tick: u64) {
        for (k, looked) in self.looked.iter_mut().enumerate() {
            if angle_diff(sector_bearing(k), heading).abs() <= half_fov {
                *looked = tick;
            }
        }
    }

    /// The bearing over the floor (`floor`: its size, from the origin) that the camera
    /// at `position` looked along least recently, the nearest to `heading` among
    /// equals; `None` if no bearing looks over the floor.
    pub fn look_round(&self, position: P2, heading: f32, floor: P2) -> Option<f32> {
        let on_floor = |p: P2| (0.0..=floor[0]).contains(&p[0]) && (0.0..=floor[1]).contains(&p[1]);
        (0..SECTORS)
            .map(|k| (k, sector_bearing(k)))
            .filter(|&(_, b)| on_floor(add(position, [LOOK_AHEAD * b.cos(), LOOK_AHEAD * b.sin()])))
            .min_by(|&(a, ba), &(b, bb)| {
                let turn = |x: f32| angle_diff(x, heading).abs();
                self.looked[a].cmp(&self.looked[b]).then(turn(ba).total_cmp(&turn(bb)))
            })
            .map(|(_, b)| b)
    }
}

/// While the worker stands: the slot of the robot that keeps it in view, the fleet's
/// robot nearest to it among those whose cameras show it. `None` while the worker
/// walks or when no camera shows it (then every camera turns to it).
pub fn keeper<'a>(
    sightings: &Sightings,
    tick: u64,
    dt: f32,
    fleet: impl Iterator<Item = (usize, P2, &'a PanUnit)>,
) -> Option<usize> {
    let worker = sightings.fresh(tick).filter(|_| sightings.standing(tick, dt))?;
    fleet
        .filter(|(_, _, pan)| pan.has_worker_in_view(tick))
        .min_by(|a, b| dist(a.1, worker).total_cmp(&dist(b.1, worker)))
        .map(|(slot, _, _)| slot)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_worker_seen_in_one_place_for_a_second_stands_and_one_walking_does_not() {
        let dt = 0.1;
        let (mut standing, mut walking) = (Sightings::default(), Sightings::default());
        for t in 1..=12 {
            standing.record([3.0 + 0.005 * t as f32, 4.0], t);
            walking.record([3.0 + 0.12 * t as f32, 4.0], t);
        }
        assert!(standing.standing(12, dt));
        assert!(!walking.standing(12, dt));
        assert!(!standing.standing(12 + IN_VIEW_TICKS + 1, dt), "not seen lately: nothing known");
        assert_eq!(standing.fresh(12 + MEMORY_TICKS), Some([3.06, 4.0]));
        assert_eq!(standing.fresh(13 + MEMORY_TICKS), None);
        let mut glimpse = Sightings::default();
        glimpse.record([1.0, 1.0], 5);
        assert!(!glimpse.standing(5, dt), "one sighting says nothing about speed");
    }

    #[test]
    fn the_nearest_robot_that_sees_a_standing_worker_keeps_it() {
        let dt = 0.1;
        let mut s = Sightings::default();
        for t in 1..=10 {
            s.record([5.0, 5.0], t);
        }
        let mut sees = PanUnit::default();
        sees.saw_worker(10);
        let blind = PanUnit::default();
        // slot 0 is nearer but does not see the worker; slots 1 and 2 do
        let fleet = [(0, [5.0, 6.0], &blind), (1, [5.0, 9.0], &sees), (2, [5.0, 8.0], &sees)];
        assert_eq!(keeper(&s, 10, dt, fleet.into_iter()), Some(2));
        // nobody sees it: nobody keeps it, every camera turns to it
        assert_eq!(keeper(&s, 10, dt, [(0, [5.0, 6.0], &blind)].into_iter()), None);
        // a walking worker is followed by every camera
        let mut walking = Sightings::default();
        for t in 1..=10 {
            walking.record([0.12 * t as f32, 5.0], t);
        }
        assert_eq!(keeper(&walking, 10, dt, fleet.into_iter()), None);
    }

    #[test]
    fn looking_round_visits_every_bearing_over_the_floor_and_never_faces_the_wall() {
        // a robot by the south wall of a 10 × 10 floor: half the circle faces the wall
        let (position, floor, half_fov) = ([5.0, 0.5], [10.0, 10.0], 45f32.to_radians());
        let over_floor = |b: f32| b.sin() >= -1e-3;
        let mut pan = PanUnit::default();
        let mut heading = std::f32::consts::FRAC_PI_2;
        for tick in 1..=60 {
            pan.looked_along(heading, half_fov, tick);
            let want = pan.look_round(position, heading, floor).expect("the floor is in front");
            assert!(over_floor(want), "turned to the wall: bearing {want}");
            heading += angle_diff(want, heading).clamp(-0.2, 0.2);
        }
        // it keeps scanning the whole half circle over the floor, not round one bearing
        for (k, &looked) in pan.looked.iter().enumerate() {
            if over_floor(sector_bearing(k)) {
                assert!(looked > 30, "bearing {k} × 30° not looked along in the last 30 ticks");
            }
        }
    }
}
