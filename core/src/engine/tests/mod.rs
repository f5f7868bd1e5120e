//! The engine's tests, by topic; the helpers here build engines on the fixture models,
//! frames, shares and votes.

mod clock;
mod deciding;
mod history;
mod rounds;
mod stale;
mod tracks_and_maps;
mod trust;

use super::*;
use crate::clock::{OffClock, TickWindow};
use crate::consensus::Rule;
use crate::floor::CameraCalibration;
use crate::model::{Backend, ModelSet};
use crate::temporal::{self, TemporalModel};
use crate::trust::{TrustConfig, UNJUDGED};
use std::sync::Arc;

fn models() -> Arc<ModelSet> {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/fixture");
    ModelSet::load(&dir, Backend::Tract, None).unwrap()
}

fn id(s: &str) -> RobotId {
    RobotId::new(s).unwrap()
}

fn engine(robot: &str, set: &Arc<ModelSet>) -> Engine {
    let cfg = EngineConfig {
        robot: id(robot),
        instance: 1,
        temporal: TemporalModel::Collective,
        decision_deadline: Duration::from_millis(60),
        consensus: Rule::Trust,
        trust: TrustConfig::default(),
        max_open_ticks: 8,
        camera: CameraCalibration::default(),
        relay_after: None,
        relayers: 4,
        ask_rounds: 2,
        catch_up: Duration::ZERO,
        stale_after: 5,
        window: TickWindow::default(),
        floor_plan: None,
    };
    Engine::new(cfg, set.inference(TemporalModel::Collective).unwrap())
}

/// A frame whose features depend on (robot, tick) so robots disagree sometimes.
pub(crate) fn frame(robot: &str, tick: u64, seen: bool) -> DetectionFrame {
    let seed = tick as f32 * 0.37 + robot.len() as f32;
    let feat = |k: f32| (0..FEATURE_DIM).map(|i| (i as f32 * 0.1 + k + seed).sin()).collect::<Vec<_>>();
    DetectionFrame {
        robot: id(robot),
        capture_us: DetectionFrame::capture_at_tick(tick),
        pose: None,
        image_size: [640.0, 480.0],
        humans: seen
            .then(|| HumanDetection {
                bbox: BBox { x: 300.0, y: 200.0, w: 40.0, h: 120.0 },
                // A live detector: the keypoints move a little every frame.
                keypoints: (0..KEYPOINT_VALUES).map(|i| 300.0 + i as f32 + (seed * 7.0).sin()).collect(),
                feature: feat(1.0),
                track: None,
            })
            .into_iter()
            .collect(),
        objects: (0..3)
            .map(|k| ObjectDetection {
                class: ObjectClass::ALL[k],
                bbox: BBox { x: 100.0 * k as f32, y: 300.0, w: 50.0, h: 50.0 },
                score: 0.8,
                feature: feat(k as f32 + 2.0),
            })
            .collect(),
        scene_feature: feat(0.0),
    }
}

fn ms(m: u64) -> Duration {
    Duration::from_millis(m)
}

fn decisions(out: &[Output]) -> Vec<&DecisionMsg> {
    out.iter().filter_map(|o| if let Output::Decision(d) = o { Some(d) } else { None }).collect()
}

/// A vote as a trusted peer with a full view sends it.
fn vote_msg(robot: &str, instance: u64, tick: u64, steps: Vec<StepVote>) -> VoteMsg {
    VoteMsg { robot: id(robot), instance, tick, steps, visibility: 1, quality: 1.0, worker: None, signature: vec![] }
}

/// A peer's share of a tick (instance 2, no landmarks): an embedding of `x`s if it
/// sees the worker, its vote if it votes, its estimate of the worker.
fn share(
    robot: &str,
    tick: u64,
    x: Option<f32>,
    vote: Option<Vec<StepVote>>,
    worker: Option<WorkerEstimate>,
) -> EmbeddingMsg {
    EmbeddingMsg {
        robot: id(robot),
        instance: 2,
        tick,
        embedding: x.map(|x| vec![x; EMBEDDING_DIM]),
        visibility: 3,
        vote: vote.map(|steps| vote_msg(robot, 2, tick, steps)),
        worker,
        facing: None,
        landmarks: Vec::new(),
        verdict: None,
        people: Vec::new(),
    }
}

/// A peer's share of a tick in which it neither sees the worker nor votes.
fn abstaining(robot: &str, tick: u64) -> Input {
    Input::Embedding(share(robot, tick, None, None, None))
}

fn one_step(class: Station) -> Vec<StepVote> {
    vec![StepVote { class, confidence: 1.0 }]
}

/// Our vote, in our share of the tick (and the same alone, for observers).
fn take_vote(out: &[Output]) -> VoteMsg {
    let v = take_embedding(out).vote.expect("a vote");
    let alone = out.iter().find_map(|o| if let Output::Vote(v) = o { Some(v) } else { None });
    assert_eq!(alone, Some(&v), "the vote goes out alone too, for observers");
    v
}

fn take_embedding(out: &[Output]) -> EmbeddingMsg {
    out.iter().find_map(|o| if let Output::Embedding(e) = o { Some(e.clone()) } else { None }).expect("an embedding")
}
