//! What a robot knows on the floor, not only in its image: where the worker is and
//! where each station stands, in the floor frame every robot shares.
//!
//! Image coordinates mean nothing to a peer and nothing on another floor; floor
//! positions mean the same to every robot of the team and on every factory. So each
//! frame is back-projected through the robot's calibrated camera at its pose
//! ([`calibration`]), the worker is tracked with a constant-velocity filter
//! ([`track`]) whose estimate the robots share and fuse, everyone else in view is
//! tracked too so that the worker followed stays the same person ([`people`]) and
//! named with ids every robot of the team gives alike ([`worker_ids`]), the
//! station objects seen by any robot build a shared map ([`stations`]), and the temporal model reads the
//! worker's relation to every mapped station ([`relations`]) — distance, bearing
//! relative to the worker's motion, closing speed — never where a station stands.
//!
//! [`FloorView`] holds one robot's part of all this; the engine, the dataset export
//! and the evaluation's observers all use it, so training and serving compute the same
//! features.

pub mod calibration;
pub mod people;
pub mod plan;
pub mod relations;
pub mod stations;
pub mod track;
pub mod worker_ids;

pub use calibration::CameraCalibration;
pub use people::{People, Seen};
pub use plan::{FloorPlan, PlannedObstacle, PlannedStation};
pub use relations::{facing, fuse_facings, peer_set, relations, FACING_DIM, RELATION_DIM};
pub use stations::StationMap;
pub use track::{agrees_with_most, fuse, held_at, predict, sightings, team_worker, Sighting, TeamWorker, Track};
pub use worker_ids::{Minter, PeerList, WorkerIds};

use spwi_proto::{DetectionFrame, HumanDetection, Landmark, PersonShare, WorkerEstimate};

/// How far from where its track predicts the worker a person may stand and still be
/// the worker a robot follows, metres.
pub const FOLLOW_GATE_M: f32 = 1.5;
/// For how many ticks the team's track of the worker says whom to follow.
pub const TEAM_TRACK_TICKS: u64 = 5;

/// One robot's floor-frame state: its own worker track, the map of what it saw
/// itself and the map of what the whole team saw.
#[derive(Debug, Clone)]
pub struct FloorView {
    camera: CameraCalibration,
    track: Track,
    /// The team's track of the worker as of a tick: whom a robot follows among several
    /// people.
    team_track: Option<(u64, WorkerEstimate)>,
    /// Everyone in view, tracked on the floor, and which of them this robot follows.
    people: People,
    followed: Option<u32>,
    /// The team's id of each person tracked.
    names: WorkerIds,
    pub own_map: StationMap,
    pub team_map: StationMap,
}

impl FloorView {
    pub fn new(camera: CameraCalibration) -> Self {
        FloorView {
            camera,
            track: Track::default(),
            team_track: None,
            people: People::default(),
            followed: None,
            names: WorkerIds::default(),
            own_map: StationMap::default(),
            team_map: StationMap::default(),
        }
    }

    /// Seeds both station maps with a floor plan, if there is one.
    pub fn plan(&mut self, plan: Option<&FloorPlan>) {
        if let Some(p) = plan {
            self.own_map.plan(p);
            self.team_map.plan(p);
        }
    }

    pub fn camera(&self) -> &CameraCalibration {
        &self.camera
    }

    /// Takes in this robot's frame (the worker it follows first, [`FloorView::follow`]):
    /// updates its tracks of the worker and of everyone in view, and both maps. Returns
    /// the estimate and landmarks to share (none when the frame carries no pose).
    pub fn observe(&mut self, frame: &DetectionFrame) -> (Option<WorkerEstimate>, Vec<Landmark>) {
        let Some(pose) = frame.pose else { return (None, Vec::new()) };
        let seen = self.seen(&pose, &frame.humans);
        let placed: Vec<Seen> = seen.iter().flatten().copied().collect();
        let ids = self.people.observe(frame.tick(), &placed);
        // The worker is the frame's first person: placed, it is the first placed too.
        if let Some(Some(worker)) = seen.first() {
            self.followed = ids.first().copied();
            self.track.observe(frame.tick(), worker.floor, worker.sigma);
        }
        let landmarks = self.camera.landmarks(&pose, &frame.objects);
        for l in &landmarks {
            self.own_map.add(l, frame.tick());
            self.team_map.add(l, frame.tick());
        }
        (self.track.estimate(frame.tick()), landmarks)
    }

