//! The payloads. Plain serde structs; [`crate::codec`] encodes them and calls
//! [`Validate::validate`] on everything it decodes, so a value of these types that came
//! from the network has the dimensions documented here and only finite floats.

use crate::id::{RobotId, WorkerId};
use crate::station::{Station, NUM_CLASSES};
use serde::{Deserialize, Serialize};

/// Length of an appearance feature (the paper's ResNet50 output) and of the global
/// scene feature.
pub const FEATURE_DIM: usize = 512;
/// 17 COCO keypoints, (x, y) each, in image pixels.
pub const KEYPOINT_VALUES: usize = 34;
/// Length of the GCN's human-node embedding that robots share.
pub const EMBEDDING_DIM: usize = 128;
/// The period of a tick: every frame, vote and decision belongs to one (10 Hz).
pub const TICK_PERIOD: std::time::Duration = std::time::Duration::from_micros(TICK_US);
/// Ticks in a second of the fleet's clock: the rate at which the team decides.
pub const TICKS_PER_SECOND: u32 = 10;
/// [`TICK_PERIOD`] in microseconds: tick `t` is the fleet clock's period
/// `[t · TICK_US, (t + 1) · TICK_US)` µs after the Unix epoch.
pub const TICK_US: u64 = 1_000_000 / TICKS_PER_SECOND as u64;

/// The tick a moment of the fleet's clock (time since the Unix epoch) falls in.
pub fn tick_at(t: std::time::Duration) -> u64 {
    (t.as_micros() / u128::from(TICK_US)) as u64
}

/// When tick `t` starts on the fleet's clock (time since the Unix epoch).
pub fn tick_start(t: u64) -> std::time::Duration {
    std::time::Duration::from_micros(t.saturating_mul(TICK_US))
}
/// Most object detections one frame may carry.
pub const MAX_OBJECTS: usize = 64;
/// Most steps (t plus forecast) one vote or decision may carry.
pub const MAX_STEPS: usize = 128;
/// Most members one decision may list.
pub const MAX_MEMBERS: usize = 1024;
/// Most floor landmarks one embedding message may carry.
pub const MAX_LANDMARKS: usize = MAX_OBJECTS;

/// Why a value failed validation: the field and what is wrong with it.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("field `{field}`: {problem}")]
pub struct Invalid {
    pub field: &'static str,
    pub problem: String,
}

fn invalid(field: &'static str, problem: impl Into<String>) -> Invalid {
    Invalid { field, problem: problem.into() }
}

/// Checked on every decoded message.
pub trait Validate {
    fn validate(&self) -> Result<(), Invalid>;
}

fn finite(field: &'static str, xs: &[f32]) -> Result<(), Invalid> {
    match xs.iter().position(|x| !x.is_finite()) {
        Some(i) => Err(invalid(field, format!("value {i} is {} (must be finite)", xs[i]))),
        None => Ok(()),
    }
}

fn dim(field: &'static str, xs: &[f32], want: usize) -> Result<(), Invalid> {
    if xs.len() != want {
        return Err(invalid(field, format!("has {} values, expected {want}", xs.len())));
    }
    finite(field, xs)
}

/// An axis-aligned box in image pixels: top-left corner, width, height.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct BBox {
    pub x: f32,
    pub y: f32,
    pub w: f32,
    pub h: f32,
}

impl BBox {
    pub fn center(&self) -> (f32, f32) {
        (self.x + self.w / 2.0, self.y + self.h / 2.0)
    }
    fn validate(&self, field: &'static str) -> Result<(), Invalid> {
        finite(field, &[self.x, self.y, self.w, self.h])?;
        if self.w < 0.0 || self.h < 0.0 {
            return Err(invalid(field, "negative width or height"));
        }
        Ok(())
    }
}

/// What kind of object a detection is (paper Table I), plus anything else a detector
/// may report. The station an object marks is [`ObjectClass::station`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, schemars::JsonSchema)]
pub enum ObjectClass {
    Crate,
    Box,
    Pallet,
    Desk,
    Chair,
    StorageDrawer,
    Computer,
    Workbench,
    CncMachine,
    Table,
    /// Not a station object (clutter, a robot, a false positive of unknown kind).
    Other,
}

