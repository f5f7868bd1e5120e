//! The world: layout, scenario, worker, robots, and one tick of everything. Determined
//! by its seed: the same seed and the same robots give the same frames, byte for byte.

use crate::appearance::Appearance;
use crate::camera::{self, DetectorState, Occluder, Pose, ROBOT_HEIGHT, ROBOT_RADIUS};
use crate::geometry::*;
use crate::layout::{Layout, Object};
use crate::worker::Worker;
use anyhow::{bail, Result};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use spwi_proto::*;

/// Seconds per tick (10 Hz).
pub const DT: f32 = 0.1;
/// Robot patrol speed, m/s.
const ROBOT_SPEED: f32 = 0.5;

/// The paper's three scenarios, in rising difficulty.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scenario {
    /// No obstacles, stationary robots: the worker walks straight.
    Ideal = 1,
    /// Static obstacles, stationary robots.
    Obstacles = 2,
    /// Static obstacles and moving robots.
    Dynamic = 3,
}

impl Scenario {
    pub fn from_number(n: u8) -> Result<Scenario> {
        Ok(match n {
            1 => Scenario::Ideal,
            2 => Scenario::Obstacles,
            3 => Scenario::Dynamic,
            _ => bail!("scenario {n}: must be 1 (ideal), 2 (static obstacles) or 3 (obstacles and moving robots)"),
        })
    }
    pub fn obstacles(self) -> bool {
        self != Scenario::Ideal
    }
    pub fn moving_robots(self) -> bool {
        self == Scenario::Dynamic
    }
}

/// One robot slot of the layout.
#[derive(Debug, Clone)]
pub struct RobotState {
    /// Whether a robot occupies the slot; changed through [`World::set_present`].
    present: bool,
    pub pose: Pose,
    next_waypoint: usize,
    detector: DetectorState,
}

pub struct World {
    pub layout: Layout,
    pub scenario: Scenario,
    pub tick: u64,
    pub worker: Worker,
    pub robots: Vec<RobotState>,
    objects: Vec<Object>,
    /// Obstacles (scenarios 2, 3), objects, then present robots: rebuilt when robots
    /// move or come and go, shared by every camera of the tick.
    occluders: Vec<Occluder>,
    appearance: Appearance,
    rng: ChaCha8Rng,
}

impl RobotState {
    pub fn is_present(&self) -> bool {
        self.present
    }
}

impl World {
    /// A world with the first `robots` slots present.
    pub fn new(layout: Layout, scenario: Scenario, seed: u64, robots: usize) -> World {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let worker = Worker::spawn(&layout, scenario.obstacles(), &mut rng);
        let objects = layout.stations.iter().flat_map(|s| s.objects.iter().cloned()).collect();
        let robots = layout
            .robots
            .iter()
            .enumerate()
            .map(|(i, r)| RobotState {
                present: i < robots,
                pose: Pose { position: r.spawn, heading: r.heading_deg.to_radians() },
                next_waypoint: 1,
                detector: DetectorState::default(),
            })
            .collect();
        let mut world = World {
            layout,
            scenario,
            tick: 0,
            worker,
            robots,
            objects,
            occluders: Vec::new(),
            appearance: Appearance::new(),
            rng,
        };
        world.refresh_occluders();
        world
    }

    /// Puts a robot into slot `slot` or takes it out.
    pub fn set_present(&mut self, slot: usize, present: bool) {
        self.robots[slot].present = present;
        self.refresh_occluders();
    }

    fn present_positions(&self) -> Vec<P2> {
        self.robots.iter().filter(|r| r.present).map(|r| r.pose.position).collect()
    }

    /// Advances everything by one tick.
    pub fn step(&mut self) {
        self.tick += 1;
        let robots = self.present_positions();
        self.worker.step(DT, &self.layout, self.scenario.obstacles(), &robots, &mut self.rng);
        if self.scenario.moving_robots() {
            let worker = self.worker.position;
            let centre = scale(self.layout.floor.size, 0.5);
            for (slot, r) in self.robots.iter_mut().enumerate() {
                let patrol = &self.layout.robots[slot].patrol;
                if !r.present || patrol.len() < 2 {
                    continue;
                }
                let target = patrol[r.next_waypoint % patrol.len()];
                let to = sub(target, r.pose.position);
                if norm(to) < 0.1 {
                    r.next_waypoint = (r.next_waypoint + 1) % patrol.len();
                    continue;
                }
                let step = scale(unit(to), (ROBOT_SPEED * DT).min(norm(to)));
                let next = add(r.pose.position, step);
                if dist(next, worker) > 1.0 {
                    r.pose.position = next; // robots yield to the worker
                }
                // The camera keeps looking over the floor while the robot patrols (a
                // surveillance robot's pan unit), turning at most 0.3 rad per tick.
                let look = sub(centre, r.pose.position);
                let want = look[1].atan2(look[0]);
                let turn = (want - r.pose.heading).sin().atan2((want - r.pose.heading).cos());
                r.pose.heading += turn.clamp(-0.3, 0.3);
            }
            self.refresh_occluders();
        }
    }

