//! The rules an engine runs by: timing, consensus, trust, relays, the clock window.
//! Built from the `[tick]` settings by the daemon and the evaluation alike, and
//! recorded with a run so that a replay runs by the same.

use crate::clock::TickWindow;
use crate::consensus::{Rule, Weights};
use crate::floor::{CameraCalibration, FloorPlan};
use crate::settings::{ConsensusRule, TickConfig};
use crate::temporal::TemporalModel;
use crate::trust::TrustConfig;
use spwi_proto::RobotId;
use std::time::Duration;

/// Timing and voting rules of a robot (recorded with a run, so a replay uses the same).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EngineConfig {
    pub robot: RobotId,
    /// Random per process: tells our own echoes from another daemon with our id.
    pub instance: u64,
    pub temporal: TemporalModel,
    /// How long after a tick starts to decide with the votes at hand.
    pub decision_deadline: Duration,
    /// How votes become the decision.
    pub consensus: Rule,
    /// How voters' trust is learned (the trust rule weighs votes by it; low-trust
    /// peers leave the fusion of embeddings and worker estimates under either rule).
    #[serde(default)]
    pub trust: TrustConfig,
    /// Most ticks open at once; the oldest is dropped beyond.
    pub max_open_ticks: usize,
    /// The camera, for back-projecting detections onto the floor.
    #[serde(default)]
    pub camera: CameraCalibration,
    /// When to relay the ballots held for a tick, from its start (`None`: never).
    #[serde(default)]
    pub relay_after: Option<Duration>,
    /// How many members relay a tick's ballots ([`Engine::relays`]; recordings made
    /// before this field had every member relay).
    #[serde(default = "every_member")]
    pub relayers: usize,
    /// How many times a robot still waiting for a vote asks for it between the relay
    /// time and the deadline; also the most answers it gives a tick ([`Engine::answer`];
    /// recordings made before this field never asked).
    #[serde(default)]
    pub ask_rounds: u32,
    /// How long a robot that joins a working team at most withholds its decisions while
    /// it learns the team's history (`engine/history.rs`; recordings made before this
    /// field never withheld one).
    #[serde(default)]
    pub catch_up: Duration,
    /// A feed showing the same worker detection this many times in a row is stale
    /// (0: never).
    #[serde(default)]
    pub stale_after: u32,
    /// The ticks around `now` a frame or a peer's message may be for.
    pub window: TickWindow,
    /// Where the factory's plan puts the stations, seeding the station maps (`None`:
    /// mapped from detections alone).
    #[serde(default)]
    pub floor_plan: Option<FloorPlan>,
}

impl EngineConfig {
    /// The rules a daemon runs with: timing and consensus from its `[tick]` config, the
    /// paper rule's weights from there or else from the model set's manifest. The
    /// daemon and the evaluation both build their engines here, so the evaluation
    /// judges what robots run.
    pub fn new(
        robot: RobotId,
        instance: u64,
        tick: &TickConfig,
        camera: &CameraCalibration,
        manifest: &crate::manifest::Manifest,
    ) -> Self {
        EngineConfig {
            robot,
            instance,
            temporal: tick.temporal,
            decision_deadline: Duration::from_millis(tick.decision_deadline_ms),
            consensus: match tick.consensus {
                ConsensusRule::Paper => Rule::Paper(Weights {
                    alpha: tick.alpha.unwrap_or(manifest.consensus.alpha),
                    beta: tick.beta.unwrap_or(manifest.consensus.beta),
                }),
                ConsensusRule::Trust => Rule::Trust,
            },
            trust: TrustConfig {
                window: tick.trust_window_ticks,
                floor: tick.trust_floor,
                fuse_above: tick.fuse_min_trust,
                count_above: tick.count_min_trust,
            },
            max_open_ticks: tick.max_open_ticks,
            camera: camera.clone(),
            relay_after: (tick.relay_ms > 0).then(|| Duration::from_millis(tick.relay_ms)),
            relayers: tick.relayers as usize,
            ask_rounds: tick.ask_rounds,
            catch_up: Duration::from_millis(tick.catch_up_ms),
            stale_after: tick.stale_after_frames,
            window: TickWindow { past: tick.accept_past_ticks, ahead: tick.accept_ahead_ticks },
            floor_plan: None,
        }
    }
}

fn every_member() -> usize {
    usize::MAX
}
