//! The world: layout, scenario, worker, robots, and one tick of everything. Determined
//! by its seed: the same seed and the same fleet give the same frames, byte for byte.
//!
//! Every robot slot of the layout is a robot on the floor — it patrols, it occludes, the
//! worker steps round it — whether or not its agent runs. The *fleet* is the set of
//! slots whose agent runs: only they see through their cameras ([`World::observe`]),
//! and with the `track` camera policy only they share where the worker was last seen.
//! Randomness comes in independent streams (the worker, and each slot's detector), so
//! the worker's walk is the same whatever the fleet's size and whatever faults a tool
//! injects, and a robot's frames do not shift when another robot joins.

use crate::appearance::Appearance;
use crate::camera::{self, DetectorState, Occluder, Pose, ROBOT_HEIGHT, ROBOT_RADIUS};
use crate::geometry::*;
use crate::layout::{CameraPolicy, Layout, Object};
use crate::pan::{self, PanUnit, Sightings};
use crate::worker::Worker;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use spwi_proto::*;

/// Seconds per tick.
pub const DT: f32 = spwi_proto::TICK_PERIOD.as_secs_f32();
/// Robot patrol speed, m/s.
const ROBOT_SPEED: f32 = 0.5;
/// How fast a camera pans, radians per tick (≈ 115 °/s: a pan-tilt unit, not a head).
const PAN_PER_TICK: f32 = 0.2;

/// The paper's three scenarios, in rising difficulty.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Scenario {
    /// No obstacles, stationary robots: the worker walks straight.
    Ideal = 1,
    /// Static obstacles, stationary robots.
    Obstacles = 2,
    /// Static obstacles and moving robots.
    Dynamic = 3,
}

impl Scenario {
    pub const ALL: [Scenario; 3] = [Scenario::Ideal, Scenario::Obstacles, Scenario::Dynamic];

    pub fn from_number(n: u8) -> anyhow::Result<Scenario> {
        Scenario::ALL.into_iter().find(|s| *s as u8 == n).ok_or_else(|| {
            anyhow::anyhow!("scenario {n}: must be 1 (ideal), 2 (static obstacles) or 3 (obstacles and moving robots)")
        })
    }
    pub fn obstacles(self) -> bool {
        self != Scenario::Ideal
    }
    pub fn moving_robots(self) -> bool {
        self == Scenario::Dynamic
    }
}

/// The random stream of one part of the world: the same seed, a different stream per
/// part (ChaCha's stream id), so parts never share draws.
pub fn stream(seed: u64, part: Stream) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(part.id());
    rng
}

/// The parts of a world (and of the tools that fault it) that draw random numbers.
#[derive(Debug, Clone, Copy)]
pub enum Stream {
    Worker,
    /// Robot slot k's camera and detector.
    Detector(usize),
    /// A fault model of a tool (message loss, …), by its own number.
    Fault(u64),
}

impl Stream {
    fn id(self) -> u64 {
        match self {
            Stream::Worker => 1,
            Stream::Detector(k) => 1_000 + k as u64,
            Stream::Fault(k) => 1_000_000 + k,
        }
    }
}

/// One robot slot of the layout.
#[derive(Debug, Clone)]
pub struct RobotState {
    /// Whether the slot's agent runs (changed through [`World::set_in_fleet`]).
    in_fleet: bool,
    pub pose: Pose,
    /// Where the camera points when nothing else says where (spawn heading, or over
    /// the floor while patrolling).
    home_heading: f32,
    next_waypoint: usize,
    /// Under `track`: what the camera showed and where it looked.
    pan: PanUnit,
    detector: DetectorState,
    rng: ChaCha8Rng,
}

impl RobotState {
    pub fn is_in_fleet(&self) -> bool {
        self.in_fleet
    }
}

