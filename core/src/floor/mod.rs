//! What a robot knows on the floor, not only in its image: where the worker is and
//! where each station stands, in the floor frame every robot shares.
//!
//! Image coordinates mean nothing to a peer and nothing on another floor; floor
//! positions mean the same to every robot of the team and on every factory. So each
//! frame is back-projected through the robot's calibrated camera at its pose
//! ([`calibration`]), the worker is tracked with a constant-velocity filter
//! ([`track`]) whose estimate the robots share and fuse, the station objects seen by
//! any robot build a shared map ([`stations`]), and the temporal model reads the
//! worker's relation to every mapped station ([`relations`]) — distance, bearing
//! relative to the worker's motion, closing speed — never where a station stands.
//!
//! [`FloorView`] holds one robot's part of all this; the engine, the dataset export
//! and the evaluation's observers all use it, so training and serving compute the same
//! features.

pub mod calibration;
pub mod relations;
pub mod stations;
pub mod track;

pub use calibration::CameraCalibration;
pub use relations::{facing, fuse_facings, peer_set, relations, FACING_DIM, RELATION_DIM};
pub use stations::StationMap;
pub use track::{agrees_with_most, fuse, held_at, sightings, team_worker, Sighting, TeamWorker, Track};

use spwi_proto::{DetectionFrame, Landmark, WorkerEstimate};

/// One robot's floor-frame state: its own worker track, the map of what it saw
/// itself and the map of what the whole team saw.
#[derive(Debug, Clone)]
pub struct FloorView {
    camera: CameraCalibration,
    track: Track,
    pub own_map: StationMap,
    pub team_map: StationMap,
}

impl FloorView {
    pub fn new(camera: CameraCalibration) -> Self {
        FloorView { camera, track: Track::default(), own_map: StationMap::default(), team_map: StationMap::default() }
    }

    pub fn camera(&self) -> &CameraCalibration {
        &self.camera
    }

    /// Takes in this robot's frame: updates its track and both maps. Returns the
    /// estimate and landmarks to share (none when the frame carries no pose).
    pub fn observe(&mut self, frame: &DetectionFrame) -> (Option<WorkerEstimate>, Vec<Landmark>) {
        let Some(pose) = frame.pose else { return (None, Vec::new()) };
        if let Some(h) = &frame.human {
            if let Some((z, sigma)) = self.camera.worker_on_floor(&pose, &h.keypoints) {
                self.track.observe(frame.tick(), z, sigma);
            }
        }
        let landmarks = self.camera.landmarks(&pose, &frame.objects);
        for l in &landmarks {
            self.own_map.add(l, frame.tick());
            self.team_map.add(l, frame.tick());
        }
        (self.track.estimate(frame.tick()), landmarks)
    }

    /// This robot's own estimate of the worker at `tick` (what it shares).
    pub fn own_estimate(&self, tick: u64) -> Option<WorkerEstimate> {
        self.track.estimate(tick)
    }

    /// The worker as this robot tracks it and as the team does, once per tick: where
    /// it stands to work teaches each map its stations' work spots.
    pub fn observe_worker(&mut self, own: Option<&WorkerEstimate>, team: Option<&WorkerEstimate>) {
        self.own_map.observe_worker(own);
        self.team_map.observe_worker(team);
    }

    /// A peer's landmarks of `tick`, into the team map.
    pub fn add_peer_landmarks(&mut self, landmarks: &[Landmark], tick: u64) {
        for l in landmarks {
            self.team_map.add(l, tick);
        }
    }
}
