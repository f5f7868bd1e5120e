//! What every robot of a fleet knows on the floor when each hears every other: each
//! robot's [`FloorView`] fed its own frames, its peers' landmarks and the team's
//! fused worker track and facing — what each engine holds when no message is lost. As
//! in the engine, a robot reads its peers' shares of the tick before (their estimates
//! carried forward a tick), since it votes as soon as its own frame is in. The
//! dataset export computes its training rows from it, and [`TeamFloor::warmed`] lets an
//! evaluation start from the maps of a fleet that has worked on the floor before.
//!
//! Why warm maps: a daemon keeps its station map for as long as it runs, so a fleet
//! that has worked on a floor for a while knows every station its cameras have ever
//! seen; an evaluation episode that starts with empty maps measures a fleet's first
//! seconds on a new floor, which is a different question.

use anyhow::Result;
use spwi_core::floor::{self, CameraCalibration, FloorView, StationMap};
use spwi_proto::{DetectionFrame, Landmark, RobotId, WorkerEstimate};
use spwi_world::layout::Layout;
use spwi_world::world::{Scenario, World};

#[derive(Clone)]
pub struct TeamFloor {
    views: Vec<FloorView>,
    /// What each robot shared in the last tick: what its peers read in this one.
    shared: Vec<Option<Shared>>,
}

/// One robot's share of a tick, as its embedding message carries it.
#[derive(Clone)]
struct Shared {
    tick: u64,
    estimate: Option<WorkerEstimate>,
    facing: Option<f32>,
    landmarks: Vec<Landmark>,
}

/// What one robot holds of a tick, after [`TeamFloor::observe_heard`].
#[derive(Debug, Clone)]
pub struct Heard {
    /// Its own estimate of the worker.
    pub own: Option<WorkerEstimate>,
    /// The team's track: its own estimate fused with the peers' it heard.
    pub team: Option<WorkerEstimate>,
    /// The peers' estimates in that fusion.
    pub peers: Vec<WorkerEstimate>,
    /// The team's facing of the worker: that of the robots whose estimates make the
    /// team's track ([`floor::fuse_facings`]).
    pub facing: Option<f32>,
}

impl TeamFloor {
    pub fn new(camera: CameraCalibration, robots: usize) -> Self {
        TeamFloor { views: vec![FloorView::new(camera); robots], shared: vec![None; robots] }
    }

    /// Puts first in each robot's frame (by slot) the person its engine would follow
    /// ([`FloorView::follow`]): call before [`TeamFloor::observe`] with the same frames.
    pub fn follow(&self, frames: &mut [DetectionFrame]) {
        for (view, frame) in self.views.iter().zip(frames) {
            view.follow(frame);
        }
    }

    /// One tick in which every robot hears every other: every robot's frame (by slot) in.
    pub fn observe(&mut self, frames: &[DetectionFrame]) -> Vec<Heard> {
        self.observe_heard(frames, |_, _| true)
    }

    /// One tick in which robot `listener` heard robot `speaker`'s share of the tick
    /// before only if `hears(listener, speaker)`: each robot's map takes the landmarks
    /// it heard, and its team track fuses its own estimate with the peers' it heard
    /// (carried forward to this tick), leaving out one most others contradict — as an
    /// engine does with the messages that reached it by the time its frame came.
    pub fn observe_heard(&mut self, frames: &[DetectionFrame], hears: impl Fn(usize, usize) -> bool) -> Vec<Heard> {
        let now: Vec<Shared> = self
            .views
            .iter_mut()
            .zip(frames)
            .map(|(v, f)| {
                let (estimate, landmarks) = v.observe(f);
                Shared { tick: f.tick(), estimate, facing: v.camera().facing_in(f), landmarks }
            })
            .collect();
        let mut heard = Vec::with_capacity(self.views.len());
        for (slot, view) in self.views.iter_mut().enumerate() {
            let tick = now[slot].tick;
            let peers: Vec<(usize, &Shared)> = (0..self.shared.len())
                .filter(|&p| p != slot && hears(slot, p))
                .filter_map(|p| Some((p, self.shared[p].as_ref()?)))
                .collect();
            for (_, s) in &peers {
                view.add_peer_landmarks(&s.landmarks, s.tick);
            }
            let own = now[slot].estimate;
            let theirs = peers.iter().map(|(p, s)| (*p, s.tick, s.estimate, s.facing));
            let held = floor::held_at(tick, own.map(|e| (slot, e, now[slot].facing)), theirs);
            let (robots, sightings) = floor::sightings(&held);
            let team = floor::team_worker(&sightings, |_| true);
            let peers = team.kept_peers(&sightings, |i| robots[i] == slot).into_iter().copied().collect();
            view.observe_worker(tick, own.as_ref(), team.track.as_ref());
            heard.push(Heard { own, team: team.track, peers, facing: team.facing });
        }
        self.shared = now.into_iter().map(Some).collect();
        heard
    }

    pub fn view(&self, slot: usize) -> &FloorView {
        &self.views[slot]
    }

    /// Each robot's own and team map.
    pub fn maps(&self) -> impl Iterator<Item = (&StationMap, &StationMap)> {
        self.views.iter().map(|v| (&v.own_map, &v.team_map))
    }