impl ObjectClass {
    pub const ALL: [ObjectClass; 11] = [
        ObjectClass::Crate,
        ObjectClass::Box,
        ObjectClass::Pallet,
        ObjectClass::Desk,
        ObjectClass::Chair,
        ObjectClass::StorageDrawer,
        ObjectClass::Computer,
        ObjectClass::Workbench,
        ObjectClass::CncMachine,
        ObjectClass::Table,
        ObjectClass::Other,
    ];

    /// The station class this object marks, if any. Chairs appear at both the
    /// workstation and the assembly station; this returns the workstation.
    pub fn station(self) -> Option<Station> {
        use ObjectClass::*;
        match self {
            Crate | Box | Pallet => Some(Station::Storage),
            Desk | Chair | StorageDrawer | Computer => Some(Station::Workstation),
            Workbench => Some(Station::Assembly),
            CncMachine | Table => Some(Station::Manufacturing),
            Other => None,
        }
    }
}

/// A person as one robot's detector sees it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct HumanDetection {
    pub bbox: BBox,
    /// 17 COCO keypoints as x0, y0, x1, y1, … in image pixels ([`KEYPOINT_VALUES`]).
    pub keypoints: Vec<f32>,
    /// Appearance feature ([`FEATURE_DIM`]).
    pub feature: Vec<f32>,
    /// The detector's id of this person across its frames, if it tracks people (ids
    /// are the detector's own: they mean nothing to another robot).
    pub track: Option<u32>,
}

/// Most people one frame may carry.
pub const MAX_HUMANS: usize = 8;

/// One detected object.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct ObjectDetection {
    pub class: ObjectClass,
    pub bbox: BBox,
    /// Detector score in [0, 1].
    pub score: f32,
    /// Appearance feature ([`FEATURE_DIM`]).
    pub feature: Vec<f32>,
}

/// Where a robot's camera stands on the floor and where it points, in the floor frame
/// (metres; radians counter-clockwise from the floor's x axis). A real robot's
/// localiser provides it; the simulated world fills it in.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct FloorPose {
    pub position: [f32; 2],
    pub heading: f32,
}

/// One camera frame's worth of detections of one robot. Its tick is the period of the
/// fleet's clock it was captured in ([`DetectionFrame::tick`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct DetectionFrame {
    pub robot: RobotId,
    /// When the camera took the frame: microseconds since the Unix epoch on the robot's
    /// synchronised clock (chrony or PTP), stamped by the frame's source.
    pub capture_us: u64,
    /// The camera's pose when the frame was taken; `None` when the robot is not
    /// localised (it then shares no floor-frame estimates).
    pub pose: Option<FloorPose>,
    /// Image size in pixels (width, height): bbox distances are normalised by its diagonal.
    pub image_size: [f32; 2],
    /// Every person in view (at most [`MAX_HUMANS`]), in any order. The robot follows
    /// one of them, the worker its team tracks (`spwi-core`'s engine puts that one
    /// first before anything reads the frame).
    pub humans: Vec<HumanDetection>,
    pub objects: Vec<ObjectDetection>,
    /// Global appearance of the whole view ([`FEATURE_DIM`]).
    pub scene_feature: Vec<f32>,
}

impl DetectionFrame {
    /// The tick the frame was captured in: `floor(capture_us / TICK_US)`.
    pub fn tick(&self) -> u64 {
        self.capture_us / TICK_US
    }

    /// The capture time of tick `t`'s start, for sources that capture on the tick.
    pub fn capture_at_tick(t: u64) -> u64 {
        t.saturating_mul(TICK_US)
    }

    /// The person the robot follows: the first (see [`DetectionFrame::humans`]).
    pub fn worker(&self) -> Option<&HumanDetection> {
        self.humans.first()
    }

    /// Visibility count N_detected: the worker (if seen) plus every object detected.
    pub fn visibility(&self) -> u32 {
        self.objects.len() as u32 + u32::from(!self.humans.is_empty())
    }
}