    /// Where each of `humans` stands on the floor (`None`: not placed from its keypoints).
    fn seen(&self, pose: &spwi_proto::FloorPose, humans: &[HumanDetection]) -> Vec<Option<Seen>> {
        humans
            .iter()
            .map(|h| {
                let (floor, sigma) = self.camera.worker_on_floor(pose, &h.keypoints)?;
                Some(Seen { floor, sigma, detector_id: h.track })
            })
            .collect()
    }

    /// Puts first the person of `frame` this robot follows, the worker its team tracks:
    /// with a pose and a fresh track — the team's (of the last [`TEAM_TRACK_TICKS`]
    /// ticks), else its own — the one nearest where the track predicts the worker, if
    /// within [`FOLLOW_GATE_M`] (if nobody is, the frame keeps nobody: the worker is not
    /// among them); without, the largest in the image. Following the team's track,
    /// robots that each started on another person come to follow the same one. One
    /// person is taken as the worker, as a frame of one worker always was.
    pub fn follow(&self, frame: &mut DetectionFrame) {
        if frame.humans.len() < 2 {
            return;
        }
        let tick = frame.tick();
        let team = self
            .team_track
            .filter(|(at, _)| *at <= tick && tick - at <= TEAM_TRACK_TICKS)
            .map(|(at, e)| track::predict(&e, tick - at));
        let (Some(tracked), Some(pose)) = (team.or_else(|| self.track.estimate(tick)), frame.pose) else {
            let area = |h: &HumanDetection| h.bbox.w * h.bbox.h;
            if let Some(largest) =
                (0..frame.humans.len()).max_by(|&a, &b| area(&frame.humans[a]).total_cmp(&area(&frame.humans[b])))
            {
                frame.humans.swap(0, largest);
            }
            return;
        };
        let seen = self.seen(&pose, &frame.humans);
        let placed: Vec<(usize, Seen)> = seen.iter().enumerate().filter_map(|(i, s)| Some((i, (*s)?))).collect();
        let tracks = self.people.assign(tick, &placed.iter().map(|(_, s)| *s).collect::<Vec<_>>());
        let off = |z: [f32; 2]| ((z[0] - tracked.position[0]).powi(2) + (z[1] - tracked.position[1]).powi(2)).sqrt();
        let near: Vec<(usize, f32, Option<u32>)> = placed
            .iter()
            .zip(tracks)
            .map(|(&(i, s), t)| (i, off(s.floor), t))
            .filter(|&(_, d, _)| d <= FOLLOW_GATE_M)
            .collect();
        // Of those where the worker is expected, the person followed so far (two
        // people close together stay apart on their own tracks), else the nearest.
        let kept = near.iter().find(|(_, _, t)| t.is_some() && *t == self.followed);
        match kept.or_else(|| near.iter().min_by(|a, b| a.1.total_cmp(&b.1))) {
            Some(&(i, _, _)) => frame.humans.swap(0, i),
            None => frame.humans.clear(),
        }
    }

    /// Names everyone this robot tracks at `tick` with the team's ids, from its peers'
    /// lists predicted to `tick` ([`worker_ids`]): what it shares of them. Called
    /// after [`FloorView::observe`] took in a frame with a pose.
    pub fn name_people(&mut self, tick: u64, me: Minter, peers: &[PeerList]) -> Vec<PersonShare> {
        self.names.name(tick, me, &self.people, peers)
    }

    /// The team's ids of the people this robot tracks.
    pub fn worker_ids(&self) -> &WorkerIds {
        &self.names
    }

    /// The team's track of the worker, if it was updated at `tick`.
    pub fn team_track(&self, tick: u64) -> Option<WorkerEstimate> {
        self.team_track.filter(|(t, _)| *t == tick).map(|(_, e)| e)
    }

    /// This robot's own estimate of the worker at `tick` (what it shares).
    pub fn own_estimate(&self, tick: u64) -> Option<WorkerEstimate> {
        self.track.estimate(tick)
    }

