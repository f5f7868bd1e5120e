//! The worker: walks to a goal station around obstacles and moving robots, works there
//! for a while, picks another goal, and sometimes changes its mind on the way.
//!
//! Motion is a global plan plus reactive avoidance, as a person walks: the shortest
//! path over the corners of the obstacles (inflated by the worker's clearance) gives
//! the next waypoint; a social-force term pushes away from nearby robots and
//! obstacles; a step that would enter an obstacle is refused, so the worker never walks
//! through one. Over the last metres the worker slows down and turns its head to the
//! station's objects, as people do before they start work.
//!
//! Ground-truth intent is the goal the worker has committed to: the label changes in
//! the very tick the worker starts to turn or walk towards the new goal, not before.
//!
//! A floor may hold several workers. Each has its own spot at every station (the first
//! worker the station's work spot, the others a free place beside it, [`spots_of`]), so
//! two people can work at one station side by side, and each steps round the others
//! while walking as it steps round robots.

use crate::geometry::*;
use crate::layout::{Layout, WORKER_CLEARANCE};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use spwi_proto::{Station, WorkerPhase, NUM_CLASSES};

/// Preferred walking speed, m/s.
pub const SPEED: f32 = 1.2;
/// Within this distance of its work spot the worker has arrived.
pub const ARRIVED: f32 = 0.25;
/// How long a change of goal counts as a transition, s.
const TRANSITION_S: f32 = 2.0;
/// Within this distance of its work spot the worker slows down, metres.
const SLOW_RADIUS: f32 = 1.5;
/// Within this distance the worker looks at its goal's objects, metres.
const LOOK_RADIUS: f32 = 3.5;
/// How far the head turns from the body, and how fast, radians (per tick).
const HEAD_MAX: f32 = 1.2;
const HEAD_RATE: f32 = 0.25;

#[derive(Debug, Clone)]
pub struct Worker {
    pub position: P2,
    pub heading: f32,
    pub velocity: P2,
    pub goal: Station,
    pub phase: WorkerPhase,
    /// Seconds left to work at the station (Stationary) or in the transition.
    timer: f32,
    /// Whether this trip may still change its goal, and at what remaining distance.
    change_at: Option<f32>,
    /// Gait phase of the walking skeleton, radians.
    pub gait: f32,
    /// Where the head points, relative to the body's heading, radians.
    pub head_yaw: f32,
    /// Goal changes made so far (mid-way ones).
    pub goal_changes: u32,
    /// Trips finished at their labelled station.
    pub arrivals: u32,
    /// Where this worker works at each station, by class.
    spots: [P2; NUM_CLASSES],
}

/// How far from a station's work spot a worker other than the first works there.
pub const SIDE_BY_SIDE_M: f32 = 1.0;
/// How far a side-by-side spot keeps from robots' spawns and patrols, metres.
const ROBOT_CLEARANCE_M: f32 = 1.6;
/// Within this distance walking workers step round each other, metres.
const PERSONAL_SPACE_M: f32 = 1.2;