impl Validate for DetectionFrame {
    fn validate(&self) -> Result<(), Invalid> {
        finite("image_size", &self.image_size)?;
        if self.image_size.iter().any(|&s| s < 1.0) {
            return Err(invalid("image_size", "width and height must be at least 1 pixel"));
        }
        dim("scene_feature", &self.scene_feature, FEATURE_DIM)?;
        if let Some(p) = &self.pose {
            finite("pose", &[p.position[0], p.position[1], p.heading])?;
        }
        if self.humans.len() > MAX_HUMANS {
            return Err(invalid("humans", format!("{} people, at most {MAX_HUMANS}", self.humans.len())));
        }
        for (i, h) in self.humans.iter().enumerate() {
            h.bbox.validate("humans.bbox")?;
            dim("humans.keypoints", &h.keypoints, KEYPOINT_VALUES)?;
            dim("humans.feature", &h.feature, FEATURE_DIM)?;
            if h.track.is_some() && self.humans[..i].iter().any(|o| o.track == h.track) {
                return Err(invalid("humans.track", format!("track {} twice", h.track.unwrap_or_default())));
            }
        }
        if self.objects.len() > MAX_OBJECTS {
            return Err(invalid("objects", format!("{} objects, at most {MAX_OBJECTS}", self.objects.len())));
        }
        for o in &self.objects {
            o.bbox.validate("objects.bbox")?;
            dim("objects.feature", &o.feature, FEATURE_DIM)?;
            if !(0.0..=1.0).contains(&o.score) {
                return Err(invalid("objects.score", format!("{} not in [0, 1]", o.score)));
            }
        }
        Ok(())
    }
}

/// A robot's estimate of the worker on the floor: a constant-velocity track.
/// The covariance is per axis (the same for x and y): position variance (m²),
/// position–velocity covariance (m²/s), velocity variance (m²/s²).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct WorkerEstimate {
    pub position: [f32; 2],
    pub velocity: [f32; 2],
    pub covariance: [f32; 3],
}

/// The names an estimate's fields go by in an error: where in a message it sits.
struct EstimateFields {
    position: &'static str,
    velocity: &'static str,
    covariance: &'static str,
}

const WORKER_FIELDS: EstimateFields =
    EstimateFields { position: "worker.position", velocity: "worker.velocity", covariance: "worker.covariance" };
const PEOPLE_FIELDS: EstimateFields = EstimateFields {
    position: "people.estimate.position",
    velocity: "people.estimate.velocity",
    covariance: "people.estimate.covariance",
};

impl WorkerEstimate {
    fn validate(&self) -> Result<(), Invalid> {
        self.validate_as(&WORKER_FIELDS)
    }

    fn validate_as(&self, names: &EstimateFields) -> Result<(), Invalid> {
        finite(names.position, &self.position)?;
        finite(names.velocity, &self.velocity)?;
        finite(names.covariance, &self.covariance)?;
        let [pp, pv, vv] = self.covariance;
        if pp <= 0.0 || vv <= 0.0 || pv * pv > pp * vv * (1.0 + 1e-4) {
            return Err(invalid(
                names.covariance,
                format!("{:?} is not a covariance (positive definite)", self.covariance),
            ));
        }
        Ok(())
    }
}

/// One person a robot tracks on the floor, under the team's id for that person: what
/// lets every robot of the team name each worker alike.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct PersonShare {
    pub worker: WorkerId,
    pub estimate: WorkerEstimate,
}

/// An object that marks a station, seen this tick, back-projected onto the floor.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Landmark {
    pub station: Station,
    pub position: [f32; 2],
    /// Standard deviation of the position (m): grows with the distance it was seen at.
    pub sigma: f32,
}

/// Where a robot's team map puts each station (`None`: not mapped), sent to a robot
/// that joins, so that it need not wait for every station to come into view again:
/// with cameras that turn to the worker, a station may not be seen for minutes.
/// Each position is a station's work spot as the worker was seen using it, or the
/// centre of the objects that mark it, in the floor frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct MapMsg {
    pub robot: RobotId,
    pub instance: u64,
    pub stations: [Option<[f32; 2]>; NUM_CLASSES],
}

/// Largest floor coordinate a map may carry (m): a floor is not 10 km across.
pub const MAX_FLOOR_M: f32 = 10_000.0;

impl Validate for MapMsg {
    fn validate(&self) -> Result<(), Invalid> {
        for p in self.stations.iter().flatten() {
            finite("stations", p)?;
            if p.iter().any(|x| x.abs() > MAX_FLOOR_M) {
                return Err(invalid("stations", format!("{p:?} lies more than {MAX_FLOOR_M} m out")));
            }
        }
        Ok(())
    }
}