pub struct World {
    pub layout: Layout,
    pub scenario: Scenario,
    pub tick: u64,
    /// The capture time stamped on tick 0's frames (µs since the Unix epoch): frames of
    /// tick `t` are stamped `clock_epoch_us + t · TICK_US`. 0 for a virtual clock (the
    /// evaluation, datasets); a world serving live agents follows the wall clock
    /// ([`World::follow_clock`]).
    pub clock_epoch_us: u64,
    pub worker: Worker,
    pub robots: Vec<RobotState>,
    objects: Vec<Object>,
    /// Obstacles (scenarios 2, 3), objects, then robots: rebuilt when robots move,
    /// shared by every camera of the tick.
    occluders: Vec<Occluder>,
    appearance: Appearance,
    worker_rng: ChaCha8Rng,
    /// Where and when robots of the fleet detected the worker (what `track` cameras
    /// turn to).
    sightings: Sightings,
}

impl World {
    /// A world with the first `fleet` slots in the fleet.
    pub fn new(layout: Layout, scenario: Scenario, seed: u64, fleet: usize) -> World {
        let mut worker_rng = stream(seed, Stream::Worker);
        let worker = Worker::spawn(&layout, scenario.obstacles(), &mut worker_rng);
        let objects = layout.stations.iter().flat_map(|s| s.objects.iter().cloned()).collect();
        let robots = layout
            .robots
            .iter()
            .enumerate()
            .map(|(i, r)| RobotState {
                in_fleet: i < fleet,
                pose: Pose { position: r.spawn, heading: r.heading_deg.to_radians() },
                home_heading: r.heading_deg.to_radians(),
                next_waypoint: 1,
                pan: PanUnit::default(),
                detector: DetectorState::default(),
                rng: stream(seed, Stream::Detector(i)),
            })
            .collect();
        let mut world = World {
            layout,
            scenario,
            tick: 0,
            clock_epoch_us: 0,
            worker,
            robots,
            objects,
            occluders: Vec::new(),
            appearance: Appearance::new(),
            worker_rng,
            sightings: Sightings::default(),
        };
        world.refresh_occluders();
        world
    }

    /// Starts or stops the agent of robot slot `slot`.
    pub fn set_in_fleet(&mut self, slot: usize, in_fleet: bool) {
        self.robots[slot].in_fleet = in_fleet;
    }

