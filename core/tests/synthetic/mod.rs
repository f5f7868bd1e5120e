//! A made-up detection frame, shared by the golden tests and the stage benchmark
//! (`core/benches/stages.rs` includes this file by path): the worker in the middle of
//! a 640 × 480 image and `objects` objects in a row below it, each class in turn and
//! each with an appearance feature of its own, seen by a robot at a fixed floor pose,
//! and the worker's track on that floor.

use spwi_proto::*;

pub fn frame(tick: u64, objects: usize) -> DetectionFrame {
    let feature = |k: f32| (0..FEATURE_DIM).map(|i| (i as f32 * 0.013 + k).sin()).collect::<Vec<_>>();
    DetectionFrame {
        robot: RobotId::new("synthetic").unwrap(),
        capture_us: DetectionFrame::capture_at_tick(tick),
        pose: Some(FloorPose { position: [2.0, 3.0], heading: 0.4 }),
        image_size: [640.0, 480.0],
        humans: vec![HumanDetection {
            bbox: BBox { x: 300.0, y: 100.0, w: 50.0, h: 200.0 },
            keypoints: (0..KEYPOINT_VALUES).map(|i| 300.0 + i as f32).collect(),
            feature: feature(1.0),
            track: None,
        }],
        objects: (0..objects)
            .map(|k| ObjectDetection {
                class: ObjectClass::ALL[k % ObjectClass::ALL.len()],
                bbox: BBox { x: 40.0 * k as f32, y: 300.0, w: 40.0, h: 40.0 },
                score: 0.9,
                feature: feature(2.0 + k as f32),
            })
            .collect(),
        scene_feature: feature(0.0),
    }
}

/// Where the worker of [`frame`] stands and walks, as the robot's track has it: what a
/// floor-relations graph places the frame's objects against.
pub static WORKER: WorkerEstimate =
    WorkerEstimate { position: [5.0, 4.5], velocity: [0.8, 0.3], covariance: [0.04, 0.0, 0.1] };

/// [`frame`] on the floor, through `camera`.
pub fn on_floor(camera: &spwi_core::floor::CameraCalibration) -> spwi_core::graph::OnFloor<'_> {
    spwi_core::graph::OnFloor { camera, worker: &WORKER }
}