/// A robot's share of one tick, one message: its GCN embedding, so peers can run the
/// collective GRU (`None` when the robot does not see the worker this tick), and its
/// vote (`None`: it does not vote for the tick, so peers do not wait for it). The vote
/// is made from what the robot holds when its frame comes in: its own view of the
/// tick and its peers' latest, so one exchange a tick carries both (engine.rs). The
/// vote also goes out alone on the vote key, for observers.
/// `worker`, `facing` and `landmarks` are what the robot knows in the floor frame
/// (empty when it is not localised): the team fuses them into one worker track, one
/// facing of the worker's body and one map of the stations. `verdict` is the robot's
/// latest decision not shared before, in brief: peers measure how often the team
/// agrees from it, so that no robot need hear every other robot's decision messages.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct EmbeddingMsg {
    pub robot: RobotId,
    /// Random per process start: two daemons that share a robot id differ here.
    pub instance: u64,
    pub tick: u64,
    pub embedding: Option<Vec<f32>>,
    pub visibility: u32,
    /// Same robot, instance and tick as the message.
    pub vote: Option<VoteMsg>,
    pub worker: Option<WorkerEstimate>,
    /// Where the robot's frame shows the worker's body facing this tick (radians,
    /// counter-clockwise from the floor's x axis); `None` when its frame does not show
    /// the shoulders or hips, or the robot is not localised.
    pub facing: Option<f32>,
    pub landmarks: Vec<Landmark>,
    pub verdict: Option<Verdict>,
    /// Everyone the robot tracks on the floor and has seen in the last half second
    /// (at most [`MAX_HUMANS`], each team id once), under the team's ids: empty when it
    /// is not localised.
    pub people: Vec<PersonShare>,
}

impl Validate for EmbeddingMsg {
    fn validate(&self) -> Result<(), Invalid> {
        if let Some(e) = &self.embedding {
            dim("embedding", e, EMBEDDING_DIM)?;
        }
        if let Some(w) = &self.worker {
            w.validate()?;
        }
        if let Some(f) = self.facing {
            finite("facing", &[f])?;
        }
        if self.landmarks.len() > MAX_LANDMARKS {
            return Err(invalid("landmarks", format!("{} landmarks, at most {MAX_LANDMARKS}", self.landmarks.len())));
        }
        for l in &self.landmarks {
            finite("landmarks.position", &l.position)?;
            if !(l.sigma.is_finite() && l.sigma > 0.0) {
                return Err(invalid("landmarks.sigma", format!("{} must be a positive number", l.sigma)));
            }
        }
        if let Some(v) = &self.verdict {
            sorted_voters("verdict.voters", &v.voters)?;
        }
        if self.people.len() > MAX_HUMANS {
            return Err(invalid("people", format!("{} people, at most {MAX_HUMANS}", self.people.len())));
        }
        for (i, p) in self.people.iter().enumerate() {
            p.estimate.validate_as(&PEOPLE_FIELDS)?;
            if self.people[..i].iter().any(|q| q.worker == p.worker) {
                return Err(invalid("people.worker", format!("worker {} named twice", p.worker)));
            }
        }
        if let Some(v) = &self.vote {
            v.validate()?;
            if (&v.robot, v.instance, v.tick) != (&self.robot, self.instance, self.tick) {
                return Err(invalid(
                    "vote",
                    format!("{}'s vote for tick {} in {}'s message of tick {}", v.robot, v.tick, self.robot, self.tick),
                ));
            }
        }
        Ok(())
    }
}

/// What a robot decided for one tick, enough to compare two robots' decisions: the
/// class at t (`None`: no member saw the worker), whose ballots were counted, and
/// their digest ([`DecisionMsg::digest`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Verdict {
    pub tick: u64,
    pub class: Option<Station>,
    /// Sorted, each member once.
    pub voters: Vec<RobotId>,
    pub digest: u64,
}

impl Verdict {
    pub fn of(d: &DecisionMsg) -> Verdict {
        Verdict { tick: d.tick, class: d.steps.first().map(|s| s.class), voters: d.voters.clone(), digest: d.digest }
    }
}

fn sorted_voters(field: &'static str, voters: &[RobotId]) -> Result<(), Invalid> {
    if voters.len() > MAX_MEMBERS {
        return Err(invalid(field, format!("{} voters, at most {MAX_MEMBERS}", voters.len())));
    }
    if let Some(w) = voters.windows(2).find(|w| w[0] >= w[1]) {
        return Err(invalid(field, format!("{} before {}: must be sorted, each once", w[0], w[1])));
    }
    Ok(())
}

/// The predicted class and its calibrated confidence for one step.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct StepVote {
    pub class: Station,
    pub confidence: f32,
}