/// Where worker `k` of a floor works at each station: the work spot for the first; for
/// each other, in turn, the first free place (on the floor, clear of obstacles and the
/// stations' objects) one to three [`SIDE_BY_SIDE_M`] from the work spot and at least
/// that far from the places of the workers before it, away from the robots' paths if
/// any is (the work spot itself if there is none).
pub fn spots_of(layout: &Layout, with_obstacles: bool, k: usize) -> [P2; NUM_CLASSES] {
    // Clear of what pushes a walking worker away (obstacle faces within 0.6 m), so it
    // can stand there.
    let walls: Vec<Rect> =
        if with_obstacles { layout.obstacles.iter().map(|o| o.rect().inflate(0.7)).collect() } else { Vec::new() };
    let [w, h] = layout.floor.size;
    let objects: Vec<Rect> =
        layout.stations.iter().flat_map(|s| s.objects.iter().map(|o| o.footprint().inflate(0.3))).collect();
    // And, where it can be, clear of where robots stand and patrol: a robot yields to a
    // worker a metre away, while the worker steps back from a robot within 1.5 m.
    let robot_clearance = |p: P2| {
        let legs = layout.robots.iter().flat_map(|r| {
            let closing = r.patrol.last().zip(r.patrol.first()).map(|(a, b)| [*a, *b]);
            r.patrol.windows(2).map(|l| [l[0], l[1]]).chain(closing).chain(std::iter::once([r.spawn, r.spawn]))
        });
        legs.map(|[a, b]| segment_dist(a, b, p)).fold(f32::INFINITY, f32::min)
    };
    let free = |p: P2| {
        p[0] > 0.5
            && p[0] < w - 0.5
            && p[1] > 0.5
            && p[1] < h - 0.5
            && !walls.iter().chain(&objects).any(|r| r.contains(p))
    };
    Station::ALL.map(|class| {
        let spot = layout.station(class).work_spot;
        let mut taken = vec![spot];
        for j in 1..=k {
            // Three rings of eight directions, starting where worker j's differs.
            let candidates = (1..=3).flat_map(|ring| {
                (0..8).map(move |i| {
                    let a = (j as f32 - 1.0) * std::f32::consts::FRAC_PI_2 + i as f32 * std::f32::consts::FRAC_PI_4;
                    add(spot, scale([a.cos(), a.sin()], SIDE_BY_SIDE_M * ring as f32))
                })
            });
            let apart: Vec<P2> =
                candidates.filter(|&p| free(p) && taken.iter().all(|&t| dist(p, t) >= SIDE_BY_SIDE_M - 1e-3)).collect();
            let clear = apart.iter().find(|&&p| robot_clearance(p) > ROBOT_CLEARANCE_M);
            let roomiest = || apart.iter().max_by(|a, b| robot_clearance(**a).total_cmp(&robot_clearance(**b)));
            taken.push(clear.or_else(roomiest).copied().unwrap_or(spot));
        }
        taken[k]
    })
}

/// Obstacles the worker plans around, inflated by its clearance.
fn inflated(layout: &Layout, with_obstacles: bool) -> Vec<Rect> {
    if !with_obstacles {
        return Vec::new();
    }
    layout.obstacles.iter().map(|o| o.rect().inflate(WORKER_CLEARANCE)).collect()
}

fn visible(a: P2, b: P2, rects: &[Rect]) -> bool {
    !rects.iter().any(|r| r.blocks(a, b))
}

/// Whether a walk from `from` to `to` bends around an obstacle: the straight line
/// between them crosses one, inflated by the worker's clearance, as the worker plans.
pub fn route_bends(from: P2, to: P2, layout: &Layout, with_obstacles: bool) -> bool {
    !visible(from, to, &inflated(layout, with_obstacles))
}

/// The first waypoint of the shortest obstacle-free path from `from` to `to`
/// (visibility graph over the inflated obstacles' corners, pushed out a little).
pub fn next_waypoint(from: P2, to: P2, rects: &[Rect]) -> P2 {
    if visible(from, to, rects) {
        return to;
    }
    let mut nodes = vec![from, to];
    for r in rects {
        for c in r.inflate(0.05).corners() {
            if !rects.iter().any(|o| o.contains(c)) {
                nodes.push(c);
            }
        }
    }
    let n = nodes.len();
    let mut best = vec![f32::INFINITY; n];
    let mut prev = vec![usize::MAX; n];
    let mut done = vec![false; n];
    best[0] = 0.0;
    for _ in 0..n {
        let Some(u) = (0..n).filter(|&i| !done[i] && best[i].is_finite()).min_by(|&a, &b| best[a].total_cmp(&best[b]))
        else {
            break;
        };
        done[u] = true;
        if u == 1 {
            break;
        }
        for v in 0..n {
            if !done[v] && visible(nodes[u], nodes[v], rects) {
                let d = best[u] + dist(nodes[u], nodes[v]);
                if d < best[v] {
                    best[v] = d;
                    prev[v] = u;
                }
            }
        }
    }
    if prev[1] == usize::MAX {
        return to; // unreachable: walk straight and let the reactive layer cope
    }
    let mut v = 1;
    while prev[v] != 0 {
        v = prev[v];
    }
    nodes[v]
}

