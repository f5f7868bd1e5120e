//! The per-robot decision engine: every input of a tick in, every message to publish
//! out. No I/O and no clock of its own (`now` comes with each input), so the daemon,
//! the replay of a recording and the tests drive the very same code, and the same
//! inputs give the same outputs bit for bit.
//!
//! One tick, as this robot lives it:
//!
//! ```text
//! frame ─► graph ─► GCN ─► window row ─► GRU ─► Embedding out, our vote inside   step.rs
//!                                                (and Vote out alone, for observers)
//!            peers' embedding messages arrive, each with its vote or none
//! relay time passed ─► Ballots out (every vote held for the tick)                rounds.rs
//!            peers' relayed ballots fill in votes lost on our own links
//! still missing a vote ─► Ballots out again, a few times before the deadline
//! a vote from every active member that said it votes, or the deadline passed
//!       ─► consensus ─► Decision out (naming a digest of the ballots counted)    decide.rs
//!       ─► trust, two ticks on: each voter judged against the others
//! ```
//!
//! The rooms: [`config`] (the rules an engine runs by), [`io`] (inputs, outputs and
//! their wire), `step` (our frame and vote, a peer's share), `admission` (which ticks
//! and messages are let in, on the fleet's clock), `rounds` (relay, ask, answer),
//! `decide` (the decision and what it teaches) and `history` (what a newcomer learns
//! of it from its peers). This file holds the state and
//! [`Engine::handle`], which sends each input to its room.

mod admission;
pub mod config;
mod decide;
mod history;
pub mod io;
mod rounds;
mod step;
#[cfg(test)]
pub(crate) mod tests;

pub use config::EngineConfig;
pub use io::{Input, Output};
pub use step::PEER_VIEW_TICKS;

use step::PeerView;

use crate::clock::PeerClock;
use crate::floor::{FloorView, StationMap};
use crate::graph::GraphBuilder;
use crate::hindsight::Hindsight;
use crate::metrics::Metrics;
use crate::model::Inference;
use crate::stale::Repeats;
use crate::temporal::{RowLayout, Window};
use crate::trust::TrustBook;
use spwi_proto::*;
use std::collections::{BTreeMap, BTreeSet};
use std::time::Duration;

/// What we know of one open (or recently decided) tick.
#[derive(Debug)]
struct Tick {
    started: Duration,
    /// When our own frame of the tick came in (and we voted, if we do).
    own_frame: Option<Duration>,
    /// Peers whose share of the tick carried no vote (or whose feed is stale).
    abstaining: BTreeSet<RobotId>,
    votes: BTreeMap<RobotId, VoteMsg>,
    /// Voters whose vote we hold as they sent it themselves (not relayed).
    heard_directly: BTreeSet<RobotId>,
    /// Rounds passed: the relay, then the asks ([`EngineConfig::ask_rounds`]).
    rounds: u32,
    /// Answers we gave to peers' ballots that lacked votes we hold.
    answers: u32,
    /// Peers' verdicts that arrived before our decision, one per peer.
    peer_verdicts: BTreeMap<RobotId, Verdict>,
}

impl Tick {
    fn new(started: Duration) -> Self {
        Tick {
            started,
            own_frame: None,
            abstaining: BTreeSet::new(),
            votes: BTreeMap::new(),
            heard_directly: BTreeSet::new(),
            rounds: 0,
            answers: 0,
            peer_verdicts: BTreeMap::new(),
        }
    }
}

