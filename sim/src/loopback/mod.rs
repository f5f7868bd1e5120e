//! A fleet on one machine: the pieces `spwi-sim demo`, `spwi-sim bench` (and its soak)
//! and the end-to-end tests (`tests/`) share, written once.
//!
//! ```text
//! hub.rs           the observer's own Zenoh session, which every agent connects to
//! agent_process.rs an `spwi-agent` process with the fleet's arguments: signals, exit
//! in_process.rs    the daemon's code in this process, with a Zenoh session of its own
//! decisions.rs     every decision the agents publish, by tick and robot: agreement, gaps
//! fleet.rs         N agent processes around a hub, started, stopped and frozen by slot
//! routers.rs       `spwi-router` processes, for a fleet of routers' clients
//! ```
//!
//! Multicast scouting is off everywhere: agents connect to the hub and gossip
//! completes the mesh (or they are clients of the fleet's own routers), so concurrent
//! fleets on one machine never meet.

mod agent_process;
mod decisions;
mod fleet;
mod hub;
mod in_process;
mod routers;

pub use agent_process::{AgentProcess, Launch};
pub use decisions::{Decided, Decisions};
pub use fleet::{layout_with_slots, next_tick_instant, usage, FleetOptions, LoopbackFleet, Usage};
pub use hub::{secured_peer, Hub};
pub use in_process::InProcessAgent;
pub use routers::Routers;
