//! spwi-agent: the daemon each robot runs to predict, with its peers, where a human
//! worker is heading (the paper's sections II and III-E: star graph, GCN, GRU, weighted
//! consensus; the wire protocol is `spwi_proto`'s).
//!
//! ```text
//!  detections ─► graph.rs ─► model/ (GCN) ─► embedding ──publish──► peers
//!   (Zenoh)      star graph     │
//!                               ▼
//!   floor/: worker track + station map, shared with the peers and fused
//!                               ▼
//!   keypoints ‖ relations to the team's stations (default set), or
//!   own ‖ mean(peer embeddings) ‖ keypoints (paper set) ─► temporal.rs (W ticks)
//!                               ▼
//!     model/ (ego or collective GRU: per-station scorer) ─► vote.rs ──publish──► peers
//!                               ▼
//!            consensus.rs over the votes of the live members ─► decision ──publish
//!                 (ballots held are relayed partway through the tick;
//!                  trust.rs learns from each decision whom to believe)
//! ```
//!
//! Modules:
//! - [`engine`]: one robot's tick state machine, pure (inputs and `now` in, messages out);
//! - [`clock`]: the fleet's clock: ticks as periods of a synchronised wall clock, and the
//!   window of ticks a robot takes input for;
//! - [`graph`], [`temporal`], [`vote`], [`consensus`]: the pure pipeline stages;
//! - [`stale`]: feeds that repeat themselves (a frozen camera), set aside;
//! - [`trust`]: what each robot learned of every voter from the ballots it decided on,
//!   which weighs their votes;
//! - [`floor`]: back-projection, the shared worker track and station map, relations;
//! - [`model`], [`manifest`]: ONNX models (tract by default, ONNX Runtime with `ort`);
//! - [`daemon`]: the event loop, its connection to the fleet (session, liveliness,
//!   subscriptions) and its publisher thread;
//! - [`config`], [`zenoh_config`], [`cli`]: settings and the command line;
//! - [`fleet`]: who may join: certificates, roster, mutual TLS and access control;
//! - [`router`]: `spwi-router`, the meeting point for hosts without multicast;
//! - [`http`], [`status`], [`metrics`]: `/healthz`, `/status`, `/metrics`.

pub mod cli;
pub mod clock;
pub mod config;
pub mod consensus;
pub mod daemon;
pub mod engine;
pub mod fleet;
pub mod floor;
pub mod graph;
mod http;
pub mod manifest;
pub mod metrics;
pub mod model;
pub mod record;
pub mod router;
mod stale;
mod status;
pub mod temporal;
pub mod trust;
pub mod vote;
pub mod zenoh_config;
