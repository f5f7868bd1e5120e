//! spwi-world: a deterministic simulated factory that stands in for the paper's Isaac Sim.
//!
//! It emits what a real floor gives a fleet — each robot's detection frame and, for
//! scoring only, the truth — and depends on nothing of the agent, its models, Zenoh or
//! tokio, so the stand-in for the world can never reach the code it is used to judge.
//!
//! ```text
//! geometry.rs   points, boxes, segment tests
//! layout.rs     the floor from a TOML file: stations and their objects, obstacles, robot slots
//! generate.rs   random floors from a seed, and named families of them (train, heldout)
//! worker.rs     the worker: plans round obstacles, avoids robots, slows to work, changes its mind
//! skeleton.rs   17 COCO keypoints of a walking body, head turning towards the goal
//! camera.rs     pinhole cameras and a flawed detector: boxes, occlusion, misses, noise
//! pan.rs        where `track` pan units point: the walking worker, or round the floor
//! appearance.rs synthetic 512-d features (class prototypes + view, distance, posture)
//! world.rs      one tick of everything, deterministic from a seed; scenarios 1-3
//! ```
//!
//! Randomness comes in independent streams (the worker, each robot slot's detector,
//! each fault drawn by a tool), so adding a robot or a fault never changes the walk.

pub mod appearance;
pub mod camera;
pub mod generate;
pub mod geometry;
pub mod layout;
pub mod pan;
pub mod skeleton;
pub mod worker;
pub mod world;