pub struct Engine {
    cfg: EngineConfig,
    inference: Inference,
    graph: GraphBuilder,
    window: Window,
    row_layout: RowLayout,
    floor: FloorView,
    scratch: Vec<f32>,
    /// The peer input of a collective model with a peer set.
    scratch_peers: Vec<f32>,
    temperature: f32,
    /// Live peers per liveliness (never ourselves).
    live: BTreeSet<RobotId>,
    /// Peers heard from at least once.
    active: BTreeSet<RobotId>,
    open: BTreeMap<u64, Tick>,
    decided: BTreeMap<u64, Verdict>,
    /// The latest decided ticks, their ballots kept to answer peers' asks.
    settled: BTreeMap<u64, Tick>,
    /// Our own feed: the worker's box and keypoints, frame after frame.
    own_feed: Repeats,
    /// Each peer's feed: its embeddings.
    peer_feeds: BTreeMap<RobotId, Repeats>,
    /// Each peer's latest share.
    peer_views: BTreeMap<RobotId, PeerView>,
    /// Every robot's record of agreeing with the others, ours included.
    trust: TrustBook,
    metrics: Metrics,
    /// Instance ids of other daemons seen using our robot id.
    duplicates: BTreeSet<u64>,
    /// Decided ticks' votes, to learn from [`decide::LESSON_LAG`] ticks later.
    lessons: BTreeMap<u64, decide::VotesHeld>,
    /// Lessons learned, the latest [`MAX_HISTORY_TICKS`], for members that join.
    learned: BTreeMap<u64, decide::VotesHeld>,
    /// The first tick we decided: a peer's history teaches only ticks before it.
    first_decided: Option<u64>,
    /// Histories asked for and answered.
    history: history::HistoryState,
    /// Learned lessons' votes, waiting to be judged by where the worker stays.
    hindsight: Hindsight,
    /// Each live peer's instance, as it last spoke to us directly: the only one whose
    /// relayed votes count.
    instances: BTreeMap<RobotId, u64>,
    /// How each live peer's ticks sit against our clock.
    peer_clocks: BTreeMap<RobotId, PeerClock>,
    /// When we last logged a frame or message refused for its tick (rate limit).
    warned_off_clock: Option<Duration>,
    last_decision: Option<DecisionMsg>,
    /// The latest tick we decided but withheld while catching up (`history.rs`).
    withheld_through: Option<u64>,
    /// Our latest verdict, until our next embedding message carries it.
    unshared_verdict: Option<Verdict>,
    /// The GCN's spatial-only logits for our latest frame that showed the worker.
    last_spatial: Option<(u64, [f32; NUM_CLASSES])>,
}

impl Engine {
    /// What the engine counted and timed.
    pub fn metrics(&self) -> &Metrics {
        &self.metrics
    }

    /// Instance ids of other live daemons seen using our robot id.
    pub fn duplicates(&self) -> &BTreeSet<u64> {
        &self.duplicates
    }

    /// Our latest decision.
    pub fn last_decision(&self) -> Option<&DecisionMsg> {
        self.last_decision.as_ref()
    }

    /// Whether our latest decided tick was withheld: we joined a working team and are
    /// still learning whom it trusts (`history.rs`).
    pub fn is_catching_up(&self) -> bool {
        self.withheld_through.is_some_and(|w| self.last_decision.as_ref().is_none_or(|d| d.tick < w))
    }

    /// An engine that runs `cfg` with `inference` (the model set and the GRU it runs).
    pub fn new(cfg: EngineConfig, inference: Inference) -> Self {
        let m = &inference.set().manifest;
        let graph = GraphBuilder::new(m.max_nodes, m.edge_weight, m.node_features);
        let window = Window::with_frames(m.window, m.frames(), m.row).with_peer_slots(inference.peer_slots());
        let row_layout = m.row;
        let temperature = inference.set().temperature(cfg.temporal);
        let mut floor = FloorView::new(cfg.camera.clone());
        floor.plan(cfg.floor_plan.as_ref());
        let trust = TrustBook::new(cfg.trust);
        Engine {
            cfg,
            inference,
            graph,
            window,
            row_layout,
            floor,
            scratch: Vec::new(),
            scratch_peers: Vec::new(),
            temperature,
            live: BTreeSet::new(),
            active: BTreeSet::new(),
            open: BTreeMap::new(),
            decided: BTreeMap::new(),
            settled: BTreeMap::new(),
            own_feed: Repeats::default(),
            peer_feeds: BTreeMap::new(),
            peer_views: BTreeMap::new(),
            trust,
            metrics: Metrics::default(),
            duplicates: BTreeSet::new(),
            lessons: BTreeMap::new(),
            learned: BTreeMap::new(),
            first_decided: None,
            history: Default::default(),
            hindsight: Hindsight::default(),
            instances: BTreeMap::new(),
            peer_clocks: BTreeMap::new(),
            warned_off_clock: None,
            last_decision: None,
            withheld_through: None,
            unshared_verdict: None,
            last_spatial: None,
        }
    }

    pub fn config(&self) -> &EngineConfig {
        &self.cfg
    }

    /// How many steps ahead of t our votes forecast (the model set's horizon H).
    pub fn horizon(&self) -> usize {
        self.inference.set().manifest.horizon
    }

    /// Live members, this robot included, sorted.
    pub fn members(&self) -> Vec<RobotId> {
        let mut m: Vec<_> = self.live.iter().cloned().collect();
        m.push(self.cfg.robot.clone());
        m.sort();
        m
    }

