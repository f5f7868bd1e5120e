//! The world: layout, scenario, worker, robots, and one tick of everything. Determined
//! by its seed: the same seed and the same fleet give the same frames, byte for byte.
//!
//! Every robot slot of the layout is a robot on the floor — it patrols, it occludes, the
//! worker steps round it — whether or not its agent runs. The *fleet* is the set of
//! slots whose agent runs: only they see through their cameras ([`World::observe`]),
//! and with the `track` camera policy only they share where the worker was last seen.
//! Randomness comes in independent streams (each worker, and each slot's detector), so
//! the worker's walk is the same whatever the fleet's size and whatever faults a tool
//! injects, and a robot's frames do not shift when another robot joins.
//!
//! A floor may hold up to [`MAX_WORKERS`] workers, each walking its own work cycle from
//! its own stream, stepping round the others and hiding them from the cameras. A world
//! of one worker is the same, value for value, as before there could be more. Frames
//! carry every worker in view; the truth describes the first (`workers[0]`), whom
//! the tools score, until the team decides per worker.

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

/// Most workers one floor holds.
pub const MAX_WORKERS: usize = 4;

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
    /// Worker k's walk and work.
    Worker(usize),
    /// Robot slot k's camera and detector.
    Detector(usize),
    /// A fault model of a tool (message loss, …), by its own number.
    Fault(u64),
}