    fn refresh_occluders(&mut self) {
        let o = &mut self.occluders;
        o.clear();
        if self.scenario.obstacles() {
            o.extend(self.layout.obstacles.iter().map(|ob| Occluder {
                footprint: ob.rect(),
                circle: None,
                height: ob.height,
            }));
        }
        o.extend(self.objects.iter().map(|ob| Occluder {
            footprint: ob.footprint(),
            circle: None,
            height: ob.size[2],
        }));
        o.extend(self.robots.iter().filter(|r| r.present).map(|r| Occluder {
            footprint: Rect { min: r.pose.position, max: r.pose.position },
            circle: Some((r.pose.position, ROBOT_RADIUS)),
            height: ROBOT_HEIGHT,
        }));
    }

    /// The detection frame of the robot in `slot`, published as `robot`.
    pub fn observe(&mut self, slot: usize, robot: &RobotId) -> DetectionFrame {
        let first_object = if self.scenario.obstacles() { self.layout.obstacles.len() } else { 0 };
        let own = first_object + self.objects.len() + self.robots[..slot].iter().filter(|r| r.present).count();
        let scene = camera::Scene {
            layout: &self.layout,
            objects: &self.objects,
            occluders: &self.occluders,
            first_object,
            worker: &self.worker,
            appearance: &self.appearance,
        };
        let r = &mut self.robots[slot];
        camera::detect(&scene, robot.clone(), self.tick, r.pose, Some(own), &mut r.detector, &mut self.rng)
    }

    /// Ground truth for this tick.
    pub fn truth(&self, robots: &[(usize, RobotId)]) -> TruthMsg {
        TruthMsg {
            tick: self.tick,
            intent: self.worker.goal,
            phase: self.worker.phase,
            worker_position: self.worker.position,
            worker_heading: self.worker.heading,
            robots: robots
                .iter()
                .map(|(slot, id)| RobotPose {
                    robot: id.clone(),
                    position: self.robots[*slot].pose.position,
                    heading: self.robots[*slot].pose.heading,
                })
                .collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ids(n: usize) -> Vec<RobotId> {
        (0..n).map(|i| RobotId::new(format!("r{i}")).unwrap()).collect()
    }

    fn run(seed: u64, scenario: Scenario, ticks: usize) -> Vec<Vec<u8>> {
        let mut w = World::new(Layout::default_layout(), scenario, seed, 4);
        let ids = ids(4);
        let mut out = Vec::new();
        for _ in 0..ticks {
            w.step();
            for (slot, id) in ids.iter().enumerate() {
                out.push(encode(&w.observe(slot, id)));
            }
        }
        out
    }

    #[test]
    fn same_seed_same_bytes_other_seed_other_bytes() {
        assert_eq!(run(7, Scenario::Dynamic, 50), run(7, Scenario::Dynamic, 50));
        assert_ne!(run(7, Scenario::Dynamic, 50), run(8, Scenario::Dynamic, 50));
    }

    #[test]
    fn frames_are_valid_protocol_messages_and_sometimes_show_the_worker() {
        let mut w = World::new(Layout::default_layout(), Scenario::Obstacles, 3, 4);
        let ids = ids(4);
        let mut seen = 0;
        for _ in 0..300 {
            w.step();
            for (slot, id) in ids.iter().enumerate() {
                let f = w.observe(slot, id);
                let back: DetectionFrame = decode(&encode(&f)).expect("valid frame");
                seen += usize::from(back.human.is_some());
            }
        }
        assert!(seen > 100 && seen < 1200, "worker seen in {seen} of 1200 frames");
    }

    #[test]
    fn a_stationary_robot_that_cannot_see_the_worker_reports_no_worker() {
        let mut w = World::new(Layout::default_layout(), Scenario::Obstacles, 5, 1);
        let id = RobotId::new("r0").unwrap();
        // put the worker straight behind robot 0's camera
        let p = w.robots[0].pose;
        w.worker.position = sub(p.position, [p.heading.cos() * 0.0, 0.5]);
        for _ in 0..20 {
            assert!(w.observe(0, &id).human.is_none());
        }
    }

    #[test]
    fn objects_behind_an_obstacle_are_not_detected() {
        // Robot 1 (0.8, 7.0) looks east; obstacle 0 (7.5..9.5, 5..9) hides whatever stands
        // right behind it on the line of sight.
        let mut layout = Layout::default_layout();
        layout.stations[2].objects[0].position = [11.0, 7.0];
        // a real detection of it, not a false positive of the same class somewhere else
        let is_workbench = |f: &DetectionFrame| {
            f.objects.iter().any(|o| o.class == ObjectClass::Workbench && (o.bbox.center().0 - 320.0).abs() < 40.0)
        };
        let id = RobotId::new("r1").unwrap();
        let mut hidden = World::new(layout.clone(), Scenario::Obstacles, 1, 2);
        let seen_hidden = (0..100).filter(|_| is_workbench(&hidden.observe(1, &id))).count();
        assert_eq!(seen_hidden, 0, "saw the hidden workbench");
        // the same spot without obstacles (scenario 1) is in plain view
        let mut open = World::new(layout, Scenario::Ideal, 1, 2);
        let seen_open = (0..100).filter(|_| is_workbench(&open.observe(1, &id))).count();
        assert!(seen_open > 50, "workbench seen in only {seen_open} of 100 open frames");
    }
}