impl Worker {
    /// A worker at a random free position, heading to a random station.
    pub fn spawn(layout: &Layout, with_obstacles: bool, rng: &mut ChaCha8Rng) -> Worker {
        Worker::spawn_nth(layout, with_obstacles, 0, rng)
    }

    /// Worker `k` of a floor ([`spots_of`]), at a random free position, heading to a
    /// random station.
    pub fn spawn_nth(layout: &Layout, with_obstacles: bool, k: usize, rng: &mut ChaCha8Rng) -> Worker {
        let [w, h] = layout.floor.size;
        let rects = inflated(layout, with_obstacles);
        let position = loop {
            let p = [rng.gen_range(0.5..w - 0.5), rng.gen_range(0.5..h - 0.5)];
            if !rects.iter().any(|r| r.contains(p)) {
                break p;
            }
        };
        let mut worker = Worker {
            position,
            heading: rng.gen_range(-std::f32::consts::PI..std::f32::consts::PI),
            velocity: [0.0, 0.0],
            goal: Station::Storage,
            phase: WorkerPhase::Moving,
            timer: 0.0,
            change_at: None,
            gait: 0.0,
            head_yaw: 0.0,
            goal_changes: 0,
            arrivals: 0,
            spots: spots_of(layout, with_obstacles, k),
        };
        worker.new_trip(rng, None);
        worker
    }

    fn new_trip(&mut self, rng: &mut ChaCha8Rng, not: Option<Station>) {
        self.goal = loop {
            let g = Station::ALL[usize::from(rng.gen_range(0..NUM_CLASSES as u8))];
            if Some(g) != not {
                break g;
            }
        };
        let d = dist(self.position, self.spot());
        // One trip in four changes its goal somewhere along the way.
        self.change_at = (rng.gen::<f32>() < 0.25 && d > 4.0).then(|| rng.gen_range(1.5..d * 0.7));
    }

    /// Where this worker works at its goal.
    pub fn spot(&self) -> P2 {
        self.spots[self.goal.index()]
    }