    /// Advances everything by one tick.
    pub fn step(&mut self) {
        self.tick += 1;
        let robots: Vec<P2> = self.robots.iter().map(|r| r.pose.position).collect();
        self.worker.step(DT, &self.layout, self.scenario.obstacles(), &robots, &mut self.worker_rng);
        let centre = scale(self.layout.floor.size, 0.5);
        let worker = self.worker.position;
        let track = self.layout.camera.policy == CameraPolicy::Track;
        let sighting = self.sightings.fresh(self.tick);
        // Only `track` cameras split roles; fixed ones need no keeper worked out.
        let keeper = track
            .then(|| {
                let fleet = self.robots.iter().enumerate().filter(|(_, r)| r.in_fleet);
                pan::keeper(&self.sightings, self.tick, DT, fleet.map(|(slot, r)| (slot, r.pose.position, &r.pan)))
            })
            .flatten();
        let (floor, half_fov) = (self.layout.floor.size, self.layout.camera.fov_deg.to_radians() / 2.0);
        for (slot, r) in self.robots.iter_mut().enumerate() {
            if self.scenario.moving_robots() {
                let patrol = &self.layout.robots[slot].patrol;
                if patrol.len() >= 2 {
                    let target = patrol[r.next_waypoint % patrol.len()];
                    let to = sub(target, r.pose.position);
                    if norm(to) < 0.1 {
                        r.next_waypoint = (r.next_waypoint + 1) % patrol.len();
                    } else {
                        let next = add(r.pose.position, scale(unit(to), (ROBOT_SPEED * DT).min(norm(to))));
                        if dist(next, worker) > 1.0 {
                            r.pose.position = next; // robots yield to the worker
                        }
                    }
                    // A patrolling robot's pan unit keeps its camera over the floor.
                    r.home_heading = heading_to(r.pose.position, centre);
                }
            }
            let want = match sighting {
                _ if !(track && r.in_fleet) => r.home_heading,
                Some(p) if keeper.is_none_or(|k| k == slot) => heading_to(r.pose.position, p),
                _ => r.pan.look_round(r.pose.position, r.pose.heading, floor).unwrap_or(r.home_heading),
            };
            r.pose.heading += angle_diff(want, r.pose.heading).clamp(-PAN_PER_TICK, PAN_PER_TICK);
            if track {
                r.pan.looked_along(r.pose.heading, half_fov, self.tick);
            }
        }
        if self.scenario.moving_robots() {
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
        o.extend(self.robots.iter().map(|r| Occluder {
            footprint: Rect { min: r.pose.position, max: r.pose.position },
            circle: Some((r.pose.position, ROBOT_RADIUS)),
            height: ROBOT_HEIGHT,
        }));
    }

    /// When this tick's frames are captured (µs since the Unix epoch).
    pub fn capture_us(&self) -> u64 {
        self.clock_epoch_us + DetectionFrame::capture_at_tick(self.tick)
    }

    /// Stamps this tick's frames (and the ticks after, one period each) with the start
    /// of the fleet clock's tick that `now` (time since the Unix epoch) falls in: a
    /// world that serves live agents stamps its frames as a camera on the fleet's clock
    /// would, whenever it was started or restarted.
    pub fn follow_clock(&mut self, now: std::time::Duration) {
        let start = DetectionFrame::capture_at_tick(tick_at(now));
        self.clock_epoch_us = start.saturating_sub(DetectionFrame::capture_at_tick(self.tick));
    }

    /// The fleet clock's tick this world tick's frames are stamped with.
    pub fn clock_tick(&self) -> u64 {
        self.capture_us() / TICK_US
    }

    /// The detection frame of the robot in `slot`, published as `robot`.
    pub fn observe(&mut self, slot: usize, robot: &RobotId) -> DetectionFrame {
        let first_object = if self.scenario.obstacles() { self.layout.obstacles.len() } else { 0 };
        let own = first_object + self.objects.len() + slot;
        let scene = camera::Scene {
            layout: &self.layout,
            objects: &self.objects,
            occluders: &self.occluders,
            first_object,
            worker: &self.worker,
            appearance: &self.appearance,
        };
        let capture_us = self.capture_us();
        let r = &mut self.robots[slot];
        let frame = camera::detect(&scene, robot.clone(), capture_us, r.pose, Some(own), &mut r.detector, &mut r.rng);
        if frame.human.is_some() && r.in_fleet {
            r.pan.saw_worker(self.tick);
            self.sightings.record(self.worker.position, self.tick);
        }
        frame
    }

    /// Ground truth for this tick.
    pub fn truth(&self, robots: &[(usize, RobotId)]) -> TruthMsg {
        TruthMsg {
            tick: self.clock_tick(),
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

fn heading_to(from: P2, to: P2) -> f32 {
    let d = sub(to, from);
    d[1].atan2(d[0])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::generate;

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

    /// The truth of an episode: intent, phase and position, tick by tick.
    fn truth_sequence(layout: &Layout, fleet: usize, leave_at: Option<u64>, skip_slot: Option<usize>) -> Vec<String> {
        let mut w = World::new(layout.clone(), Scenario::Dynamic, 42, fleet);
        let ids = ids(fleet);
        let mut out = Vec::new();
        for t in 0..600 {
            w.step();
            if leave_at == Some(t) {
                w.set_in_fleet(fleet - 1, false);
            }
            for (slot, id) in ids.iter().enumerate() {
                if w.robots[slot].is_in_fleet() && Some(slot) != skip_slot {
                    w.observe(slot, id);
                }
            }
            out.push(format!("{} {:?} {:?}", w.worker.goal, w.worker.phase, w.worker.position));
        }
        out
    }

    #[test]
    fn the_worker_walks_the_same_whatever_the_fleet_and_its_faults() {
        for layout in [Layout::default_layout(), generate::layout(3), generate::layout(17)] {
            let one = truth_sequence(&layout, 1, None, None);
            assert_eq!(one, truth_sequence(&layout, 3, None, None), "3 robots");
            assert_eq!(one, truth_sequence(&layout, 8, None, None), "8 robots");
            assert_eq!(one, truth_sequence(&layout, 8, Some(300), None), "a robot leaving half-way");
            assert_eq!(one, truth_sequence(&layout, 3, None, Some(1)), "a camera that stops delivering");
        }
    }

    #[test]
    fn a_robots_frames_do_not_change_when_another_joins() {
        let frames_of_r0 = |fleet: usize| {
            let mut w = World::new(Layout::default_layout(), Scenario::Dynamic, 9, fleet);
            let ids = ids(fleet);
            (0..200)
                .map(|_| {
                    w.step();
                    let f = encode(&w.observe(0, &ids[0]));
                    for (slot, id) in ids.iter().enumerate().skip(1) {
                        w.observe(slot, id);
                    }
                    f
                })
                .collect::<Vec<_>>()
        };
        assert_eq!(frames_of_r0(1), frames_of_r0(5));
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

    /// Share of ticks on which some robot of a fleet of `n` sees the worker.
    fn coverage(policy: CameraPolicy, n: usize) -> f64 {
        let (mut seen, mut ticks) = (0, 0);
        for seed in 0..6 {
            let mut layout = generate::layout(100 + seed);
            layout.camera.policy = policy;
            let mut w = World::new(layout, Scenario::Dynamic, seed, n);
            let ids = ids(n);
            for _ in 0..300 {
                w.step();
                let mut any = false;
                for (slot, id) in ids.iter().enumerate() {
                    any |= w.observe(slot, id).human.is_some();
                }
                seen += usize::from(any);
                ticks += 1;
            }
        }
        seen as f64 / ticks as f64
    }

    #[test]
    fn tracking_cameras_keep_the_worker_in_view_more_often_than_fixed_ones() {
        for n in [1, 3] {
            let (fixed, track) = (coverage(CameraPolicy::Fixed, n), coverage(CameraPolicy::Track, n));
            assert!(track > fixed + 0.1, "{n} robots: track {track:.2} vs fixed {fixed:.2}");
        }
    }

    /// Mean number of a fleet of 3's cameras with the worker in view (range and field
    /// of view) on ticks when it walks, and on ticks when it has worked a second or more.
    fn cameras_on_the_worker(policy: CameraPolicy) -> (f64, f64) {
        let (mut walking, mut working) = ((0, 0), (0, 0));
        for seed in 0..6 {
            let mut layout = generate::layout(200 + seed);
            layout.camera.policy = policy;
            let mut w = World::new(layout, Scenario::Dynamic, seed, 3);
            let ids = ids(3);
            let mut working_for = 0;
            for _ in 0..600 {
                w.step();
                for (slot, id) in ids.iter().enumerate() {
                    w.observe(slot, id);
                }
                let on =
                    (0..3).filter(|&s| camera::in_view(&w.layout.camera, w.robots[s].pose, w.worker.position)).count();
                working_for = if w.worker.phase == WorkerPhase::Stationary { working_for + 1 } else { 0 };
                let tally = match (w.worker.phase, working_for) {
                    (WorkerPhase::Stationary, ..10) => continue,
                    (WorkerPhase::Stationary, _) => &mut working,
                    _ => &mut walking,
                };
                *tally = (tally.0 + on, tally.1 + 1);
            }
        }
        (walking.0 as f64 / walking.1 as f64, working.0 as f64 / working.1 as f64)
    }

    #[test]
    fn tracking_cameras_follow_a_walking_worker_and_look_round_while_it_works() {
        let (walking, working) = cameras_on_the_worker(CameraPolicy::Track);
        assert!(walking > 1.8, "{walking:.2} of 3 cameras on the walking worker");
        assert!(
            working < walking - 0.5,
            "{working:.2} of 3 cameras stay on a working worker ({walking:.2} on a walking one)"
        );
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
