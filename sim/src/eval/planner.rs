//! A yardstick that plans: Bayesian goal inference over the candidate stations
//! ("inverse planning", after Baker, Saxe and Tenenbaum, 2009), the way a planner that
//! knows the floor would read the worker's walk.
//!
//! - **Paths**: the distance from any point to a station's work spot is the length of
//!   the shortest obstacle-free path to it — over the visibility graph of the
//!   obstacles' corners, the obstacles inflated by the worker's clearance, Dijkstra
//!   from each spot (`pathfinding`'s). So a walk that bends around a rack makes
//!   progress towards a station behind it, which a straight line cannot see.
//! - **Likelihood**: a noisily rational worker walks towards its goal: a step that
//!   shortens the path to station k by Δₖ metres is `exp(β Δₖ)` times as likely under
//!   goal k as a step that leaves it as far ([`BETA`]). Applied tick by tick to the
//!   team's track of the worker.
//! - **Prior for switching goals**: while it walks, the worker may change its mind: each
//!   tick [`SWITCH_PER_TICK`] of the belief moves evenly to the other stations. A worker
//!   standing within [`AT_STATION_M`] of a station works there (the prediction is that
//!   station); its next goal is, a priori, any other station alike.
//!
//! The prediction at t is the most probable goal; like the constant-velocity model it
//! says the same for every future step. It runs on the team's shared track with the
//! stations of the team's map (what the robots know), and with the true work spots
//! (what the constant-velocity baseline is handed). Its constants are the worker's
//! physics and a round rationality, not fitted to any floor or score.

use pathfinding::directed::dijkstra::dijkstra_all;
use spwi_proto::{Station, NUM_CLASSES};
use spwi_world::geometry::{dist, Rect, P2};
use spwi_world::layout::{Layout, WORKER_CLEARANCE};

/// Rationality, per metre of progress: one metre walked towards one station rather
/// than another multiplies its odds by e³ ≈ 20 (about a second of walking at 1.2 m/s).
pub const BETA: f32 = 3.0;
/// The share of the belief that moves to other goals each tick of walking (a change of
/// mind every 10 s of walking, on average).
pub const SWITCH_PER_TICK: f32 = 0.01;
/// Below this speed (m/s) the worker stands.
const STANDING: f32 = 0.15;
/// A worker standing this close to a station works there (m): the team's map places a
/// station a metre or two from where the worker stands at it until it has watched the
/// worker there.
pub const AT_STATION_M: f32 = 2.0;
/// A goal that moved this far (the team's map refining it) gets its paths again (m).
const REPLAN_M: f32 = 0.2;
/// A track silent longer than this (s) starts the walk afresh (the belief stays).
const GAP_S: f32 = 1.0;

/// Shortest obstacle-free path lengths to a set of goals.
#[derive(Debug, Clone)]
struct Paths {
    rects: Vec<Rect>,
    /// The obstacles' corners, pushed out a little off the inflated rectangles.
    corners: Vec<P2>,
    /// Which corners see each other.
    sees: Vec<Vec<bool>>,
    /// Per goal: its place, and the path length from each corner to it.
    goals: Vec<(Station, P2, Vec<f32>)>,
}

impl Paths {
    fn new(rects: Vec<Rect>) -> Paths {
        let corners: Vec<P2> = rects
            .iter()
            .flat_map(|r| r.inflate(0.05).corners())
            .filter(|&c| !rects.iter().any(|o| o.contains(c)))
            .collect();
        let sees = corners.iter().map(|&a| corners.iter().map(|&b| visible(a, b, &rects)).collect()).collect();
        Paths { rects, corners, sees, goals: Vec::new() }
    }