    /// Advances the worker by `dt` seconds among `robots` (positions, radius 0.35 m)
    /// and the other workers (`people`).
    pub fn step(
        &mut self,
        dt: f32,
        layout: &Layout,
        with_obstacles: bool,
        robots: &[P2],
        people: &[P2],
        rng: &mut ChaCha8Rng,
    ) {
        let rects = inflated(layout, with_obstacles);
        match self.phase {
            WorkerPhase::Stationary => {
                self.velocity = [0.0, 0.0];
                self.timer -= dt;
                if self.timer > 0.0 {
                    self.turn_head(layout);
                    return;
                }
                // Committed to the next goal: the label changes now, and so does the motion.
                let here = self.goal;
                self.new_trip(rng, Some(here));
                self.phase = WorkerPhase::Moving;
            }
            WorkerPhase::Transition => {
                self.timer -= dt;
                if self.timer <= 0.0 {
                    self.phase = WorkerPhase::Moving;
                }
            }
            WorkerPhase::Moving => {}
        }
        let remaining = dist(self.position, self.spot());
        if remaining < ARRIVED {
            self.phase = WorkerPhase::Stationary;
            self.timer = rng.gen_range(2.0..6.0);
            self.arrivals += 1;
            self.velocity = [0.0, 0.0];
            return;
        }
        if self.change_at.is_some_and(|at| remaining < at) {
            self.change_at = None;
            let old = self.goal;
            self.new_trip(rng, Some(old));
            self.change_at = None;
            self.goal_changes += 1;
            self.phase = WorkerPhase::Transition;
            self.timer = TRANSITION_S;
        }
        let spot = self.spot();
        let waypoint = next_waypoint(self.position, spot, &rects);
        let remaining = dist(self.position, spot);
        // Slow down over the last metres (never below a quarter of the pace, so it arrives).
        let pace = SPEED * (remaining / SLOW_RADIUS).clamp(0.25, 1.0);
        let mut desired = scale(unit(sub(waypoint, self.position)), pace.min(remaining / dt));
        // Social force: robots within 1.5 m and obstacle faces within 0.6 m push away.
        for &r in robots {
            let away = sub(self.position, r);
            let d = norm(away);
            if d < 1.5 && d > 1e-3 {
                desired = add(desired, scale(unit(away), 1.2 * (1.5 - d) / 1.5));
            }
        }
        // Other people, while walking, push away and to the side (people pass each
        // other on the right); near its spot a worker goes to work beside them.
        for &p in people.iter().filter(|_| remaining > SLOW_RADIUS) {
            let away = sub(self.position, p);
            let d = norm(away);
            if d < PERSONAL_SPACE_M && d > 1e-3 {
                let push = 2.5 * (PERSONAL_SPACE_M - d) / PERSONAL_SPACE_M;
                let right = [away[1], -away[0]];
                desired = add(desired, add(scale(unit(away), push), scale(unit(right), push)));
            }
        }
        for r in &rects {
            let away = sub(self.position, r.closest(self.position));
            let d = norm(away);
            if d < 0.6 && d > 1e-3 {
                desired = add(desired, scale(unit(away), 0.5 * (0.6 - d) / 0.6));
            }
        }
        // Smooth velocity changes (a person does not turn on the spot).
        self.velocity = add(scale(self.velocity, 0.6), scale(desired, 0.4));
        let speed = norm(self.velocity);
        if speed > SPEED {
            self.velocity = scale(self.velocity, SPEED / speed);
        }
        let next = add(self.position, scale(self.velocity, dt));
        let [w, h] = layout.floor.size;
        let inside = |p: P2| p[0] > 0.2 && p[0] < w - 0.2 && p[1] > 0.2 && p[1] < h - 0.2;
        let walls: Vec<Rect> = layout.obstacles.iter().map(|o| o.rect().inflate(0.1)).collect();
        let free = |p: P2| inside(p) && (!with_obstacles || !walls.iter().any(|r| r.contains(p)));
        if free(next) {
            self.position = next;
        } else {
            // slide along whichever axis is free, else stay
            let sx = [next[0], self.position[1]];
            let sy = [self.position[0], next[1]];
            if free(sx) {
                self.position = sx;
            } else if free(sy) {
                self.position = sy;
            }
        }
        if norm(self.velocity) > 0.05 {
            self.heading = self.velocity[1].atan2(self.velocity[0]);
            self.gait += norm(self.velocity) * dt * 2.0 * std::f32::consts::PI / 1.3;
        }
        self.turn_head(layout);
    }

