//! What every robot of a fleet knows on the floor when each hears every other: each
//! robot's [`FloorView`] fed its own frames, its peers' landmarks and the team's
//! fused worker track — what each engine's floor holds when no message is lost. The
//! dataset export computes its training rows from it, and [`TeamFloor::warmed`] lets an
//! evaluation start from the maps of a fleet that has worked on the floor before.
//!
//! Why warm maps: a daemon keeps its station map for as long as it runs, so a fleet
//! that has worked on a floor for a while knows every station its cameras have ever
//! seen; an evaluation episode that starts with empty maps measures a fleet's first
//! seconds on a new floor, which is a different question.

use anyhow::Result;
use spwi_agent::floor::{self, CameraCalibration, FloorView, StationMap};
use spwi_proto::{DetectionFrame, RobotId, WorkerEstimate};
use spwi_world::layout::Layout;
use spwi_world::world::{Scenario, World};

pub struct TeamFloor {
    views: Vec<FloorView>,
}

impl TeamFloor {
    pub fn new(camera: CameraCalibration, robots: usize) -> Self {
        TeamFloor { views: vec![FloorView::new(camera); robots] }
    }

    /// One tick: every robot's frame (by slot) in. Returns each robot's own estimate of
    /// the worker and the team's fused one.
    pub fn observe(&mut self, frames: &[DetectionFrame]) -> (Vec<Option<WorkerEstimate>>, Option<WorkerEstimate>) {
        let shared: Vec<_> = self.views.iter_mut().zip(frames).map(|(v, f)| v.observe(f)).collect();
        let team = floor::fuse(shared.iter().filter_map(|(w, _)| w.as_ref()));
        for (slot, view) in self.views.iter_mut().enumerate() {
            for (peer, (_, landmarks)) in shared.iter().enumerate() {
                if peer != slot {
                    view.add_peer_landmarks(landmarks);
                }
            }
            view.observe_worker(shared[slot].0.as_ref(), team.as_ref());
        }
        (shared.into_iter().map(|(w, _)| w).collect(), team)
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
        Ok(TeamFloor { views })
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
