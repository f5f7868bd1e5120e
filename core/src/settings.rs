//! The `[tick]` section of a robot's configuration: when it stops waiting for its peers,
//! how votes become the decision, whom it trusts and which ticks it takes input for.
//! The daemon reads it from its config file, the evaluation from `--agent-config`; both
//! build their engines from it ([`crate::engine::EngineConfig::new`]).

use crate::temporal::TemporalModel;
use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};

/// When a robot stops waiting for its peers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TickConfig {
    /// Which GRU the robot runs.
    pub temporal: TemporalModel,
    /// Decide with the votes at hand this long after a tick starts (ms).
    pub decision_deadline_ms: u64,
    /// Relay the ballots held for a tick this long after it starts (ms; 0: never).
    pub relay_ms: u64,
    /// How many members relay each tick's ballots: a different few each tick, every
    /// member when the fleet has no more (see `Engine::relays`).
    pub relayers: u32,
    /// How many times between the relay time and the deadline a robot still waiting
    /// for a member's vote sends the ballots it holds, which asks the tick's relayers
    /// for the missing vote; also the most answers a robot gives a tick (0: neither).
    pub ask_rounds: u32,
    /// How long a robot that joins a working team at most withholds its decisions
    /// while it learns whom the team trusts (ms; 0: it decides at once). It still votes
    /// meanwhile; see `engine/history.rs`.
    pub catch_up_ms: u64,
    /// A camera showing, this many frames in a row, worker detections it showed before
    /// (the last frame's, or any of the last minute's) is frozen or playing back a clip:
    /// set aside until it shows new ones (0: never).
    pub stale_after_frames: u32,
    /// How votes become the decision: "paper" (normalised shares of visibility and
    /// confidence) or "trust" (evidence weighted by each voter's record and view).
    pub consensus: ConsensusRule,
    /// Weight of visibility in the paper's rule; default: the model manifest's.
    pub alpha: Option<f32>,
    /// Weight of confidence in the paper's rule; default: the model manifest's.
    pub beta: Option<f32>,
    /// Decided ticks over which a voter's agreement with the others is averaged.
    pub trust_window_ticks: u32,
    /// Least trust a voter keeps, so that it can earn its trust back.
    pub trust_floor: f32,
    /// Peers trusted less than this leave the fusion of embeddings and worker tracks.
    pub fuse_min_trust: f32,
    /// Voters trusted less than this are not counted while a voter trusted more is,
    /// and never decide a tick alone while a trusted member is live.
    pub count_min_trust: f32,
    /// How many ticks behind our clock's a frame or a peer's message is still taken
    /// (late ones); the window must reach past the decision deadline.
    pub accept_past_ticks: u64,
    /// How many ticks ahead of our clock's a frame or a peer's message is taken (hosts
    /// whose clocks run a little ahead).
    pub accept_ahead_ticks: u64,
    /// Shifts this robot's clock (ms). 0 on a real robot, whose host clock chrony or
    /// PTP keeps in step; tests and benchmarks shift one robot to see what it costs.
    pub clock_offset_ms: i64,
    /// Most ticks in flight at once.
    pub max_open_ticks: usize,
    /// Capacity of the event queue between Zenoh and the tick loop.
    pub event_queue: usize,
}

/// The consensus rule ([`crate::consensus`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ConsensusRule {
    Paper,
    Trust,
}

impl ConsensusRule {
    /// The name the config file uses.
    pub fn name(self) -> &'static str {
        match self {
            ConsensusRule::Paper => "paper",
            ConsensusRule::Trust => "trust",
        }
    }
}

impl Default for TickConfig {
    fn default() -> Self {
        TickConfig {
            temporal: TemporalModel::Collective,
            decision_deadline_ms: 60,
            relay_ms: 40,
            relayers: 4,
            ask_rounds: 2,
            catch_up_ms: 1000,
            stale_after_frames: 5,
            consensus: ConsensusRule::Trust,
            alpha: None,
            beta: None,
            trust_window_ticks: 100,
            trust_floor: 0.1,
            fuse_min_trust: 0.5,
            count_min_trust: 0.5,
            accept_past_ticks: 5,
            accept_ahead_ticks: 2,
            clock_offset_ms: 0,
            max_open_ticks: 64,
            event_queue: 1024,
        }
    }
}