    /// What this robot knows on the floor: its track and its own and team maps.
    pub fn floor(&self) -> &FloorView {
        &self.floor
    }

    /// Starts from station maps built before (a fleet that knows the floor): this
    /// robot's own and its team's. The worker's track starts afresh.
    pub fn adopt_maps(&mut self, own: StationMap, team: StationMap) {
        self.floor.own_map = own;
        self.floor.team_map = team;
        self.floor.plan(self.cfg.floor_plan.as_ref());
    }

    /// Our own feed repeats itself: we set it aside until it changes.
    pub fn feed_is_stale(&self) -> bool {
        self.own_feed.is_stale(self.cfg.stale_after)
    }

    /// Peers whose feeds repeat themselves: left out until they change.
    pub fn stale_peers(&self) -> Vec<RobotId> {
        self.peer_feeds.iter().filter(|(_, f)| f.is_stale(self.cfg.stale_after)).map(|(r, _)| r.clone()).collect()
    }

    /// The trust this robot has learned of every robot judged so far, itself included.
    pub fn trust(&self) -> BTreeMap<RobotId, f32> {
        self.trust.all()
    }

    pub(super) fn peer_is_stale(&self, robot: &RobotId) -> bool {
        self.peer_feeds.get(robot).is_some_and(|f| f.is_stale(self.cfg.stale_after))
    }

    /// The spatial-only prediction (GCN logits) for our frame of `tick`, if it showed
    /// the worker: what the evaluation scores as the GNN alone.
    pub fn spatial_logits(&self, tick: u64) -> Option<[f32; NUM_CLASSES]> {
        self.last_spatial.filter(|(t, _)| *t == tick).map(|(_, l)| l)
    }

    /// The earliest time at which [`Input::Poll`] could change something.
    pub fn next_deadline(&self) -> Option<Duration> {
        self.open
            .values()
            .map(|t| {
                let next = t.started + self.cfg.decision_deadline;
                self.round_time(t, t.rounds).map_or(next, |r| next.min(r))
            })
            .min()
    }

    /// How the ticks of each live peer's messages sit against our clock: the offset
    /// of its ticks' starts from when we heard them (ms, averaged; includes the link's
    /// delay), and how many of its messages fell outside our window.
    pub fn peer_clocks(&self) -> &BTreeMap<RobotId, PeerClock> {
        &self.peer_clocks
    }

    /// Handles one input at time `now` (the fleet's clock, since the Unix epoch) and
    /// returns what to publish, in order.
    pub fn handle(&mut self, input: Input, now: Duration) -> Vec<Output> {
        let mut out = Vec::new();
        self.note_coming(now);
        self.forget_the_past(now, &mut out);
        match input {
            Input::Frame(f) => self.on_frame(f, now, &mut out),
            Input::Embedding(e) => self.on_embedding(e, now, &mut out),
            Input::Ballots(b) => self.on_ballots(b, now, &mut out),
            Input::Map(m) => {
                // A peer's map fills in the stations ours lacks (floor/stations.rs);
                // not from a peer whose feed is stale or whom we doubt.
                if m.robot != self.cfg.robot && !self.peer_is_stale(&m.robot) && self.trust.fuses(&m.robot) {
                    self.floor.team_map.borrow(&m.stations);
                }
            }
            Input::History(h) => self.on_history(h, now, &mut out),
            Input::MemberJoined(r) => {
                // A robot that joins has mapped nothing yet: we tell it what we have.
                // (What it learned it asks for itself, as do we while we are new.)
                if r != self.cfg.robot && self.live.insert(r.clone()) {
                    self.metrics.members_joined += 1;
                    let stations = self.floor.team_map.own_stations();
                    if stations.iter().any(Option::is_some) {
                        let (robot, instance) = (self.cfg.robot.clone(), self.cfg.instance);
                        out.push(Output::Map(MapMsg { robot, instance, stations }));
                    }
                    self.ask_for_history(now, &mut out);
                    self.answer_kept_ask(&r, now, &mut out);
                }
            }
            Input::MemberLeft(r) => {
                if self.live.remove(&r) {
                    self.metrics.members_left += 1;
                }
                self.active.remove(&r);
                self.instances.remove(&r);
                self.peer_clocks.remove(&r);
                self.peer_feeds.remove(&r); // a robot that comes back is judged afresh
                self.peer_views.remove(&r);
                self.advance_all(now, &mut out);
            }
            Input::Poll => {
                self.ask_for_history(now, &mut out);
                self.advance_all(now, &mut out);
            }
        }
        out
    }
}
