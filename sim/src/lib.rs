//! spwi-sim: a deterministic simulated factory that stands in for the paper's Isaac Sim.
//!
//! ```text
//! layout.rs     the floor from a TOML file: stations and their objects, obstacles, robot slots
//! worker.rs     the worker: plans round obstacles, avoids robots, works, changes its mind
//! skeleton.rs   17 COCO keypoints of a walking body
//! camera.rs     pinhole cameras and a flawed detector: boxes, occlusion, misses, noise
//! appearance.rs synthetic 512-d features (class prototypes + view, distance, posture)
//! world.rs      one tick of everything, deterministic from a seed; scenarios 1-3
//! service.rs    `spwi-sim world`: frames for every live agent over Zenoh at 10 Hz
//! cli.rs        the `spwi-sim` command line
//! dataset.rs    `spwi-sim dataset`: training data (.npy), graphs built by the agent's code
//! eval/         `spwi-sim eval`: the paper's tables on held-out episodes, the agent's code
//! npy.rs        a streaming .npy writer
//! render.rs     `spwi-sim render`: a top-down PNG and each camera's detections
//! stats.rs      `spwi-sim stats`: how hard the task is, per scenario
//! bench.rs      `spwi-sim bench`: N agent processes over Zenoh; latency, CPU, memory
//! demo.rs       `spwi-sim demo`: world + N agents in one process, live view, summary
//! demo_web.rs   the demo's live page (HTML shipped in the binary, server-sent events)
//! ```

pub mod appearance;
pub mod bench;
pub mod camera;
pub mod cli;
pub mod dataset;
pub mod demo;
pub mod demo_web;
pub mod eval;
pub mod geometry;
pub mod layout;
pub mod npy;
pub mod render;
pub mod service;
pub mod skeleton;
pub mod stats;
pub mod worker;
pub mod world;