    /// Plans the paths to `goals`, keeping those of goals that have not moved.
    fn plan(&mut self, goals: &[(Station, P2)]) {
        let kept = std::mem::take(&mut self.goals);
        for &(k, at) in goals {
            match kept.iter().find(|(g, p, _)| *g == k && dist(*p, at) < REPLAN_M) {
                Some(same) => self.goals.push(same.clone()),
                None => {
                    let to_goal = self.corner_lengths_to(at);
                    self.goals.push((k, at, to_goal));
                }
            }
        }
    }

    /// Dijkstra from `goal` over the corners (costs in millimetres): each corner's path
    /// length to it.
    fn corner_lengths_to(&self, goal: P2) -> Vec<f32> {
        let n = self.corners.len();
        let point = |i: usize| if i == n { goal } else { self.corners[i] };
        let mm = |a: P2, b: P2| (dist(a, b) * 1000.0).round() as u64;
        let reached = dijkstra_all(&n, |&i| {
            (0..n)
                .filter(move |&j| {
                    j != i && if i == n { visible(goal, self.corners[j], &self.rects) } else { self.sees[i][j] }
                })
                .map(move |j| (j, mm(point(i), point(j))))
                .collect::<Vec<_>>()
        });
        (0..n).map(|i| reached.get(&i).map_or(f32::INFINITY, |&(_, c)| c as f32 / 1000.0)).collect()
    }

    /// The path length from `x` to each goal, in the order they were planned.
    fn lengths(&self, x: P2) -> Vec<f32> {
        let seen: Vec<usize> = (0..self.corners.len()).filter(|&i| visible(x, self.corners[i], &self.rects)).collect();
        self.goals
            .iter()
            .map(|(_, at, to_goal)| {
                if visible(x, *at, &self.rects) {
                    return dist(x, *at);
                }
                let around = seen.iter().map(|&i| dist(x, self.corners[i]) + to_goal[i]).fold(f32::INFINITY, f32::min);
                // Inside an inflated obstacle (a noisy track) nothing is visible: straight.
                if around.is_finite() {
                    around
                } else {
                    dist(x, *at)
                }
            })
            .collect()
    }
}

fn visible(a: P2, b: P2, rects: &[Rect]) -> bool {
    !rects.iter().any(|r| r.blocks(a, b))
}

/// One robot's goal inference over one set of stations.
#[derive(Debug, Clone)]
pub struct Planner {
    paths: Paths,
    /// The probability of each station being the goal (0 for stations not candidates).
    belief: [f32; NUM_CLASSES],
    /// The previous tick's place, time (s) and path lengths from there.
    last: Option<(P2, f32, Vec<f32>)>,
    /// The station the worker stands at, if it does.
    at: Option<Station>,
}

impl Planner {
    /// A planner on `layout`'s floor (its obstacles if `with_obstacles`).
    pub fn on_floor(layout: &Layout, with_obstacles: bool) -> Planner {
        let obstacles = layout.obstacles.iter().filter(|_| with_obstacles).map(|o| o.rect());
        Planner::around(obstacles)
    }

    /// A planner whose paths go around `obstacles` (inflated by the worker's clearance).
    pub fn around(obstacles: impl Iterator<Item = Rect>) -> Planner {
        let rects = obstacles.map(|r| r.inflate(WORKER_CLEARANCE)).collect();
        Planner { paths: Paths::new(rects), belief: [0.0; NUM_CLASSES], last: None, at: None }
    }

