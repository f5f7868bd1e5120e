//! spwi-sim: the tools around the simulated factory (the world itself is `spwi-world`).
//!
//! ```text
//! service.rs    `spwi-sim world`: frames for every live agent over Zenoh at 10 Hz
//! calibration.rs the simulated camera as an agent is configured with it
//! cli.rs        the `spwi-sim` command line: a dispatch table; each tool has its Args and main
//! dataset.rs    `spwi-sim dataset`: training data (.npy), graphs built by the agent's code
//! eval/         `spwi-sim eval`: the paper's tables on held-out episodes, the agent's code
//! npy.rs        a streaming .npy writer
//! progress.rs   progress of long jobs: a bar on a terminal, plain lines in logs
//! render.rs     `spwi-sim render`: a top-down PNG and each camera's detections
//! stats.rs      `spwi-sim stats`: how hard the task is, per scenario
//! faulty_camera.rs cameras that lie: frozen on one frame, or looping an old clip
//! floor_plan.rs a layout's floor plan, exact or displaced
//! bench.rs      `spwi-sim bench`: N agent processes over Zenoh; latency, CPU, memory
//! soak.rs       `spwi-sim bench --soak`: the same fleet for long, robots leaving and freezing
//! loopback/     a fleet on one machine (hub, agents in-process or as processes, their
//!               decisions): shared by the demo, the bench and the end-to-end tests
//! demo.rs       `spwi-sim demo`: world + N agents in one process, live view, summary
//! demo_web.rs   the demo's live page (HTML shipped in the binary, server-sent events)
//! world_args.rs the world every tool runs in (scenario, floors, cameras)
//! measures.rs   agreement and latency, counted the same way by every tool
//! durations.rs  "20s", "2m", "500ms" on the command line
//! episodes.rs   the world seed of each episode of a run
//! team_floor.rs every robot's floor view when each hears every other; warm maps
//! training_mix.rs the cameras and warm-ups of a training export's episodes
//! layout.rs     `spwi-sim layout`: a generated or mirrored floor to a TOML file
//! ```

pub mod bench;
pub mod calibration;
pub mod cli;
pub mod dataset;
pub mod demo;
pub mod demo_web;
pub mod durations;
pub mod episodes;
pub mod eval;
pub mod faulty_camera;
pub mod floor_plan;
pub mod layout;
pub mod loopback;
pub mod measures;
pub mod npy;
pub mod progress;
pub mod render;
pub mod service;
pub mod soak;
pub mod stats;
pub mod team_floor;
pub mod training_mix;
pub mod world_args;
