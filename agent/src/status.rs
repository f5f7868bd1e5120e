//! What `/status` reports: a snapshot the tick loop refreshes after each decision and
//! membership change, so HTTP readers never touch the loop's state.

use crate::metrics::Metrics;
use serde::Serialize;
use spwi_proto::{DecisionMsg, RobotId};
use std::sync::{Arc, Mutex};

#[derive(Debug, Clone, Serialize)]
pub struct Status {
    pub robot: String,
    pub fleet: String,
    pub instance: u64,
    pub model_set: String,
    /// True when running the random-weight fixture models.
    pub fixture_models: bool,
    pub backend: String,
    pub temporal: String,
    /// Live members, this robot included.
    pub members: Vec<RobotId>,
    pub last_decision: Option<DecisionMsg>,
    /// Instance ids of other live daemons that use this robot's id.
    pub duplicate_robot_id: Vec<u64>,
    pub metrics: Metrics,
}

/// Shared between the tick loop (writer) and the HTTP server (readers).
pub type SharedStatus = Arc<Mutex<Status>>;