impl TickConfig {
    /// Refuses values out of range, naming the field (as the config file spells it) and
    /// the range.
    pub fn validate(&self) -> Result<()> {
        let t = self;
        if !(1..=1000).contains(&t.decision_deadline_ms) {
            bail!("tick.decision_deadline_ms = {}: must be within 1..=1000 (a tick is 100 ms)", t.decision_deadline_ms);
        }
        if t.relay_ms >= t.decision_deadline_ms {
            bail!(
            "tick.relay_ms = {}: must be below tick.decision_deadline_ms ({}) for relays to arrive in time; 0 relays nothing",
            t.relay_ms,
            t.decision_deadline_ms
        );
        }
        if !(1..=1024).contains(&t.relayers) {
            bail!("tick.relayers = {}: must be within 1..=1024 (tick.relay_ms = 0 relays nothing)", t.relayers);
        }
        if t.ask_rounds > 10 {
            bail!("tick.ask_rounds = {}: must be within 0..=10 (0: robots never ask for a missing vote)", t.ask_rounds);
        }
        if t.catch_up_ms > 10_000 {
            bail!("tick.catch_up_ms = {}: must be within 0..=10000 (0: a new robot decides at once)", t.catch_up_ms);
        }
        for (name, v) in [("tick.alpha", t.alpha), ("tick.beta", t.beta)] {
            if let Some(v) = v {
                if !(v.is_finite() && (0.0..=1000.0).contains(&v)) {
                    bail!("{name} = {v}: must be a finite number within 0..=1000");
                }
            }
        }
        if t.alpha == Some(0.0) && t.beta == Some(0.0) {
            bail!("tick.alpha and tick.beta are both 0: at least one must weigh the votes");
        }
        if !(1..=100_000).contains(&t.trust_window_ticks) {
            bail!("tick.trust_window_ticks = {}: must be within 1..=100000", t.trust_window_ticks);
        }
        for (name, v) in [
            ("tick.trust_floor", t.trust_floor),
            ("tick.fuse_min_trust", t.fuse_min_trust),
            ("tick.count_min_trust", t.count_min_trust),
        ] {
            if !(v.is_finite() && (0.0..=1.0).contains(&v)) {
                bail!("{name} = {v}: must be within 0..=1");
            }
        }
        if !(1..=600).contains(&t.accept_past_ticks) {
            bail!("tick.accept_past_ticks = {}: must be within 1..=600", t.accept_past_ticks);
        }
        if t.accept_ahead_ticks > 600 {
            bail!("tick.accept_ahead_ticks = {}: must be within 0..=600", t.accept_ahead_ticks);
        }
        let reach_ms = t.accept_past_ticks * spwi_proto::TICK_PERIOD.as_millis() as u64;
        if t.decision_deadline_ms >= reach_ms {
            bail!(
            "tick.accept_past_ticks = {}: the window reaches {reach_ms} ms back, not past tick.decision_deadline_ms ({}): a tick would leave the window before its deadline",
            t.accept_past_ticks,
            t.decision_deadline_ms
        );
        }
        if t.clock_offset_ms.unsigned_abs() > 3_600_000 {
            bail!("tick.clock_offset_ms = {}: must be within ±3600000 (one hour)", t.clock_offset_ms);
        }
        if !(1..=10_000).contains(&t.max_open_ticks) {
            bail!("tick.max_open_ticks = {}: must be within 1..=10000", t.max_open_ticks);
        }
        if !(16..=1_000_000).contains(&t.event_queue) {
            bail!("tick.event_queue = {}: must be within 16..=1000000", t.event_queue);
        }
        Ok(())
    }
}