    /// Near its goal (or working there) the worker looks at the goal's objects;
    /// otherwise where it walks.
    fn turn_head(&mut self, layout: &Layout) {
        let station = layout.station(self.goal);
        let near = self.phase == WorkerPhase::Stationary || dist(self.position, self.spot()) < LOOK_RADIUS;
        let want = if near {
            let n = station.objects.len() as f32;
            let centre = station.objects.iter().fold([0.0, 0.0], |c, o| add(c, scale(o.position, 1.0 / n)));
            let to = sub(centre, self.position);
            let rel = to[1].atan2(to[0]) - self.heading;
            rel.sin().atan2(rel.cos()).clamp(-HEAD_MAX, HEAD_MAX)
        } else {
            0.0
        };
        self.head_yaw += (want - self.head_yaw).clamp(-HEAD_RATE, HEAD_RATE);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn plans_around_an_obstacle() {
        let r = [Rect { min: [4.0, -5.0], max: [6.0, 5.0] }];
        let w = next_waypoint([0.0, 0.0], [10.0, 0.0], &r);
        assert!(w != [10.0, 0.0] && (w[1].abs() > 4.9), "waypoint {w:?} must go round the wall");
        assert_eq!(next_waypoint([0.0, 6.0], [10.0, 6.0], &r), [10.0, 6.0]);
    }

    #[test]
    fn never_walks_through_an_obstacle_and_arrives_where_labelled() {
        let layout = Layout::default_layout();
        let walls: Vec<Rect> = layout.obstacles.iter().map(|o| o.rect()).collect();
        for seed in 0..12 {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let mut w = Worker::spawn(&layout, true, &mut rng);
            let mut label_before_stop = w.goal;
            let mut was_stationary = false;
            for _ in 0..3000 {
                let prev = w.position;
                w.step(0.1, &layout, true, &[[10.0, 0.8]], &[], &mut rng);
                assert!(
                    !walls.iter().any(|r| r.contains(w.position)),
                    "seed {seed}: inside an obstacle at {:?}",
                    w.position
                );
                assert!(!walls.iter().any(|r| r.blocks(prev, w.position)), "seed {seed}: stepped through an obstacle");
                let stationary = w.phase == WorkerPhase::Stationary;
                if stationary && !was_stationary {
                    // every labelled trip ends at its labelled station
                    assert_eq!(w.goal, label_before_stop);
                    assert!(dist(w.position, layout.station(w.goal).work_spot) < ARRIVED + 1e-3);
                }
                was_stationary = stationary;
                label_before_stop = w.goal;
            }
            assert!(w.arrivals >= 3, "seed {seed}: only {} arrivals in 300 s", w.arrivals);
        }
    }

    #[test]
    fn slows_down_before_its_work_spot_and_looks_at_the_station() {
        let layout = Layout::default_layout();
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let mut w = Worker::spawn(&layout, true, &mut rng);
        let (mut far, mut near, mut looked) = (Vec::new(), Vec::new(), 0);
        for _ in 0..3000 {
            w.step(0.1, &layout, true, &[], &[], &mut rng);
            let d = dist(w.position, layout.station(w.goal).work_spot);
            if w.phase != WorkerPhase::Stationary {
                let speed = norm(w.velocity);
                if d > 3.0 {
                    far.push(speed);
                } else if d < 0.8 {
                    near.push(speed);
                }
            } else {
                looked += usize::from(w.head_yaw.abs() > 0.05);
            }
        }
        let mean = |v: &[f32]| v.iter().sum::<f32>() / v.len() as f32;
        assert!(mean(&near) < 0.6 * mean(&far), "near {} vs far {}", mean(&near), mean(&far));
        assert!(looked > 0, "the head never turned to a station's objects");
    }

    #[test]
    fn the_label_changes_in_the_tick_the_worker_turns_to_its_new_goal() {
        let layout = Layout::default_layout();
        let mut checked = 0;
        for seed in 0..8 {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let mut w = Worker::spawn(&layout, true, &mut rng);
            for _ in 0..3000 {
                let (goal, velocity) = (w.goal, w.velocity);
                w.step(0.1, &layout, true, &[], &[], &mut rng);
                if w.goal == goal {
                    continue;
                }
                // In this very tick the motion changed towards the new goal's next waypoint.
                let rects: Vec<Rect> = layout.obstacles.iter().map(|o| o.rect().inflate(WORKER_CLEARANCE)).collect();
                let to = unit(sub(next_waypoint(w.position, layout.station(w.goal).work_spot, &rects), w.position));
                // The velocity changed towards it (a turn, or braking for a U-turn), or was
                // already headed its way.
                let change = sub(w.velocity, velocity);
                let towards = change[0] * to[0] + change[1] * to[1] > 0.0;
                let headed = norm(w.velocity) > 0.05
                    && (w.velocity[0] * to[0] + w.velocity[1] * to[1]) / norm(w.velocity) > 0.95;
                assert!(
                    towards || headed,
                    "seed {seed}: label changed, motion did not: {velocity:?} -> {:?}, towards {to:?}",
                    w.velocity
                );
                checked += 1;
            }
        }
        assert!(checked > 20, "only {checked} goal changes seen");
    }
}