    /// The worker at `x` moving at `speed` (m/s) at time `t_s` (s), the candidate
    /// stations at `goals`: the belief follows, and the predicted goal comes back
    /// (`None` without candidates).
    pub fn observe(&mut self, t_s: f32, x: P2, speed: f32, goals: &[(Station, P2)]) -> Option<Station> {
        if goals.is_empty() {
            self.last = None;
            return None;
        }
        let candidates_changed = goals.len() != self.paths.goals.len()
            || goals.iter().zip(&self.paths.goals).any(|(&(k, at), (g, p, _))| k != *g || dist(at, *p) >= REPLAN_M);
        if candidates_changed {
            self.paths.plan(goals);
            self.admit(goals.iter().map(|&(k, _)| k));
            self.last = self.last.take().map(|(p, t, _)| (p, t, self.paths.lengths(p)));
        }
        let now = self.paths.lengths(x);
        // The progress made towards each candidate since the last tick, if the walk goes on.
        let progress: Option<Vec<f32>> = self
            .last
            .as_ref()
            .filter(|(_, t, _)| t_s - t <= GAP_S)
            .map(|(_, _, before)| before.iter().zip(&now).map(|(b, n)| b - n).collect());
        let nearest = goals.iter().zip(&now).min_by(|a, b| a.1.total_cmp(b.1)).map(|(&(k, _), &d)| (k, d));
        match (progress, nearest) {
            (Some(_), Some((k, d))) if speed < STANDING && d <= AT_STATION_M => self.stand_at(k),
            (Some(progress), _) => {
                self.at = None;
                self.walk(&progress);
            }
            (None, _) => {
                if self.belief.iter().all(|&b| b == 0.0) {
                    self.admit(goals.iter().map(|&(k, _)| k));
                }
            }
        }
        self.last = Some((x, t_s, now));
        self.prediction()
    }

    /// Candidates now: a station that joins gets the mean belief, one that leaves none.
    fn admit(&mut self, candidates: impl Iterator<Item = Station>) {
        let mut next = [0.0; NUM_CLASSES];
        let held: Vec<Station> = candidates.collect();
        let mean = 1.0 / held.len() as f32;
        for &k in &held {
            next[k.index()] = if self.belief[k.index()] > 0.0 { self.belief[k.index()] } else { mean };
        }
        self.belief = next;
        self.normalise();
    }

    /// The worker works at `k`: the prediction is `k`, and its next goal any other
    /// candidate alike.
    fn stand_at(&mut self, k: Station) {
        self.at = Some(k);
        let others: Vec<usize> =
            self.paths.goals.iter().map(|(g, _, _)| g.index()).filter(|&i| i != k.index()).collect();
        self.belief = [0.0; NUM_CLASSES];
        for &i in &others {
            self.belief[i] = 1.0 / others.len() as f32;
        }
        if others.is_empty() {
            self.belief[k.index()] = 1.0;
        }
    }

    /// One tick of walking: the switching prior, then the likelihood of the progress
    /// made towards each candidate (in the order planned).
    fn walk(&mut self, progress: &[f32]) {
        let ks: Vec<usize> = self.paths.goals.iter().map(|(k, _, _)| k.index()).collect();
        if ks.len() > 1 {
            let moved = SWITCH_PER_TICK / (ks.len() - 1) as f32;
            let old = self.belief;
            for &i in &ks {
                self.belief[i] = old[i] * (1.0 - SWITCH_PER_TICK) + (1.0 - old[i]) * moved;
            }
        }
        // exp(β Δ) relative to the best progress, so that nothing underflows.
        let best = progress.iter().copied().filter(|d| d.is_finite()).fold(f32::NEG_INFINITY, f32::max);
        for (&i, &d) in ks.iter().zip(progress) {
            let l = if d.is_finite() && best.is_finite() { (BETA * (d - best)).exp() } else { 1.0 };
            self.belief[i] *= l;
        }
        self.normalise();
    }

    fn normalise(&mut self) {
        let sum: f32 = self.belief.iter().sum();
        if sum > 0.0 && sum.is_finite() {
            self.belief.iter_mut().for_each(|b| *b /= sum);
        }
    }