impl Stream {
    fn id(self) -> u64 {
        match self {
            // The first worker's stream is the one a world of one worker always drew.
            Stream::Worker(0) => 1,
            Stream::Worker(k) => 2_000_000 + k as u64,
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
    /// One or more; the truth describes the first.
    pub workers: Vec<Worker>,
    pub robots: Vec<RobotState>,
    objects: Vec<Object>,
    /// Obstacles (scenarios 2, 3), objects, then robots: rebuilt when robots move,
    /// shared by every camera of the tick.
    occluders: Vec<Occluder>,
    appearance: Appearance,
    /// Each worker's stream.
    worker_rngs: Vec<ChaCha8Rng>,
    /// Where and when robots of the fleet detected the worker (what `track` cameras
    /// turn to).
    sightings: Sightings,
}

impl World {
    /// A world of one worker with the first `fleet` slots in the fleet.
    pub fn new(layout: Layout, scenario: Scenario, seed: u64, fleet: usize) -> World {
        World::with_workers(layout, scenario, seed, fleet, 1)
    }

    /// A world of `workers` workers (1..=[`MAX_WORKERS`]) with the first `fleet` slots
    /// in the fleet.
    pub fn with_workers(layout: Layout, scenario: Scenario, seed: u64, fleet: usize, workers: usize) -> World {
        assert!((1..=MAX_WORKERS).contains(&workers), "{workers} workers: 1..={MAX_WORKERS}");
        let mut worker_rngs: Vec<ChaCha8Rng> = (0..workers).map(|k| stream(seed, Stream::Worker(k))).collect();
        let workers = worker_rngs
            .iter_mut()
            .enumerate()
            .map(|(k, rng)| Worker::spawn_nth(&layout, scenario.obstacles(), k, rng))
            .collect();
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
            workers,
            robots,
            objects,
            occluders: Vec::new(),
            appearance: Appearance::new(),
            worker_rngs,
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
        for k in 0..self.workers.len() {
            let people: Vec<P2> =
                self.workers.iter().enumerate().filter(|&(j, _)| j != k).map(|(_, w)| w.position).collect();
            let obstacles = self.scenario.obstacles();
            self.workers[k].step(DT, &self.layout, obstacles, &robots, &people, &mut self.worker_rngs[k]);
        }
        let centre = scale(self.layout.floor.size, 0.5);
        let people: Vec<P2> = self.workers.iter().map(|w| w.position).collect();
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
                        if people.iter().all(|&p| dist(next, p) > 1.0) {
                            r.pose.position = next; // robots yield to the workers
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
            workers: &self.workers,
            appearance: &self.appearance,
        };
        let capture_us = self.capture_us();
        let r = &mut self.robots[slot];
        let (frame, first_seen) =
            camera::detect(&scene, robot.clone(), capture_us, r.pose, Some(own), &mut r.detector, &mut r.rng);
        // Cameras that track turn to the first worker, whom the truth describes.
        if first_seen && r.in_fleet {
            r.pan.saw_worker(self.tick);
            self.sightings.record(self.workers[0].position, self.tick);
        }
        frame
    }

    /// The worker the frames show (the first).
    pub fn worker(&self) -> &Worker {
        &self.workers[0]
    }

    /// Ground truth for this tick, of the worker the frames show.
    pub fn truth(&self, robots: &[(usize, RobotId)]) -> TruthMsg {
        let worker = self.worker();
        TruthMsg {
            tick: self.clock_tick(),
            intent: worker.goal,
            phase: worker.phase,
            worker_position: worker.position,
            worker_heading: worker.heading,
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
            out.push(format!("{} {:?} {:?}", w.worker().goal, w.worker().phase, w.worker().position));
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
                seen += usize::from(back.worker().is_some());
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
        w.workers[0].position = sub(p.position, [p.heading.cos() * 0.0, 0.5]);
        for _ in 0..20 {
            assert!(w.observe(0, &id).worker().is_none());
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
                    any |= w.observe(slot, id).worker().is_some();
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
                let on = (0..3)
                    .filter(|&s| camera::in_view(&w.layout.camera, w.robots[s].pose, w.worker().position))
                    .count();
                working_for = if w.worker().phase == WorkerPhase::Stationary { working_for + 1 } else { 0 };
                let tally = match (w.worker().phase, working_for) {
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

#[cfg(test)]
mod one_worker {
    use super::*;
    use crate::generate;

    /// FNV-1a over the values (not the encoding, which the protocol version changes)
    /// of every frame and truth message of an episode of 4 robots.
    pub(super) fn digest(layout: Layout, seed: u64, workers: usize) -> u64 {
        let mut w = World::with_workers(layout, Scenario::Dynamic, seed, 4, workers);
        let ids: Vec<(usize, RobotId)> = (0..4).map(|i| (i, RobotId::new(format!("r{i}")).unwrap())).collect();
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        let mut eat = |bytes: &[u8]| {
            for b in bytes {
                h = (h ^ u64::from(*b)).wrapping_mul(0x0100_0000_01b3);
            }
        };
        let floats = |v: &[f32]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
        let bbox = |b: &BBox| floats(&[b.x, b.y, b.w, b.h]);
        for _ in 0..300 {
            w.step();
            let t = w.truth(&ids);
            eat(&t.tick.to_le_bytes());
            eat(&[t.intent.index() as u8, t.phase as u8]);
            eat(&floats(&[t.worker_position[0], t.worker_position[1], t.worker_heading]));
            for r in &t.robots {
                eat(r.robot.as_str().as_bytes());
                eat(&floats(&[r.position[0], r.position[1], r.heading]));
            }
            for (slot, id) in &ids {
                let f = w.observe(*slot, id);
                eat(f.robot.as_str().as_bytes());
                eat(&f.capture_us.to_le_bytes());
                if let Some(p) = f.pose {
                    eat(&floats(&[p.position[0], p.position[1], p.heading]));
                }
                eat(&floats(&f.image_size));
                if let Some(person) = f.humans.first() {
                    eat(&bbox(&person.bbox));
                    eat(&floats(&person.keypoints));
                    eat(&floats(&person.feature));
                }
                for o in &f.objects {
                    eat(&[o.class as u8]);
                    eat(&bbox(&o.bbox));
                    eat(&floats(&[o.score]));
                    eat(&floats(&o.feature));
                }
                eat(&floats(&f.scene_feature));
            }
        }
        h
    }

    /// A world of one worker is the world there was before a floor could hold more,
    /// and before frames could carry several people: its frames and truth, value for
    /// value (digests taken then).
    #[test]
    fn one_worker_is_the_world_it_always_was() {
        let got = [digest(Layout::default_layout(), 7, 1), digest(generate::layout(3), 11, 1)];
        assert_eq!(got, [0x4047_d2f9_d0eb_21d3, 0x462d_14f5_57f2_e0d2]);
    }
}

#[cfg(test)]
mod several_workers {
    use super::*;
    use crate::generate;

    /// The goals worker `k` walks to, in order, over `ticks`.
    fn goals(layout: &Layout, seed: u64, workers: usize, k: usize, ticks: usize) -> Vec<Station> {
        let mut w = World::with_workers(layout.clone(), Scenario::Dynamic, seed, 3, workers);
        let mut goals = vec![w.workers[k].goal];
        for _ in 0..ticks {
            w.step();
            if goals.last() != Some(&w.workers[k].goal) {
                goals.push(w.workers[k].goal);
            }
        }
        goals
    }

    #[test]
    fn adding_a_worker_changes_no_other_workers_goals() {
        for (i, layout) in [Layout::default_layout(), generate::layout(5), generate::layout(21)].iter().enumerate() {
            let alone = goals(layout, 40 + i as u64, 1, 0, 1500);
            let among_three = goals(layout, 40 + i as u64, 3, 0, 1500);
            let n = alone.len().min(among_three.len());
            assert!(n >= 5, "{n} trips");
            assert_eq!(alone[..n], among_three[..n], "floor {i}: the first worker's goals");
            assert_eq!(goals(layout, 40 + i as u64, 2, 1, 1500)[..4], goals(layout, 40 + i as u64, 4, 1, 1500)[..4]);
        }
    }

    /// Four workers on one floor for two minutes: each keeps working (arrives at its
    /// goals), walking workers keep their distance, and two work at one station side by
    /// side now and then.
    #[test]
    fn workers_work_side_by_side_and_step_round_each_other() {
        for seed in 0..3 {
            let mut w = World::with_workers(generate::layout(30 + seed), Scenario::Dynamic, seed, 3, 4);
            let (mut closest, mut shared) = (f32::INFINITY, 0);
            for _ in 0..1200 {
                w.step();
                for a in 0..4 {
                    for b in a + 1..4 {
                        let (p, q) = (&w.workers[a], &w.workers[b]);
                        let walking =
                            |x: &Worker| x.phase != WorkerPhase::Stationary && dist(x.position, x.spot()) > 2.0;
                        if walking(p) && walking(q) {
                            closest = closest.min(dist(p.position, q.position));
                        }
                        let working = |x: &Worker| x.phase == WorkerPhase::Stationary;
                        if working(p) && working(q) && p.goal == q.goal {
                            shared += 1;
                            assert!(dist(p.position, q.position) > 0.45, "seed {seed}: two workers on one spot");
                        }
                    }
                }
            }
            assert!(
                w.workers.iter().all(|x| x.arrivals >= 5),
                "{:?}",
                w.workers.iter().map(|x| x.arrivals).collect::<Vec<_>>()
            );
            assert!(closest > 0.45, "seed {seed}: walking workers came within {closest:.2} m");
            assert!(shared > 0, "seed {seed}: no station was ever shared");
        }
    }

    #[test]
    fn a_worker_hides_another_from_a_camera() {
        let mut w = World::with_workers(Layout::default_layout(), Scenario::Obstacles, 5, 1, 2);
        let id = RobotId::new("r0").unwrap();
        let p = w.robots[0].pose;
        let ahead = |d: f32, side: f32| {
            let (c, s) = (p.heading.cos(), p.heading.sin());
            add(p.position, [d * c - side * s, d * s + side * c])
        };
        let frames_with =
            |w: &mut World, people: usize| (0..40).filter(|_| w.observe(0, &id).humans.len() == people).count();
        // Side by side, 5 m ahead: both seen.
        w.workers[0].position = ahead(5.0, 0.6);
        w.workers[1].position = ahead(5.0, -0.6);
        assert!(frames_with(&mut w, 2) > 20, "two people side by side");
        // One behind the other: never both.
        w.workers[0].position = ahead(5.0, 0.0);
        w.workers[1].position = ahead(2.5, 0.0);
        assert_eq!(frames_with(&mut w, 2), 0, "the worker behind another was seen");
        assert!(frames_with(&mut w, 1) > 20, "the one in front is seen");
    }
}