/// A robot's vote for one tick: `steps[0]` is the prediction for t, `steps[h]` for t+h.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct VoteMsg {
    pub robot: RobotId,
    pub instance: u64,
    pub tick: u64,
    pub steps: Vec<StepVote>,
    pub visibility: u32,
    /// How well the robot says it sees the worker this tick (in [0, 1]): how large and
    /// how complete the worker is in its view. It can only lower the vote's weight:
    /// what a vote weighs is the trust its receivers have observed of its voter.
    pub quality: f32,
    /// Where the voter's own camera puts the worker this tick (`None`: it does not see
    /// the worker, or is not localised). Every robot that counts the ballot judges it
    /// against the other ballots' estimates, so that all of them learn alike whose
    /// camera places the worker where nobody else does.
    pub worker: Option<WorkerEstimate>,
    /// In a secured fleet, the voter's Ed25519 signature over [`VoteMsg::signed_bytes`]
    /// (64 bytes), so that a peer relaying the vote cannot change it; empty in an open
    /// fleet. Not part of what is decided, nor of the decision digest.
    pub signature: Vec<u8>,
}

impl VoteMsg {
    /// What the signature covers: the fleet's id, then the vote encoded with an empty
    /// signature (robot, instance, tick and content). The fleet binds a vote to its
    /// fleet, the instance to the voter's run, the tick to a period of the fleet's
    /// clock: a vote recorded in one fleet or run counts in no other.
    pub fn signed_bytes(&self, fleet: &crate::FleetId) -> Vec<u8> {
        let mut bytes = fleet.as_str().as_bytes().to_vec();
        bytes.push(0xff); // ids hold no 0xff byte: the fleet ends here
        bytes.extend(crate::encode(&VoteMsg { signature: Vec::new(), ..self.clone() }));
        bytes
    }
}

impl Validate for VoteMsg {
    fn validate(&self) -> Result<(), Invalid> {
        if self.steps.is_empty() || self.steps.len() > MAX_STEPS {
            return Err(invalid("steps", format!("{} steps, expected 1..={MAX_STEPS}", self.steps.len())));
        }
        for s in &self.steps {
            if !(s.confidence.is_finite() && (0.0..=1.0).contains(&s.confidence)) {
                return Err(invalid("steps.confidence", format!("{} not in [0, 1]", s.confidence)));
            }
        }
        if !(self.quality.is_finite() && (0.0..=1.0).contains(&self.quality)) {
            return Err(invalid("quality", format!("{} not in [0, 1]", self.quality)));
        }
        if let Some(w) = &self.worker {
            w.validate()?;
        }
        if !matches!(self.signature.len(), 0 | 64) {
            return Err(invalid("signature", format!("{} bytes, expected 0 or 64", self.signature.len())));
        }
        Ok(())
    }
}

/// How a decision came about.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
pub enum DecidedBy {
    /// Every live member had voted (or said it does not see the worker).
    AllVoted,
    /// The tick's deadline passed first.
    Deadline,
}

/// The team's decision for one step: the winning class and its weighted score.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct TeamStep {
    pub class: Station,
    pub score: f32,
}

/// A robot's view of the team decision for one tick. `steps` is empty when no member
/// saw the worker; otherwise `steps[0]` is for t and `steps[h]` for t+h.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct DecisionMsg {
    pub robot: RobotId,
    pub instance: u64,
    pub tick: u64,
    pub steps: Vec<TeamStep>,
    /// The members whose votes were counted, sorted.
    pub voters: Vec<RobotId>,
    /// How many members were live when deciding.
    pub live_members: u32,
    pub decided_by: DecidedBy,
    /// A digest of the ballots counted (origin, visibility and every step, in robot
    /// order): two robots that decided on the same ballots name the same digest.
    pub digest: u64,
}

impl Validate for DecisionMsg {
    fn validate(&self) -> Result<(), Invalid> {
        if self.steps.len() > MAX_STEPS {
            return Err(invalid("steps", format!("{} steps, at most {MAX_STEPS}", self.steps.len())));
        }
        for s in &self.steps {
            finite("steps.score", &[s.score])?;
        }
        sorted_voters("voters", &self.voters)
    }
}