    /// The worker as this robot tracks it and as the team does, once per tick (`tick`):
    /// where it stands to work teaches each map its stations' work spots, and the
    /// team's track says whom to follow ([`FloorView::follow`]).
    pub fn observe_worker(&mut self, tick: u64, own: Option<&WorkerEstimate>, team: Option<&WorkerEstimate>) {
        if let Some(team) = team {
            self.team_track = Some((tick, *team));
        }
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

#[cfg(test)]
mod tests {
    use super::calibration::ANKLE_HEIGHT;
    use super::*;
    use spwi_proto::*;

    const POSE: FloorPose = FloorPose { position: [0.0, 0.0], heading: 0.0 };

    /// A person standing at `at` on the floor, `h` pixels tall in the image.
    fn person(view: &FloorView, at: [f32; 2], h: f32) -> HumanDetection {
        let (u, v) = view.camera().project(&POSE, [at[0], at[1], ANKLE_HEIGHT]).expect("in front of the camera");
        HumanDetection {
            bbox: BBox { x: u - h / 6.0, y: v - h, w: h / 3.0, h },
            keypoints: [u, v].repeat(KEYPOINT_VALUES / 2),
            feature: vec![0.0; FEATURE_DIM],
            track: None,
        }
    }

    fn frame(tick: u64, humans: Vec<HumanDetection>) -> DetectionFrame {
        DetectionFrame {
            robot: RobotId::new("r1").unwrap(),
            capture_us: DetectionFrame::capture_at_tick(tick),
            pose: Some(POSE),
            image_size: [640.0, 480.0],
            humans,
            objects: Vec::new(),
            scene_feature: vec![0.0; FEATURE_DIM],
        }
    }

    #[test]
    fn a_robot_follows_the_person_its_track_predicts_else_the_largest() {
        let mut view = FloorView::new(CameraCalibration::default());
        // Without a track: the largest person first.
        let mut f = frame(1, vec![person(&view, [6.0, 1.0], 80.0), person(&view, [4.0, -1.0], 160.0)]);
        view.follow(&mut f);
        assert_eq!(f.humans[0].bbox.h, 160.0);
        // The worker tracked at 5 m straight ahead for a second.
        for t in 1..=10 {
            let f = frame(t, vec![person(&view, [5.0, 0.0], 100.0)]);
            view.observe(&f);
        }
        // Another, larger person nearby: the one where the track predicts stays first.
        let mut f = frame(11, vec![person(&view, [3.5, 1.5], 200.0), person(&view, [5.1, 0.1], 90.0)]);
        view.follow(&mut f);
        assert_eq!((f.humans.len(), f.humans[0].bbox.h), (2, 90.0));
        // Only people far from it: none of them is the worker.
        let mut f = frame(12, vec![person(&view, [3.0, 2.0], 200.0), person(&view, [7.5, -2.0], 90.0)]);
        view.follow(&mut f);
        assert!(f.humans.is_empty(), "followed someone else");
        // One person is taken as the worker, as a frame of one worker always was.
        let mut f = frame(12, vec![person(&view, [3.0, 2.0], 200.0)]);
        view.follow(&mut f);
        assert_eq!(f.humans.len(), 1);
        // The team tracks the other one: the robot follows the team's.
        let team = WorkerEstimate { position: [3.5, 1.5], velocity: [0.0; 2], covariance: [0.1, 0.0, 0.1] };
        view.observe_worker(12, None, Some(&team));
        let mut f = frame(13, vec![person(&view, [5.1, 0.1], 90.0), person(&view, [3.6, 1.5], 200.0)]);
        view.follow(&mut f);
        assert_eq!(f.humans[0].bbox.h, 200.0, "followed its own track, not the team's");
        // A robot without a pose cannot place anyone on the floor: the largest in view.
        let mut f = frame(13, vec![person(&view, [3.6, 1.5], 90.0), person(&view, [5.1, 0.1], 120.0)]);
        f.pose = None;
        view.follow(&mut f);
        assert_eq!(f.humans[0].bbox.h, 120.0);
    }

    #[test]
    fn of_two_people_where_the_worker_is_expected_a_robot_keeps_the_one_it_followed() {
        let mut view = FloorView::new(CameraCalibration::default());
        // The worker W stands 5 m ahead; another person P walks up beside it.
        let at = |t: u64| [5.0, 2.5 - 0.12 * t as f32];
        for t in 1..=10 {
            let mut f = frame(t, vec![person(&view, at(t), 90.0), person(&view, [5.0, 0.0], 100.0)]);
            view.follow(&mut f);
            assert_eq!(f.humans[0].bbox.h, 100.0, "tick {t}: W, the larger, then the one tracked");
            view.observe(&f);
        }
        // The team's track puts the worker between them, nearer P: the robot stays with
        // W, whose track it holds, rather than take whoever is nearest the estimate.
        let team = WorkerEstimate { position: [5.0, 0.8], velocity: [0.0; 2], covariance: [0.1, 0.0, 0.1] };
        view.observe_worker(10, None, Some(&team));
        let mut f = frame(11, vec![person(&view, at(11), 90.0), person(&view, [5.0, 0.0], 100.0)]);
        view.follow(&mut f);
        assert_eq!(f.humans[0].bbox.h, 100.0, "took P, who stood nearer the team's estimate");
        assert_eq!(view.people.len(), 2);
    }
}
