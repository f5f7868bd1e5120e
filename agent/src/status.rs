//! What `/status` reports: a snapshot the tick loop refreshes after each decision and
//! membership change, and at least twice a second whatever peers send, so HTTP readers
//! never touch the loop's state. `/healthz` reads its [`Health`].

use crate::metrics::TransportCounters;
use serde::Serialize;
use spwi_core::clock::PeerClock;
use spwi_core::engine::Engine;
use spwi_core::metrics::Metrics;
use spwi_proto::{DecisionMsg, RobotId, Station};
use std::collections::{BTreeMap, VecDeque};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Decisions kept in `/status` (10 s at 10 Hz): enough to compare robots' decisions
/// tick by tick from outside, e.g. in the container end-to-end test.
pub const RECENT_DECISIONS: usize = 100;

/// One decided tick: the team's class at t, none when no member saw the worker, as its
/// number and its name.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct RecentDecision {
    pub tick: u64,
    pub class: Option<Station>,
    pub station: Option<&'static str>,
}

impl RecentDecision {
    pub fn of(d: &DecisionMsg) -> RecentDecision {
        let class = d.steps.first().map(|s| s.class);
        RecentDecision { tick: d.tick, class, station: class.map(Station::name) }
    }
}

/// The stations' names by class number, the legend of the numbers in `/status`.
pub const STATION_NAMES: [&str; 4] =
    [Station::Storage.name(), Station::Workstation.name(), Station::Assembly.name(), Station::Manufacturing.name()];

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
    /// The version of the signed roster this daemon holds (`None`: an open fleet).
    pub roster_version: Option<u64>,
    /// When that roster was taken: at start, or adopted while running (RFC 3339, UTC).
    pub roster_adopted_at: Option<String>,
    /// Live members, this robot included.
    pub members: Vec<RobotId>,
    pub last_decision: Option<DecisionMsg>,
    /// The name of each station class the decisions number (`stations[class]`).
    pub stations: [&'static str; 4],
    /// The latest decisions, oldest first.
    pub recent_decisions: VecDeque<RecentDecision>,
    /// Instance ids of other live daemons that use this robot's id.
    pub duplicate_robot_id: Vec<u64>,
    /// We joined a working team and withhold our decisions (we still vote) until we
    /// learned whom it trusts, for at most `tick.catch_up_ms`.
    pub catching_up: bool,
    /// Our camera repeats the same worker detection: set aside, not voting.
    pub feed_stale: bool,
    /// Peers whose feeds repeat themselves: left out of the tick until they change.
    pub stale_peers: Vec<RobotId>,
    /// The trust this robot has learned of each robot judged so far, itself included
    /// (`spwi_core::trust`): how often its votes and its worker estimates agreed with the
    /// others' lately.
    pub trust: BTreeMap<RobotId, f32>,
    /// The engine's counters and stage timings.
    pub metrics: Metrics,
    /// The daemon's: messages refused before the engine, outgoing ones dropped.
    pub transport: TransportCounters,
    /// How each live peer's ticks sit against our clock ([`spwi_core::clock::PeerClock`]):
    /// a peer whose messages keep being refused shows here with its estimated offset.
    pub clocks: BTreeMap<RobotId, PeerClock>,
    /// Whether frames come in and ticks get decided (`/healthz`).
    pub health: Health,
    /// The floor plan this robot was given, if any, and what its cameras say of it.
    pub floor_plan: Option<FloorPlanStatus>,
    /// Everyone this robot tracks on the floor and saw lately, under the team's ids
    /// (`spwi_core::floor::worker_ids`), as it last shared them; empty when it is not
    /// localised.
    pub people: Vec<PersonStatus>,
}

/// One person this robot tracks, under the team's id.
#[derive(Debug, Clone, Serialize)]
pub struct PersonStatus {
    /// The team's id, as a number and as the short name a page or log shows.
    pub worker: u64,
    pub name: String,
    pub position: [f32; 2],
    pub velocity: [f32; 2],
    /// The tick this place is of.
    pub tick: u64,
}

/// The floor plan as the robot's team map stands against it.
#[derive(Debug, Clone, Default, Serialize)]
pub struct FloorPlanStatus {
    /// How many stations the plan places.
    pub stations: usize,
    /// The planned stations the team map puts elsewhere (a work spot or objects seen
    /// well away from the plan's place): the plan or a camera's calibration is wrong.
    pub contradicted: Vec<&'static str>,
}

/// Frames come in but no tick gets decided: the robot is of no use to its team, and an
/// orchestrator should know (`/healthz` answers 503).
#[derive(Debug, Clone, Serialize)]
pub struct Health {
    /// Why the robot is unhealthy, as of the last refresh; `None` when it is not.
    pub problem: Option<String>,
    #[serde(skip)]
    started: Instant,
    #[serde(skip)]
    last_frame: Option<Instant>,
    #[serde(skip)]
    last_decision: Option<Instant>,
    #[serde(skip)]
    after: Duration,
}