/// The ballots a robot holds for one tick, its own and those it heard from peers,
/// published partway through the tick so that a peer that lost one of them on its own
/// link still counts it. Each vote keeps its origin; `robot` is the relaying robot.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct BallotsMsg {
    pub robot: RobotId,
    pub instance: u64,
    pub tick: u64,
    pub votes: Vec<VoteMsg>,
}

impl Validate for BallotsMsg {
    fn validate(&self) -> Result<(), Invalid> {
        if self.votes.len() > MAX_MEMBERS {
            return Err(invalid("votes", format!("{} votes, at most {MAX_MEMBERS}", self.votes.len())));
        }
        let mut origins = std::collections::BTreeSet::new();
        for v in &self.votes {
            v.validate()?;
            if v.tick != self.tick {
                return Err(invalid(
                    "votes.tick",
                    format!("a vote for tick {} in the ballots of tick {}", v.tick, self.tick),
                ));
            }
            if !origins.insert(&v.robot) {
                return Err(invalid("votes.robot", format!("two votes from {}", v.robot)));
            }
        }
        Ok(())
    }
}

/// Most ticks one history may carry: ten seconds, about what trust averages over.
pub const MAX_HISTORY_TICKS: usize = 100;

/// Every vote a robot held for one tick it learned from (the votes of its lesson).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Lesson {
    pub tick: u64,
    /// Sorted by voter, each voter once.
    pub votes: Vec<VoteMsg>,
}

/// The lessons a robot learned lately, sent when a member joins: the newcomer learns
/// from these signed votes whom the team has seen agree, as its peers did, instead of
/// starting out trusting nobody more than anybody. A history never speaks for its
/// sender: the receiver takes from it only the votes of others.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct HistoryMsg {
    pub robot: RobotId,
    pub instance: u64,
    /// Oldest first, each tick once.
    pub lessons: Vec<Lesson>,
}

impl Validate for HistoryMsg {
    fn validate(&self) -> Result<(), Invalid> {
        if self.lessons.len() > MAX_HISTORY_TICKS {
            let n = self.lessons.len();
            return Err(invalid("lessons", format!("{n} lessons, at most {MAX_HISTORY_TICKS}")));
        }
        if let Some(w) = self.lessons.windows(2).find(|w| w[0].tick >= w[1].tick) {
            return Err(invalid(
                "lessons.tick",
                format!("{} before {}: oldest first, each once", w[0].tick, w[1].tick),
            ));
        }
        for l in &self.lessons {
            if l.votes.len() > MAX_MEMBERS {
                return Err(invalid("lessons.votes", format!("{} votes, at most {MAX_MEMBERS}", l.votes.len())));
            }
            if let Some(w) = l.votes.windows(2).find(|w| w[0].robot >= w[1].robot) {
                let (a, b) = (&w[0].robot, &w[1].robot);
                return Err(invalid("lessons.votes.robot", format!("{a} before {b}: sorted, each once")));
            }
            for v in &l.votes {
                v.validate()?;
                if v.tick != l.tick {
                    return Err(invalid(
                        "lessons.votes.tick",
                        format!("a vote for tick {} in the lesson of tick {}", v.tick, l.tick),
                    ));
                }
            }
        }
        Ok(())
    }
}

/// What the worker is doing, as the simulated world knows it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
pub enum WorkerPhase {
    /// Walking to a goal.
    Moving,
    /// Walking, but the goal changed within the last seconds.
    Transition,
    /// Working at a station.
    Stationary,
}

/// A robot's pose on the floor (metres, radians), for views and scoring.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct RobotPose {
    pub robot: RobotId,
    pub position: [f32; 2],
    pub heading: f32,
}

/// Ground truth for one tick (simulation only; agents never read it).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct TruthMsg {
    pub tick: u64,
    /// The station the worker is heading to or working at.
    pub intent: Station,
    pub phase: WorkerPhase,
    pub worker_position: [f32; 2],
    pub worker_heading: f32,
    pub robots: Vec<RobotPose>,
}

impl Validate for TruthMsg {
    fn validate(&self) -> Result<(), Invalid> {
        finite("worker_position", &self.worker_position)?;
        finite("worker_heading", &[self.worker_heading])?;
        if self.robots.len() > MAX_MEMBERS {
            return Err(invalid("robots", format!("{} robots, at most {MAX_MEMBERS}", self.robots.len())));
        }
        for r in &self.robots {
            finite("robots.position", &r.position)?;
            finite("robots.heading", &[r.heading])?;
        }
        Ok(())
    }
}
