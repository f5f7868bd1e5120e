//! spwi-core: the pipeline every robot runs, with no I/O of its own. From a robot's
//! detections and its peers' messages to what it publishes: the star graph, the GCN
//! and GRU (ONNX models), the vote, trust and the team's consensus. No network, no
//! async runtime, no HTTP, no certificates: the daemon (`spwi-agent`) wraps it around a
//! Zenoh session, the evaluation (`spwi-sim eval`) around a simulated bus, and a replay
//! around a recording, and all three run the very same [`engine::Engine`].
//!
//! ```text
//!  detections ─► graph ─► model (GCN) ─► embedding ─────────────► peers
//!                            │
//!  floor: worker track + station map, shared with the peers and fused
//!                            ▼
//!  keypoints ‖ relations to the team's stations (default set), or
//!  own ‖ mean(peer embeddings) ‖ keypoints (paper set) ─► temporal (W ticks)
//!                            ▼
//!  model (ego or collective GRU: per-station scorer) ─► vote ──────► peers
//!                            ▼
//!  consensus over the votes of the live members ─► decision ──────► observers
//!       (ballots held are relayed partway through the tick;
//!        trust learns from each decision whom to believe)
//! ```
//!
//! Modules:
//! - [`engine`]: one robot's tick state machine (inputs and `now` in, messages out),
//!   and the one mapping of its inputs and outputs to the wire;
//! - [`clock`]: the fleet's clock: ticks as periods of a synchronised wall clock, and the
//!   window of ticks a robot takes input for;
//! - [`graph`], [`temporal`], [`vote`], [`consensus`]: the pipeline stages;
//! - [`trust`]: what each robot learned of every voter from the ballots it decided on,
//!   and [`hindsight`], from the station the worker then stayed at;
//! - [`sight`]: what a receiver can check of a vote's view;
//! - [`stale`]: feeds that repeat themselves (a frozen camera), set aside;
//! - [`floor`]: back-projection, the shared worker track and station map, relations;
//! - [`model`], [`manifest`]: ONNX models (tract by default, ONNX Runtime with `ort`);
//! - [`settings`]: the `[tick]` settings an engine is built from;
//! - [`metrics`]: what the engine counts and times;
//! - [`hash`]: the hash robots compute alike.

pub mod clock;
pub mod consensus;
pub mod engine;
pub mod floor;
pub mod graph;
pub mod hash;
pub mod hindsight;
pub mod manifest;
pub mod metrics;
pub mod model;
pub mod settings;
pub mod sight;
pub mod stale;
pub mod temporal;
pub mod trust;
pub mod vote;