    /// The station the worker stands at, else the most probable goal.
    fn prediction(&self) -> Option<Station> {
        if let Some(k) = self.at {
            return Some(k);
        }
        let (i, &b) = self.belief.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1))?;
        (b > 0.0).then(|| Station::ALL[i])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SPOTS: [(Station, P2); 4] = [
        (Station::Storage, [1.0, 1.0]),
        (Station::Workstation, [9.0, 1.0]),
        (Station::Assembly, [9.0, 9.0]),
        (Station::Manufacturing, [1.0, 9.0]),
    ];

    /// Walks from `from` to `to` at 1.2 m/s from time `t0`, feeding the planner; its
    /// last prediction.
    fn walk(p: &mut Planner, from: P2, to: P2, t0: f32, goals: &[(Station, P2)]) -> Option<Station> {
        let steps = (dist(from, to) / 0.12).ceil() as usize;
        let mut last = None;
        for s in 0..=steps {
            let f = s as f32 / steps as f32;
            let x = [from[0] + (to[0] - from[0]) * f, from[1] + (to[1] - from[1]) * f];
            last = p.observe(t0 + 0.1 * s as f32, x, if s == 0 { 0.0 } else { 1.2 }, goals);
        }
        last
    }

    #[test]
    fn a_worker_walking_straight_at_a_station_is_read_as_heading_there() {
        let mut p = Planner::around(std::iter::empty());
        assert_eq!(walk(&mut p, [5.0, 5.0], [8.0, 8.0], 0.0, &SPOTS), Some(Station::Assembly));
    }

    /// A wall stands between the worker and the station above it; the way there runs
    /// round the wall's right end. Walking that way reads as heading for the station
    /// behind the wall, though the straight line points at the workstation.
    #[test]
    fn a_walk_round_an_obstacle_reads_as_progress_to_the_station_behind_it() {
        let wall = Rect { min: [-5.0, 5.0], max: [8.5, 5.4] };
        let goals = [(Station::Workstation, [9.5, 2.0]), (Station::Assembly, [2.0, 8.0])];
        let mut p = Planner::around(std::iter::once(wall));
        assert_eq!(walk(&mut p, [5.0, 3.0], [8.5, 4.5], 0.0, &goals), Some(Station::Assembly));
        // Without the wall, the same walk heads for the workstation.
        let mut open = Planner::around(std::iter::empty());
        assert_eq!(walk(&mut open, [5.0, 3.0], [8.5, 4.5], 0.0, &goals), Some(Station::Workstation));
    }

    #[test]
    fn a_worker_standing_at_a_station_works_there_and_then_goes_anywhere_else() {
        let mut p = Planner::around(std::iter::empty());
        p.observe(0.0, [1.2, 1.1], 0.0, &SPOTS);
        for s in 1..20 {
            assert_eq!(p.observe(0.1 * s as f32, [1.2, 1.1], 0.05, &SPOTS), Some(Station::Storage));
        }
        assert_eq!(p.belief[Station::Storage.index()], 0.0, "the next goal is another station");
        assert_eq!(walk(&mut p, [1.2, 1.1], [1.2, 5.0], 2.0, &SPOTS), Some(Station::Manufacturing));
    }

    #[test]
    fn stations_that_join_the_map_become_candidates() {
        let mut p = Planner::around(std::iter::empty());
        assert_eq!(p.observe(0.0, [5.0, 5.0], 0.0, &[]), None);
        assert_eq!(walk(&mut p, [5.0, 5.0], [6.0, 4.0], 0.1, &SPOTS[..1]), Some(Station::Storage), "the only one");
        assert_eq!(walk(&mut p, [6.0, 4.0], [8.0, 2.0], 1.3, &SPOTS[..2]), Some(Station::Workstation));
    }

    /// A worker that changes its mind mid-walk is followed within a couple of seconds.
    #[test]
    fn a_change_of_goal_is_followed() {
        let mut p = Planner::around(std::iter::empty());
        assert_eq!(walk(&mut p, [5.0, 5.0], [8.0, 8.0], 0.0, &SPOTS), Some(Station::Assembly));
        assert_eq!(walk(&mut p, [8.0, 8.0], [5.5, 8.0], 3.6, &SPOTS), Some(Station::Manufacturing));
    }
}