    /// The fleet of `robots` robots after `ticks` ticks of work on `layout`, watching
    /// another worker than the one an episode will score (the world of `seed`): the
    /// maps they built, fresh worker tracks. Deterministic in its arguments.
    pub fn warmed(layout: &Layout, scenario: Scenario, seed: u64, robots: usize, ticks: u32) -> Result<Self> {
        let camera = crate::calibration::of(&layout.camera);
        let mut team = TeamFloor::new(camera.clone(), robots);
        let mut world = World::new(layout.clone(), scenario, seed, robots);
        let ids: Vec<RobotId> = (0..robots).map(|i| RobotId::new(format!("r{i}"))).collect::<Result<_, _>>()?;
        for _ in 0..ticks {
            world.step();
            let frames: Vec<DetectionFrame> =
                ids.iter().enumerate().map(|(slot, id)| world.observe(slot, id)).collect();
            team.observe(&frames);
        }
        let views = team
            .views
            .into_iter()
            .map(|v| {
                let mut fresh = FloorView::new(camera.clone());
                (fresh.own_map, fresh.team_map) = (v.own_map, v.team_map);
                fresh
            })
            .collect();
        Ok(TeamFloor { views, shared: vec![None; robots] })
    }
}

/// The seed of the unscored world that warms the maps of the episode of `episode_seed`
/// (another worker, the same floor and robots).
pub fn warm_up_seed(episode_seed: u64) -> u64 {
    episode_seed ^ 0x5741_524d_5f4d_4150 // "WARM_MAP"
}

#[cfg(test)]
mod tests {
    use super::*;
    use spwi_proto::Station;
    use std::f32::consts::PI;

    #[test]
    fn a_robot_holds_the_track_of_the_peers_it_hears_and_nobody_elses() {
        let layout = Layout::default_layout();
        let camera = crate::calibration::of(&layout.camera);
        let (mut all, mut deaf, mut half) =
            (TeamFloor::new(camera.clone(), 4), TeamFloor::new(camera.clone(), 4), TeamFloor::new(camera, 4));
        let mut world = World::new(layout, Scenario::Dynamic, 9, 4);
        let ids: Vec<RobotId> = (0..4).map(|i| RobotId::new(format!("r{i}")).unwrap()).collect();
        let (mut fused_peers, mut shared_facings) = (0, 0);
        // Each robot's estimate and facing (while it has an estimate) of the tick before.
        let mut before: Vec<(Option<WorkerEstimate>, Option<f32>)> = vec![(None, None); 4];
        for _ in 0..100 {
            world.step();
            let frames: Vec<DetectionFrame> = ids.iter().enumerate().map(|(s, id)| world.observe(s, id)).collect();
            let own: Vec<_> = all.observe(&frames).into_iter().map(|h| h.own).collect();
            // A robot's facing counts for the team while its estimate does.
            let facing = |slot: usize| {
                own[slot].and_then(|_| crate::calibration::of(&world.layout.camera).facing_in(&frames[slot]))
            };
            for (slot, h) in deaf.observe_heard(&frames, |_, _| false).into_iter().enumerate() {
                assert_eq!((h.own, h.team, h.peers.len()), (own[slot], own[slot], 0), "alone: its own track");
                let same = match (h.facing, facing(slot)) {
                    (Some(a), Some(b)) => ((a - b + PI).rem_euclid(2.0 * PI) - PI).abs() < 1e-5,
                    (a, b) => a == b,
                };
                assert!(same, "and its own facing: {:?} vs {:?}", h.facing, facing(slot));
            }
            // Robot 0 hears robot 1 only: its peers are robot 1's estimate of the tick
            // before, carried forward a tick, fused with its own of this tick.
            let h = half.observe_heard(&frames, |l, s| l != 0 || s == 1).remove(0);
            let heard = before[1].0.map(|e| floor::track::predict(&e, 1));
            assert_eq!(h.peers, heard.into_iter().collect::<Vec<_>>());
            assert_eq!(h.team, floor::fuse(own[0].iter().chain(&heard)));
            assert_eq!(h.facing, floor::fuse_facings([facing(0), before[1].1].into_iter().flatten()));
            shared_facings += usize::from(facing(0).is_some() && before[1].1.is_some());
            fused_peers += h.peers.len();
            before = (0..4).map(|s| (own[s], facing(s))).collect();
        }
        assert!(fused_peers > 20, "robot 1 should see the worker on some ticks: {fused_peers}");
        assert!(shared_facings > 10, "both robots should see the body's facing on some ticks: {shared_facings}");
        let (own_maps, team_maps): (Vec<_>, Vec<_>) = deaf.maps().map(|(o, t)| (o.stations(), t.stations())).unzip();
        assert_eq!(own_maps, team_maps, "a robot that hears nobody maps only what it saw");
    }

    #[test]
    fn a_fleet_that_worked_on_the_floor_starts_with_its_stations_mapped() {
        let layout = Layout::default_layout();
        let cold = TeamFloor::warmed(&layout, Scenario::Dynamic, 5, 3, 0).unwrap();
        assert!(cold.maps().all(|(own, team)| own.stations() == [None; 4] && team.stations() == [None; 4]));
        let warm = TeamFloor::warmed(&layout, Scenario::Dynamic, 5, 3, 300).unwrap();
        let (_, team) = warm.maps().next().unwrap();
        let storage = team.station(Station::Storage).expect("storage, in front of a robot, is mapped");
        let objects = &layout.station(Station::Storage).objects;
        let nearest = objects.iter().map(|o| (storage[0] - o.position[0]).hypot(storage[1] - o.position[1]));
        assert!(nearest.fold(f32::INFINITY, f32::min) < 1.0, "{storage:?}: among its objects");
        for (own, team) in warm.maps() {
            for k in Station::ALL.into_iter().filter(|&k| own.station(k).is_some()) {
                assert!(team.station(k).is_some(), "what one robot mapped, its team map holds");
            }
        }
        assert!(warm.view(0).own_estimate(0).is_none(), "the warm-up's worker is not tracked");
        let again = TeamFloor::warmed(&layout, Scenario::Dynamic, 5, 3, 300).unwrap();
        assert!(again.maps().eq(warm.maps()), "deterministic");
    }
}
