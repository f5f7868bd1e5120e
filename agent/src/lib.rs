//! spwi-agent: the daemon each robot runs to predict, with its peers, where a human
//! worker is heading. The pipeline itself (star graph, GCN, GRU, vote, trust,
//! consensus) is `spwi_core`'s, a state machine with no I/O; this crate runs it on a
//! robot: a Zenoh session to the fleet, the wall clock, the publisher thread, the
//! recorder, certificates and access control, and the HTTP side.
//!
//! Modules:
//! - [`daemon`]: the event loop, its connection to the fleet (session, liveliness,
//!   subscriptions) and its publisher thread;
//! - [`config`], [`zenoh_config`], [`cli`]: settings and the command line;
//! - [`fleet`]: who may join: certificates, roster, mutual TLS and access control;
//! - [`record`]: recordings of a robot's inputs and outputs, and their replay;
//! - [`router`]: `spwi-router`, the meeting point for hosts without multicast;
//! - [`http`], [`status`], [`metrics`]: `/healthz`, `/status`, `/metrics`.

pub mod cli;
pub mod config;
pub mod daemon;
pub mod fleet;
mod http;
pub mod metrics;
pub mod record;
pub mod router;
mod status;
pub mod zenoh_config;
