//! What `/status` reports: a snapshot the tick loop refreshes after each decision and
//! membership change, so HTTP readers never touch the loop's state.

use crate::engine::Engine;
use crate::metrics::{Metrics, TransportCounters};
use serde::Serialize;
use spwi_proto::{DecisionMsg, RobotId, Station};
use std::collections::{BTreeMap, VecDeque};
use std::sync::{Arc, Mutex};

/// Decisions kept in `/status` (10 s at 10 Hz): enough to compare robots' decisions
/// tick by tick from outside, e.g. in the container end-to-end test.
pub const RECENT_DECISIONS: usize = 100;

/// One decided tick: the team's class at t, none when no member saw the worker.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct RecentDecision {
    pub tick: u64,
    pub class: Option<Station>,
}

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
    /// The consensus rule: "paper" or "trust".
    pub consensus: String,
    /// Who may join: the identity this daemon presents in a secured fleet (mutual TLS,
    /// access control from the roster); `None` in an open fleet.
    pub identity: Option<String>,
    /// Live members, this robot included.
    pub members: Vec<RobotId>,
    pub last_decision: Option<DecisionMsg>,
    /// The latest decisions, oldest first.
    pub recent_decisions: VecDeque<RecentDecision>,
    /// Instance ids of other live daemons that use this robot's id.
    pub duplicate_robot_id: Vec<u64>,
    /// Our camera repeats the same worker detection: set aside, not voting.
    pub feed_stale: bool,
    /// Peers whose feeds repeat themselves: left out of the tick until they change.
    pub stale_peers: Vec<RobotId>,
    /// The trust this robot has learned of each robot judged so far, itself included
    /// (`crate::trust`): how often its votes and its worker estimates agreed with the
    /// others' lately.
    pub trust: BTreeMap<RobotId, f32>,
    /// The engine's counters and stage timings.
    pub metrics: Metrics,
    /// The daemon's: messages refused before the engine, outgoing ones dropped.
    pub transport: TransportCounters,
}

/// Shared between the tick loop (writer) and the HTTP server (readers).
pub type SharedStatus = Arc<Mutex<Status>>;

impl Status {
    /// Takes in the engine's state after an event that decided `decided` (or changed
    /// the members): who is live, the last decision, duplicates of our id, the feeds
    /// set aside, trust and the counters, the daemon's too.
    pub fn refresh(&mut self, engine: &Engine, transport: &TransportCounters, decided: Vec<RecentDecision>) {
        self.members = engine.members();
        self.last_decision = engine.last_decision().cloned();
        self.remember(decided);
        self.duplicate_robot_id = engine.duplicates().iter().copied().collect();
        self.feed_stale = engine.feed_is_stale();
        self.stale_peers = engine.stale_peers();
        self.trust = engine.trust();
        self.metrics = engine.metrics().clone();
        self.transport = transport.clone();
    }

    /// Appends new decisions, forgetting the oldest beyond [`RECENT_DECISIONS`].
    pub fn remember(&mut self, decided: impl IntoIterator<Item = RecentDecision>) {
        self.recent_decisions.extend(decided);
        let excess = self.recent_decisions.len().saturating_sub(RECENT_DECISIONS);
        self.recent_decisions.drain(..excess);
    }

    /// `/metrics`: the counters and histograms, then the state of the feeds and trust.
    pub fn prometheus(&self) -> String {
        use crate::metrics::{exposition, registry, ByLabel};
        use prometheus_client::metrics::gauge::ConstGauge;
        use prometheus_client::metrics::MetricType;
        let mut r = registry(&self.robot);
        self.metrics.register(&mut r, self.members.len());
        self.transport.register(&mut r);
        r.register(
            "spwi_feed_stale",
            "1 while our camera repeats the same worker detection (set aside)",
            ConstGauge::new(i64::from(self.feed_stale)),
        );
        let stale = self.stale_peers.iter().map(|p| (p.to_string(), ConstGauge::new(1i64)));
        r.register(
            "spwi_peer_feed_stale",
            "1 for each peer whose feed repeats itself (left out)",
            ByLabel::new("peer", MetricType::Gauge, stale),
        );
        let trust = self.trust.iter().map(|(p, &t)| (p.to_string(), ConstGauge::new(f64::from(t))));
        r.register(
            "spwi_trust",
            "trust this robot learned of each robot: how often its votes and worker estimates agreed with the others'",
            ByLabel::new("peer", MetricType::Gauge, trust),
        );
        exposition(&r)
    }
}