impl Health {
    /// Unhealthy once frames come in without a decision for `after`.
    pub fn new(after: Duration) -> Health {
        Health { problem: None, started: Instant::now(), last_frame: None, last_decision: None, after }
    }

    pub fn frame(&mut self, at: Instant) {
        self.last_frame = Some(at);
    }

    pub fn decision(&mut self, at: Instant) {
        self.last_decision = Some(at);
    }

    /// What is wrong at `now`, if anything: frames arrived within `after`, yet no tick
    /// was decided for `after` (or ever, once the daemon has run that long). A robot
    /// without frames is not unhealthy: it may simply have no camera feed yet.
    pub fn check(&self, now: Instant) -> Option<String> {
        let recent = |t: Option<Instant>| t.is_some_and(|t| now.saturating_duration_since(t) <= self.after);
        if !recent(self.last_frame)
            || recent(self.last_decision)
            || now.saturating_duration_since(self.started) < self.after
        {
            return None;
        }
        Some(match self.last_decision {
            Some(t) => format!(
                "frames arrive but no tick was decided for {:.1} s (limit http.unhealthy_after_ms = {})",
                now.saturating_duration_since(t).as_secs_f64(),
                self.after.as_millis()
            ),
            None => format!(
                "frames arrive but no tick was ever decided in {:.1} s (limit http.unhealthy_after_ms = {})",
                now.saturating_duration_since(self.started).as_secs_f64(),
                self.after.as_millis()
            ),
        })
    }
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
        self.catching_up = engine.is_catching_up();
        self.feed_stale = engine.feed_is_stale();
        self.stale_peers = engine.stale_peers();
        self.trust = engine.trust();
        self.metrics = engine.metrics().clone();
        self.transport = transport.clone();
        self.clocks = engine.peer_clocks().clone();
        let (tick, people) = engine.floor().worker_ids().shared();
        self.people = people
            .iter()
            .map(|p| PersonStatus {
                worker: p.worker.0,
                name: p.worker.to_string(),
                position: p.estimate.position,
                velocity: p.estimate.velocity,
                tick,
            })
            .collect();
        if let Some(plan) = self.floor_plan.as_mut() {
            plan.contradicted = engine.floor().team_map.contradicts().into_iter().map(|k| k.name()).collect();
        }
    }

    /// Appends new decisions, forgetting the oldest beyond [`RECENT_DECISIONS`].
    pub fn remember(&mut self, decided: impl IntoIterator<Item = RecentDecision>) {
        self.recent_decisions.extend(decided);
        let excess = self.recent_decisions.len().saturating_sub(RECENT_DECISIONS);
        self.recent_decisions.drain(..excess);
    }

    /// `/metrics`: the counters and histograms, then the state of the feeds and trust.
    pub fn prometheus(&self) -> String {
        use crate::metrics::{exposition, register_engine, registry, ByLabel};
        use prometheus_client::metrics::gauge::ConstGauge;
        use prometheus_client::metrics::MetricType;
        let mut r = registry(&self.robot);
        register_engine(&self.metrics, &mut r, self.members.len());
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
        let offsets =
            self.clocks.iter().filter_map(|(p, c)| Some((p.to_string(), ConstGauge::new(f64::from(c.offset_ms?)))));
        r.register(
            "spwi_peer_clock_offset_ms",
            "start of the tick each live peer names less when we hear it (ms, averaged; the link's delay included)",
            ByLabel::new("peer", MetricType::Gauge, offsets),
        );
        r.register(
            "spwi_healthy",
            "1 unless frames arrive and no tick was decided for http.unhealthy_after_ms",
            ConstGauge::new(i64::from(self.health.problem.is_none())),
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_without_decisions_for_too_long_are_unhealthy_and_no_frames_are_not() {
        let after = Duration::from_secs(3);
        let mut h = Health::new(after);
        let t0 = h.started;
        let at = |s: f64| t0 + Duration::from_secs_f64(s);
        assert_eq!(h.check(at(10.0)), None, "no frames yet: maybe no camera, not a fault of ours");
        h.frame(at(1.0));
        assert_eq!(h.check(at(2.0)), None, "not running long enough to tell");
        h.frame(at(3.9));
        let p = h.check(at(4.0)).expect("frames, and no decision in 4 s");
        assert!(p.contains("no tick was ever decided") && p.contains("http.unhealthy_after_ms = 3000"), "{p}");
        h.decision(at(4.5));
        h.frame(at(4.6));
        assert_eq!(h.check(at(5.0)), None);
        h.frame(at(8.0));
        let p = h.check(at(8.0)).expect("3.5 s since the last decision");
        assert!(p.contains("no tick was decided for 3.5 s"), "{p}");
        assert_eq!(h.check(at(20.0)), None, "frames stopped too: nothing to decide");
    }
}
