//! The per-robot decision engine: every input of a tick in, every message to publish
//! out. No I/O and no clock of its own — `now` comes with each input — so the daemon,
//! the replay of a recording and the tests drive the very same code, and the same
//! inputs give the same outputs bit for bit.
//!
//! One tick, as this robot lives it:
//!
//! ```text
//! frame ─► graph ─► GCN ─► window row ─► GRU ─► Embedding out, our vote inside
//!                                                (and Vote out alone, for observers)
//!          (paper rows: own ‖ mean(peers) ‖ keypoints; relation rows: keypoints ‖
//!           the worker's relations to the stations, from the team's fused track and
//!           map; what peers shared is read as the latest each of them sent)
//!            peers' embedding messages arrive, each with its vote or none
//! relay_after passed ─► Ballots out (every vote held for the tick, ours and peers';
//!                      by the few members that relay this tick)
//!            peers' relayed ballots fill in votes lost on our own links
//! still missing a vote ─► Ballots out again, ask_rounds times before the deadline
//!                      (an ask: what we hold shows what we lack); a relayer that holds
//!                      what a peer's ballots lack answers with its own
//! a vote from every active member that said it votes, or decision_deadline passed
//!       ─► consensus ─► Decision out (naming a digest of the ballots counted)
//!       ─► trust: each voter judged against the others
//! ```
//!
//! One message a tick, not two: a robot votes as soon as its own frame is in, reading
//! its peers' latest shares (their worker estimates predicted to this tick, their
//! facings and embeddings, at most [`PEER_VIEW_TICKS`] old) instead of waiting for
//! theirs of this tick. So each robot hears each peer once a tick, not once for the
//! embedding and once more for the vote: half the messages every robot takes in, and
//! one exchange instead of two before a tick can be decided (docs/BENCHMARKS.md).
//!
//! The decision is a deterministic function of the ballots held, so robots that hold
//! the same ballots decide the same; relaying each robot's ballots partway through the
//! tick is what makes them hold the same ballots when links lose messages. A relay sent
//! once is lost as easily as the vote it carries: with 30 % of messages lost, relays
//! alone left 8 simulated robots counting different ballots on 1.3 % of ticks, and 3
//! robots on real lossy QUIC links on 12–17 % (docs/BENCHMARKS.md, "Asking for a missing
//! vote"). So every Ballots message lists every vote its sender holds, which also says
//! what it lacks; a robot still waiting for a vote sends its ballots again, a few times
//! before the deadline, and a relayer of the tick that holds a vote a peer's ballots
//! lack answers with its own (also after it decided the tick). Each round needs a
//! message there and one back, so a few rounds bring the missing votes in on lossy
//! links, and on links that lose nothing no robot waits past the relay time and nothing
//! more is sent. Each robot's
//! next embedding carries its latest decision in brief ([`Verdict`]): comparing class
//! and digest with ours measures how often the team agrees and shows, per robot, when
//! it decided on fewer ballots, without any robot hearing every peer's decisions (the
//! decisions still go out, for observers: n − 1 fewer messages into each robot a tick).
//!
//! Each decision also teaches the robot whom to trust ([`crate::trust`]): every voter
//! is judged against what most of the others' trust names, and the worker estimate
//! inside its ballot against the other ballots' (one that most of them contradict also
//! leaves this tick's team track at once). Nothing a voter says of itself raises its
//! weight: the trust rule weighs each ballot by the trust its receiver learned, and
//! since that is learned from the ballots decided on alone, robots that counted the
//! same ballots weigh them alike. The same trust decides whether we fuse a peer's
//! embedding and worker estimate.
//!
//! A feed that repeats itself is set aside ([`crate::stale`]): our own frames showing
//! the worker identically `stale_after` times in a row count as not seeing the worker
//! (no embedding, no track, no vote) until they change; a peer whose embedding repeats
//! as often is heard as abstaining, its votes and floor estimates left out.
//!
//! Time is the fleet's clock, never a peer's word ([`crate::clock`]): `now` is the
//! robot's synchronised wall clock (time since the Unix epoch; an injected one in the
//! evaluation and a replay), a tick is one of its 100 ms periods, and every frame is
//! stamped with the time it was captured. A frame or a peer's message is taken only for
//! a tick within [`TickWindow`] of `now`; others are refused and counted by reason, so
//! no tick number — huge, repeated, going backwards — can open ticks for the team or
//! block the ones that follow, and a restarted frame source goes on at the current
//! tick. A tick's deadline runs from the first thing this robot heard of it, but never
//! from before the tick starts on its own clock unless that first thing is its own
//! frame: a peer that opens ticks early moves no deadline, and a robot whose clock runs
//! a little behind still decides as soon as its peers. What is remembered of decided
//! ticks reaches back as far as the window.
//!
//! Membership decides whom to wait for: live members (liveliness) that have spoken at
//! least once ("counted from the first vote"), so a peer that joins never stalls a
//! tick, and one that leaves is not waited for. A vote relayed by a peer counts only if
//! its origin is a live member and the vote is of the origin's live instance (the one
//! we hear from directly); the origin's own copy replaces a relayed one.

use crate::clock::TickWindow;
use crate::config::ConsensusRule;
use crate::consensus::{self, Ballot, Rule, Weights};
use crate::floor::{self, CameraCalibration, FloorView, StationMap, RELATION_DIM};
use crate::graph::{GraphBuilder, OnFloor};
use crate::metrics::{Metrics, Stage};
use crate::model::Inference;
use crate::stale::Repeats;
use crate::temporal::{self, Row, RowLayout, TemporalModel, Window};
use crate::trust::{TrustBook, TrustConfig};
use crate::vote;
use spwi_proto::*;
use std::collections::{BTreeMap, BTreeSet};
use std::time::{Duration, Instant};

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
    /// A feed showing the same worker detection this many times in a row is stale
    /// (0: never).
    #[serde(default)]
    pub stale_after: u32,
    /// The ticks around `now` a frame or a peer's message may be for.
    pub window: TickWindow,
}

impl EngineConfig {
    /// The rules a daemon runs with: timing and consensus from its `[tick]` config, the
    /// paper rule's weights from there or else from the model set's manifest. The
    /// daemon and the evaluation both build their engines here, so the evaluation
    /// judges what robots run.
    pub fn new(
        robot: RobotId,
        instance: u64,
        tick: &crate::config::TickConfig,
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
            stale_after: tick.stale_after_frames,
            window: TickWindow { past: tick.accept_past_ticks, ahead: tick.accept_ahead_ticks },
        }
    }
}

fn every_member() -> usize {
    usize::MAX
}

/// Everything that can happen to a robot.
#[derive(Debug, Clone, PartialEq)]
pub enum Input {
    Frame(DetectionFrame),
    /// A peer's share of a tick, its vote inside.
    Embedding(EmbeddingMsg),
    /// The ballots a peer holds for a tick.
    Ballots(BallotsMsg),
    /// Where a member's map puts the stations (sent when a robot joins).
    Map(MapMsg),
    MemberJoined(RobotId),
    MemberLeft(RobotId),
    /// Time passed: deadlines may have expired.
    Poll,
}

impl Input {
    /// The tick the input is for, if it names one.
    pub fn tick(&self) -> Option<u64> {
        match self {
            Input::Frame(f) => Some(f.tick()),
            Input::Embedding(e) => Some(e.tick),
            Input::Ballots(b) => Some(b.tick),
            Input::Map(_) | Input::MemberJoined(_) | Input::MemberLeft(_) | Input::Poll => None,
        }
    }
}

/// What the robot publishes.
#[derive(Debug, Clone, PartialEq)]
pub enum Output {
    /// Our share of a tick, our vote inside.
    Embedding(EmbeddingMsg),
    /// Our vote again, alone, for observers (peers read it in our share).
    Vote(VoteMsg),
    Ballots(BallotsMsg),
    Decision(DecisionMsg),
    /// Our team map, for a robot that just joined.
    Map(MapMsg),
}

/// How many ticks old a peer's share may be for our vote to read it (0.3 s): its
/// worker estimate is predicted forward to our tick, its embedding and facing read
/// as they are. The latest share of every peer is one tick old when our frame comes
/// in; older ones stand in for a few lost messages.
pub const PEER_VIEW_TICKS: u64 = 3;

/// A peer's latest share, until a newer one arrives: what our vote reads of it.
#[derive(Debug)]
struct PeerView {
    tick: u64,
    /// `None` when it does not see the worker (or its feed is stale).
    embedding: Option<Vec<f32>>,
    worker: Option<WorkerEstimate>,
    facing: Option<f32>,
}

/// What our own frame gave for a tick, until it is voted on.
struct OwnView {
    visibility: u32,
    /// How well our frame shows the worker ([`vote::view_quality`]).
    quality: f32,
    /// `None` when the worker was not seen (or the GCN failed).
    embedding: Option<Vec<f32>>,
    keypoints: Option<Vec<f32>>,
    /// Our own track's estimate of the worker for this tick.
    worker: Option<WorkerEstimate>,
    /// Where our frame shows the worker's body facing (floor frame, radians).
    facing: Option<f32>,
    /// We vote for this tick: we see the worker, or (relation rows) we track it.
    will_vote: bool,
}

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

/// Where robot `robot` ranks among tick `tick`'s relayers (lower first): FNV-1a of the
/// two, then a 64-bit finaliser (splitmix64's) so that every bit of the tick moves the
/// order.
fn relay_rank(tick: u64, robot: &RobotId) -> u64 {
    let mut fnv = consensus::Fnv1a::default();
    fnv.eat(&tick.to_le_bytes());
    fnv.eat(robot.as_str().as_bytes());
    let mut h = fnv.0;
    h = (h ^ (h >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    h = (h ^ (h >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    h ^ (h >> 31)
}

/// Decided ticks whose ballots we keep to answer peers still deciding them (a tick is
/// decided within its deadline, well before the next but one starts).
const ANSWERED_TICKS: usize = 2;

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
    own_feed: Repeats<(BBox, Vec<f32>)>,
    /// Each peer's feed: its embeddings.
    peer_feeds: BTreeMap<RobotId, Repeats<Vec<f32>>>,
    /// Each peer's latest share.
    peer_views: BTreeMap<RobotId, PeerView>,
    /// Every robot's record of agreeing with the others, ours included.
    trust: TrustBook,
    metrics: Metrics,
    /// Instance ids of other daemons seen using our robot id.
    duplicates: BTreeSet<u64>,
    /// Each live peer's instance, as it last spoke to us directly: the only one whose
    /// relayed votes count.
    instances: BTreeMap<RobotId, u64>,
    /// How each live peer's ticks sit against our clock.
    peer_clocks: BTreeMap<RobotId, crate::clock::PeerClock>,
    /// When we last logged a frame or message refused for its tick (rate limit).
    warned_off_clock: Option<Duration>,
    last_decision: Option<DecisionMsg>,
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

    pub fn new(cfg: EngineConfig, inference: Inference) -> Self {
        let m = &inference.set().manifest;
        let graph = GraphBuilder::new(m.max_nodes, m.edge_weight, m.node_features);
        let window = Window::with_frames(m.window, m.frames(), m.row).with_peer_slots(inference.peer_slots());
        let row_layout = m.row;
        let temperature = inference.set().temperature(cfg.temporal);
        let floor = FloorView::new(cfg.camera.clone());
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
            instances: BTreeMap::new(),
            peer_clocks: BTreeMap::new(),
            warned_off_clock: None,
            last_decision: None,
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

    fn peer_is_stale(&self, robot: &RobotId) -> bool {
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

    /// When round `k` of tick `t` comes: round 0 at the relay time, then the asks,
    /// spread evenly between it and the deadline (`None`: no relays, or no rounds left).
    fn round_time(&self, t: &Tick, k: u32) -> Option<Duration> {
        let after = self.cfg.relay_after.filter(|_| k <= self.cfg.ask_rounds)?;
        Some(t.started + after + self.cfg.decision_deadline.saturating_sub(after) * k / (self.cfg.ask_rounds + 1))
    }

    /// How the ticks of each live peer's messages sit against our clock: the offset
    /// of its ticks' starts from when we heard them (ms, averaged; includes the link's
    /// delay), and how many of its messages fell outside our window.
    pub fn peer_clocks(&self) -> &BTreeMap<RobotId, crate::clock::PeerClock> {
        &self.peer_clocks
    }

    /// Handles one input at time `now` (the fleet's clock, since the Unix epoch) and
    /// returns what to publish, in order.
    pub fn handle(&mut self, input: Input, now: Duration) -> Vec<Output> {
        let mut out = Vec::new();
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
            Input::MemberJoined(r) => {
                // A robot that joins has mapped nothing yet: we tell it what we have.
                if r != self.cfg.robot && self.live.insert(r) {
                    let stations = self.floor.team_map.own_stations();
                    if stations.iter().any(Option::is_some) {
                        let (robot, instance) = (self.cfg.robot.clone(), self.cfg.instance);
                        out.push(Output::Map(MapMsg { robot, instance, stations }));
                    }
                }
            }
            Input::MemberLeft(r) => {
                self.live.remove(&r);
                self.active.remove(&r);
                self.instances.remove(&r);
                self.peer_clocks.remove(&r);
                self.peer_feeds.remove(&r); // a robot that comes back is judged afresh
                self.peer_views.remove(&r);
                self.advance_all(now, &mut out);
            }
            Input::Poll => self.advance_all(now, &mut out),
        }
        out
    }

    fn on_frame(&mut self, mut f: DetectionFrame, now: Duration, out: &mut Vec<Output>) {
        if f.robot != self.cfg.robot {
            return; // the daemon only subscribes to our own detections
        }
        let tick = f.tick();
        if let Some(off) = self.cfg.window.refuses(tick, now) {
            self.metrics.count_off_clock(off.frame());
            self.warn_off_clock(&f, now);
            return;
        }
        if self.decided.contains_key(&tick) || self.open.get(&tick).is_some_and(|t| t.own_frame.is_some()) {
            self.metrics.stale_frames += 1;
            return;
        }
        self.metrics.frames += 1;
        let was_stale = self.feed_is_stale();
        self.own_feed.see(f.human.as_ref().map(|h| (h.bbox, h.keypoints.clone())));
        let stale = self.feed_is_stale();
        if stale != was_stale {
            if stale {
                tracing::warn!(
                    tick = tick,
                    repeats = self.cfg.stale_after,
                    "our camera repeats the same worker detection: a frozen feed; not voting until it changes"
                );
            } else {
                tracing::info!(tick = tick, "our camera's feed changes again: voting");
            }
        }
        if stale {
            // Nothing of a frozen frame is evidence: not the worker, not the objects.
            self.metrics.repeated_frames += 1;
            f.human = None;
            f.objects.clear();
        }
        // The track first: a graph of floor relations places the objects against it.
        let (worker, landmarks) = if stale { (None, Vec::new()) } else { self.floor.observe(&f) };
        let on_floor = worker.as_ref().map(|worker| OnFloor { camera: self.floor.camera(), worker });
        let t0 = Instant::now();
        let embedding = match self.graph.build(&f, on_floor) {
            None => None,
            Some(g) => {
                self.metrics.frames_with_worker += 1;
                let t1 = Instant::now();
                self.metrics.observe(Stage::Graph, t1 - t0);
                let r = self.inference.gcn(g);
                self.metrics.observe(Stage::Gcn, t1.elapsed());
                match r {
                    Ok(o) => {
                        self.last_spatial = Some((tick, o.logits));
                        Some(o.embedding)
                    }
                    Err(e) => {
                        self.metrics.model_errors += 1;
                        tracing::error!(tick = tick, "GCN failed, not voting this tick: {e:#}");
                        None
                    }
                }
            }
        };
        let keypoints = f.human.as_ref().map(|h| temporal::normalise_keypoints(&h.keypoints, f.image_size));
        let visibility = f.visibility();
        let quality = vote::view_quality(&f);
        // Shared whatever our set reads: a peer's set may read the team's facing.
        let facing = self.floor.camera().facing_in(&f);
        // A set that reads relations votes from the worker's track while it is fresh:
        // the team keeps an answer through a few frames in which nobody sees the worker.
        let will_vote = embedding.is_some() || (self.row_layout.reads_relations() && worker.is_some());
        let shared = embedding.clone();
        let own = OwnView { visibility, quality, embedding, keypoints, worker, facing, will_vote };
        let vote = self.vote(tick, own);
        out.push(Output::Embedding(EmbeddingMsg {
            robot: self.cfg.robot.clone(),
            instance: self.cfg.instance,
            tick,
            embedding: shared,
            visibility,
            vote: vote.clone(),
            worker,
            facing,
            landmarks,
            verdict: self.unshared_verdict.take(),
        }));
        let me = self.cfg.robot.clone();
        let open = self.open_tick(tick, now);
        // Our own frame, stamped by our own source, may start the tick before our
        // clock says it starts (a clock a little behind the fleet's); a peer's word
        // never can.
        open.started = open.started.min(now);
        open.own_frame = Some(now);
        if let Some(v) = vote {
            open.votes.insert(me, v.clone());
            out.push(Output::Vote(v));
        }
        self.advance(tick, now, out);
    }

    fn on_embedding(&mut self, mut e: EmbeddingMsg, now: Duration, out: &mut Vec<Output>) {
        let from_peer = e.robot != self.cfg.robot;
        if !self.on_our_clock(&e.robot, e.tick, now) {
            return;
        }
        if from_peer && self.live.contains(&e.robot) {
            // What the peer says directly names its live instance.
            self.instances.insert(e.robot.clone(), e.instance);
        }
        if from_peer {
            self.peer_feeds.entry(e.robot.clone()).or_default().see(e.embedding.clone());
            if let Some(theirs) = e.verdict.take() {
                self.compare(&e.robot, theirs);
            }
        }
        let stale = self.peer_is_stale(&e.robot);
        if stale {
            self.metrics.stale_peer_messages += 1;
        } else if from_peer {
            // Where a peer saw station objects stays true after its tick.
            self.floor.add_peer_landmarks(&e.landmarks, e.tick);
        }
        if from_peer && self.peer_views.get(&e.robot).is_none_or(|v| v.tick <= e.tick) {
            // A stale peer is heard as one that does not see the worker.
            let view = if stale {
                PeerView { tick: e.tick, embedding: None, worker: None, facing: None }
            } else {
                PeerView { tick: e.tick, embedding: e.embedding, worker: e.worker, facing: e.facing }
            };
            self.peer_views.insert(e.robot.clone(), view);
        }
        if let Some(tick) = self.accept_peer(&e.robot, e.instance, e.tick, now) {
            match e.vote {
                // A stale peer is heard as one that abstains. Its own copy of its vote
                // wins over one a peer relayed; of its own copies, the first.
                Some(v) if !stale => {
                    if tick.heard_directly.insert(e.robot.clone()) {
                        tick.votes.insert(e.robot.clone(), v);
                    }
                }
                _ => {
                    tick.abstaining.insert(e.robot.clone());
                }
            }
            self.advance(e.tick, now, out);
        }
    }

    /// A peer's relayed ballots: the votes we do not hold yet join the tick (never our
    /// own, never a stale peer's); for a tick already decided they are only counted.
    fn on_ballots(&mut self, b: BallotsMsg, now: Duration, out: &mut Vec<Output>) {
        if !self.on_our_clock(&b.robot, b.tick, now) {
            return;
        }
        if b.robot == self.cfg.robot {
            // Our own relay (or another daemon's with our id, which this notes).
            self.accept_peer(&b.robot, b.instance, b.tick, now);
            return;
        }
        if let Some(ours) = self.decided.get(&b.tick) {
            let missed = b.votes.iter().filter(|v| v.robot != self.cfg.robot && !ours.voters.contains(&v.robot));
            self.metrics.late_relayed_ballots += missed.count() as u64;
        }
        self.answer(&b, out);
        let me = self.cfg.robot.clone();
        let relayer = b.robot.clone();
        let (usable, foreign): (Vec<VoteMsg>, Vec<VoteMsg>) = b
            .votes
            .into_iter()
            .filter(|v| v.robot != me && !self.peer_is_stale(&v.robot))
            .partition(|v| v.robot == relayer || self.is_live_instance(&v.robot, v.instance));
        self.metrics.foreign_votes += foreign.len() as u64;
        if let Some(tick) = self.accept_peer(&b.robot, b.instance, b.tick, now) {
            let mut used = 0;
            for v in usable {
                if let std::collections::btree_map::Entry::Vacant(slot) = tick.votes.entry(v.robot.clone()) {
                    slot.insert(v);
                    used += 1;
                }
            }
            self.metrics.relayed_ballots_used += used;
        }
        self.advance(b.tick, now, out);
    }

    /// A peer's ballots list every vote it holds for their tick: if they lack one we
    /// hold (not the peer's own) and we relay the tick, we answer with ours, at most
    /// `ask_rounds` times a tick, also once we decided it.
    fn answer(&mut self, theirs: &BallotsMsg, out: &mut Vec<Output>) {
        let t = theirs.tick;
        if self.cfg.relay_after.is_none() || !self.relays(t) {
            return;
        }
        let Some(tick) = self.open.get_mut(&t).or_else(|| self.settled.get_mut(&t)) else { return };
        let held = |r: &RobotId| *r == theirs.robot || theirs.votes.iter().any(|v| v.robot == *r);
        if tick.answers < self.cfg.ask_rounds && !tick.votes.keys().all(held) {
            tick.answers += 1;
            self.metrics.ballot_answers += 1;
            out.push(ballots(&self.cfg, t, &tick.votes));
        }
    }

    /// Checks a peer message's origin and tick; returns the tick to file it in.
    fn accept_peer(&mut self, robot: &RobotId, instance: u64, tick: u64, now: Duration) -> Option<&mut Tick> {
        if *robot == self.cfg.robot {
            if instance != self.cfg.instance {
                self.metrics.duplicate_id_messages += 1;
                if self.duplicates.insert(instance) {
                    tracing::error!(robot = %robot, other_instance = instance, "another live daemon uses this robot id: peers cannot tell our votes apart; give each robot a unique id");
                }
            }
            return None;
        }
        self.active.insert(robot.clone()); // even a late message shows the peer is there
        if self.decided.contains_key(&tick) {
            self.metrics.late_messages += 1;
            return None;
        }
        Some(self.open_tick(tick, now))
    }

    /// Whether a message of `robot` for `tick` is for a tick near our clock; one that
    /// is not is refused and counted, and shows in the peer's clock record either way.
    fn on_our_clock(&mut self, robot: &RobotId, tick: u64, now: Duration) -> bool {
        let refused = self.cfg.window.refuses(tick, now);
        if *robot != self.cfg.robot && self.live.contains(robot) {
            let clock = self.peer_clocks.entry(robot.clone()).or_default();
            match refused {
                None => clock.heard(tick, now),
                Some(_) => clock.heard_off_window(tick, now),
            }
        }
        match refused {
            Some(off) => {
                self.metrics.count_off_clock(off.message());
                if self.may_warn_off_clock(now) {
                    let by = crate::clock::signed_ms(tick_start(tick), now);
                    tracing::warn!(%robot, tick, "refused a message for a tick starting {by} ms from our clock's now (spwi_off_clock_total counts them; /status clocks shows the peer)");
                }
                false
            }
            None => true,
        }
    }

    /// At most one log line about ticks off our clock every 5 s.
    fn may_warn_off_clock(&mut self, now: Duration) -> bool {
        if self.warned_off_clock.is_some_and(|at| now.saturating_sub(at) < Duration::from_secs(5)) {
            return false;
        }
        self.warned_off_clock = Some(now);
        true
    }

    /// Whether `instance` is the one `robot`, a live member, runs as far as we heard.
    fn is_live_instance(&self, robot: &RobotId, instance: u64) -> bool {
        self.live.contains(robot) && self.instances.get(robot).is_none_or(|&i| i == instance)
    }

    fn warn_off_clock(&mut self, f: &DetectionFrame, now: Duration) {
        if !self.may_warn_off_clock(now) {
            return;
        }
        if f.capture_us == 0 {
            tracing::warn!("refused a frame without a capture time: its source must stamp capture_us (µs since the Unix epoch, on a synchronised clock)");
        } else {
            let by = crate::clock::signed_ms(Duration::from_micros(f.capture_us), now);
            tracing::warn!(
                tick = f.tick(),
                "refused a frame captured {} ms {} our clock (the window takes {} ticks back, {} ahead): is the source's clock synchronised?",
                by.unsigned_abs(),
                if by < 0 { "behind" } else { "ahead of" },
                self.cfg.window.past,
                self.cfg.window.ahead
            );
        }
    }

    /// Forgets what lies behind the window: ticks still open there are decided with
    /// what they hold (their deadline has passed), decided ones are forgotten.
    fn forget_the_past(&mut self, now: Duration, out: &mut Vec<Output>) {
        let oldest = self.cfg.window.oldest(now);
        while let Some(&t) = self.open.keys().next().filter(|&&t| t < oldest) {
            self.decide(t, DecidedBy::Deadline, now, out);
        }
        if self.decided.keys().next().is_some_and(|&t| t < oldest) {
            self.decided = self.decided.split_off(&oldest);
        }
    }

    /// Tick `t`, opened if it was not: its deadline runs from now, or from its start on
    /// our clock if that is later.
    fn open_tick(&mut self, tick: u64, now: Duration) -> &mut Tick {
        if !self.open.contains_key(&tick) && self.open.len() >= self.cfg.max_open_ticks {
            if let Some((old, _)) = self.open.pop_first() {
                self.metrics.evicted_ticks += 1;
                tracing::warn!(tick = old, "dropping an undecided tick: too many open");
            }
        }
        self.open.entry(tick).or_insert_with(|| Tick::new(now.max(tick_start(tick))))
    }

    fn advance_all(&mut self, now: Duration, out: &mut Vec<Output>) {
        let ticks: Vec<u64> = self.open.keys().copied().collect();
        for t in ticks {
            self.advance(t, now, out);
        }
    }

    /// Moves tick `t` on as far as its messages and `now` allow.
    fn advance(&mut self, t: u64, now: Duration, out: &mut Vec<Output>) {
        let Some(tick) = self.open.get(&t) else { return };
        let decision_due = now >= tick.started + self.cfg.decision_deadline;

        // Relay, then ask: partway through the tick, the ballots we hold go to every peer.
        self.run_rounds(t, now, out);

        // The decision, once our frame is in and every active member voted or abstained.
        let tick = &self.open[&t];
        let all_voted = tick.own_frame.is_some() && !self.waits_for_a_vote(tick);
        if all_voted {
            self.decide(t, DecidedBy::AllVoted, now, out);
        } else if decision_due {
            self.decide(t, DecidedBy::Deadline, now, out);
        }
    }

    /// Adds tick `t`'s window row from our own view of it and our peers' latest shares
    /// and, if we vote for the tick, runs the GRU and votes.
    fn vote(&mut self, t: u64, own: OwnView) -> Option<VoteMsg> {
        let peers: Vec<(&RobotId, &PeerView)> =
            self.peer_views.iter().filter(|(_, v)| v.tick.abs_diff(t) <= PEER_VIEW_TICKS).collect();
        // Where each robot puts the worker this tick, ours first: an estimate most of
        // the others contradict is left out of the team's track, and so are peers we
        // have learned to doubt.
        let me = &self.cfg.robot;
        let theirs = peers.iter().map(|(r, v)| (*r, v.tick, v.worker, v.facing));
        let held = floor::held_at(t, own.worker.map(|w| (me, w, own.facing)), theirs);
        let (robots, sightings) = floor::sightings(&held);
        let trust = &self.trust;
        let team = floor::team_worker(&sightings, |i| robots[i] == me || trust.fuses(robots[i]));
        // A peer-set model also reads each fused peer's own estimate.
        let slots = self.inference.peer_slots();
        let fused_peers = if slots > 0 { team.kept_peers(&sightings, |i| robots[i] == me) } else { Vec::new() };
        let peers_mean =
            temporal::mean(peers.iter().filter(|(r, _)| trust.fuses(r)).filter_map(|(_, v)| v.embedding.as_deref()));
        self.floor.observe_worker(own.worker.as_ref(), team.track.as_ref());
        let will_vote = own.will_vote;
        // The ego model reads our own track, facing and map, the collective the team's.
        let (worker, facing, stations) = match self.cfg.temporal {
            TemporalModel::Ego => (own.worker.as_ref(), own.facing, self.floor.own_map.stations()),
            TemporalModel::Collective => (team.track.as_ref(), team.facing, self.floor.team_map.stations()),
        };
        let (relations, facing) = self.row_layout.blocks(worker, facing, &stations);
        let peers = (slots > 0).then(|| {
            let mut p = vec![0.0; slots * RELATION_DIM];
            floor::peer_set(&fused_peers, &self.floor.team_map.stations(), slots, &mut p);
            p
        });
        let row = Row { own: own.embedding, peers_mean, keypoints: own.keypoints, relations, facing, peers };
        let (visibility, quality) = (own.visibility, own.quality);
        self.window.insert(t, row);
        if !will_vote {
            return None;
        }
        self.window.input(t, self.cfg.temporal, &mut self.scratch);
        self.window.peer_input(t, &mut self.scratch_peers);
        let t0 = Instant::now();
        let logits = self.inference.gru(&self.scratch, &self.scratch_peers);
        self.metrics.observe(Stage::Gru, t0.elapsed());
        match logits {
            Ok(l) => Some(VoteMsg {
                robot: self.cfg.robot.clone(),
                instance: self.cfg.instance,
                tick: t,
                steps: vote::vote(&l, self.temperature),
                visibility,
                quality,
                worker: own.worker,
                signature: Vec::new(), // the daemon signs what it publishes
            }),
            Err(e) => {
                self.metrics.model_errors += 1;
                tracing::error!(tick = t, "GRU failed, not voting this tick: {e:#}");
                None
            }
        }
    }

    /// Some active member has neither voted nor abstained in `tick` (as far as we heard).
    fn waits_for_a_vote(&self, tick: &Tick) -> bool {
        self.live.intersection(&self.active).any(|r| !tick.abstaining.contains(r) && !tick.votes.contains_key(r))
    }

    /// The rounds of tick `t` that came by `now` (one message however many came): at the
    /// first, the relay time, the tick's relayers publish the ballots they hold (nothing
    /// when they hold none); at each later one, a robot still waiting for a member's
    /// vote publishes them, an ask.
    fn run_rounds(&mut self, t: u64, now: Duration, out: &mut Vec<Output>) {
        let tick = &self.open[&t];
        let due = (tick.rounds..).take_while(|&k| self.round_time(tick, k).is_some_and(|at| now >= at)).count();
        if due == 0 {
            return;
        }
        let relay = self.owes_relay(t);
        // Not at the relay time itself: the relays of that moment are still on their way.
        let ask = tick.rounds + due as u32 > 1 && self.waits_for_a_vote(tick);
        let tick = self.open.get_mut(&t).expect("open");
        tick.rounds += due as u32;
        if relay || ask {
            if ask && !relay {
                self.metrics.ballot_asks += 1;
            }
            out.push(ballots(&self.cfg, t, &tick.votes));
        }
    }

    /// We relay open tick `t`, hold votes to relay, and its relay time is yet to pass.
    fn owes_relay(&self, t: u64) -> bool {
        let tick = &self.open[&t];
        self.cfg.relay_after.is_some() && tick.rounds == 0 && self.relays(t) && !tick.votes.is_empty()
    }

    /// Whether we relay tick `t`'s ballots. Every member holding them relaying them
    /// would send each vote once per member again: n² votes a tick, n − 1 messages to
    /// each robot, most of a large fleet's traffic (docs/BENCHMARKS.md). A vote lost on
    /// one link needs only a few other paths, so `relayers` members relay each tick:
    /// those that rank first by a hash of the tick and their id, a different few each
    /// tick so that no robot carries it alone; every member when the fleet has no
    /// more. The members counted are ours and the peers we wait for; two robots that
    /// count differently for a moment only change how many relay.
    fn relays(&self, t: u64) -> bool {
        let mine = (relay_rank(t, &self.cfg.robot), &self.cfg.robot);
        let ahead = self.live.intersection(&self.active).filter(|r| (relay_rank(t, r), *r) < mine).count();
        ahead < self.cfg.relayers
    }

    fn decide(&mut self, t: u64, by: DecidedBy, now: Duration, out: &mut Vec<Output>) {
        // Deciding before the relay time: if we relay the tick, the ballots we hold go
        // out now, since a peer that lost one of them may still be waiting.
        if self.owes_relay(t) {
            out.push(ballots(&self.cfg, t, &self.open[&t].votes));
        }
        let mut tick = self.open.remove(&t).expect("open");
        let t0 = Instant::now();
        // Each ballot weighs what we learned of its voter. Voters we doubt are set
        // aside while one we trust votes, and never decide a tick for the team while
        // a trusted member (we at least) is live: the tick then goes without a class.
        let all: Vec<Ballot<'_>> = tick.votes.values().map(|v| Ballot::of(v, self.trust.weight(&v.robot))).collect();
        let trusted = |b: &&Ballot<'_>| self.trust.counts(b.robot);
        let members = || std::iter::once(&self.cfg.robot).chain(self.live.iter());
        let anyone_trusted = all.iter().any(|b| trusted(&b)) || members().any(|r| self.trust.counts(r));
        let mut counted: Vec<Ballot<'_>> = all.iter().filter(|b| !anyone_trusted || trusted(b)).copied().collect();
        // Nor does a voter not yet established decide a tick alone while a member the
        // team has seen agree is live.
        if let [alone] = counted[..] {
            let others_established = members().any(|m| m != alone.robot && self.trust.established(m));
            if others_established && !self.trust.established(alone.robot) {
                counted.clear();
            }
        }
        let steps = consensus::decide(&mut counted, self.cfg.consensus);
        let digest = consensus::digest(&counted);
        let voters: Vec<RobotId> = counted.iter().map(|b| b.robot.clone()).collect();
        self.metrics.votes_set_aside += (all.len() - counted.len()) as u64;
        self.trust.learn(&all); // tick.votes is a map by robot: `all` is in robot order
        let estimates: Vec<(&RobotId, &WorkerEstimate)> =
            tick.votes.values().filter_map(|v| Some((&v.robot, v.worker.as_ref()?))).collect();
        self.trust.learn_tracks(&estimates);
        self.metrics.observe(Stage::Consensus, t0.elapsed());
        if let Some(arrived) = tick.own_frame {
            self.metrics.observe(Stage::FrameToDecision, now.saturating_sub(arrived));
        }
        self.metrics.decisions += 1;
        if by == DecidedBy::Deadline {
            self.metrics.decisions_by_deadline += 1;
        }
        let d = DecisionMsg {
            robot: self.cfg.robot.clone(),
            instance: self.cfg.instance,
            tick: t,
            steps: steps.clone(),
            voters,
            live_members: self.live.len() as u32 + 1,
            decided_by: by,
            digest,
        };
        let ours = Verdict::of(&d);
        for theirs in std::mem::take(&mut tick.peer_verdicts).values() {
            record_agreement(&mut self.metrics, &ours, theirs);
        }
        self.settled.insert(t, tick);
        while self.settled.len() > ANSWERED_TICKS {
            self.settled.pop_first();
        }
        self.unshared_verdict = Some(ours.clone());
        self.decided.insert(t, ours);
        self.last_decision = Some(d.clone());
        out.push(Output::Decision(d));
    }

    /// A peer's verdict against ours for its tick, now or when we decide it.
    fn compare(&mut self, peer: &RobotId, theirs: Verdict) {
        if let Some(ours) = self.decided.get(&theirs.tick) {
            record_agreement(&mut self.metrics, ours, &theirs);
        } else if let Some(tick) = self.open.get_mut(&theirs.tick) {
            tick.peer_verdicts.insert(peer.clone(), theirs);
        }
    }
}

/// Our Ballots message for tick `t`: every vote we hold for it.
fn ballots(cfg: &EngineConfig, t: u64, held: &BTreeMap<RobotId, VoteMsg>) -> Output {
    let votes = held.values().cloned().collect();
    Output::Ballots(BallotsMsg { robot: cfg.robot.clone(), instance: cfg.instance, tick: t, votes })
}

/// Counts one comparison of our verdict of a tick with a peer's.
fn record_agreement(m: &mut Metrics, ours: &Verdict, theirs: &Verdict) {
    m.agreement_compared += 1;
    m.agreement_same += u64::from(ours.class == theirs.class);
    if ours.digest != theirs.digest {
        m.ballot_sets_differ += 1;
        let theirs_has_ours = ours.voters.iter().all(|v| theirs.voters.binary_search(v).is_ok());
        if theirs_has_ours && theirs.voters.len() > ours.voters.len() {
            m.decided_on_fewer_ballots += 1;
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::clock::OffClock;
    use crate::model::{Backend, ModelSet};
    use crate::trust::UNJUDGED;
    use std::sync::Arc;

    fn models() -> Arc<ModelSet> {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/fixture");
        ModelSet::load(&dir, Backend::Tract, None).unwrap()
    }

    fn id(s: &str) -> RobotId {
        RobotId::new(s).unwrap()
    }

    fn engine(robot: &str, set: &Arc<ModelSet>) -> Engine {
        let cfg = EngineConfig {
            robot: id(robot),
            instance: 1,
            temporal: TemporalModel::Collective,
            decision_deadline: Duration::from_millis(60),
            consensus: Rule::Trust,
            trust: TrustConfig::default(),
            max_open_ticks: 8,
            camera: CameraCalibration::default(),
            relay_after: None,
            relayers: 4,
            ask_rounds: 2,
            stale_after: 5,
            window: TickWindow::default(),
        };
        Engine::new(cfg, set.inference(TemporalModel::Collective).unwrap())
    }

    /// A frame whose features depend on (robot, tick) so robots disagree sometimes.
    pub(crate) fn frame(robot: &str, tick: u64, seen: bool) -> DetectionFrame {
        let seed = tick as f32 * 0.37 + robot.len() as f32;
        let feat = |k: f32| (0..FEATURE_DIM).map(|i| (i as f32 * 0.1 + k + seed).sin()).collect::<Vec<_>>();
        DetectionFrame {
            robot: id(robot),
            capture_us: DetectionFrame::capture_at_tick(tick),
            pose: None,
            image_size: [640.0, 480.0],
            human: seen.then(|| HumanDetection {
                bbox: BBox { x: 300.0, y: 200.0, w: 40.0, h: 120.0 },
                // A live detector: the keypoints move a little every frame.
                keypoints: (0..KEYPOINT_VALUES).map(|i| 300.0 + i as f32 + (seed * 7.0).sin()).collect(),
                feature: feat(1.0),
            }),
            objects: (0..3)
                .map(|k| ObjectDetection {
                    class: ObjectClass::ALL[k],
                    bbox: BBox { x: 100.0 * k as f32, y: 300.0, w: 50.0, h: 50.0 },
                    score: 0.8,
                    feature: feat(k as f32 + 2.0),
                })
                .collect(),
            scene_feature: feat(0.0),
        }
    }

    fn ms(m: u64) -> Duration {
        Duration::from_millis(m)
    }

    fn decisions(out: &[Output]) -> Vec<&DecisionMsg> {
        out.iter().filter_map(|o| if let Output::Decision(d) = o { Some(d) } else { None }).collect()
    }

    /// A vote as a trusted peer with a full view sends it.
    fn vote_msg(robot: &str, instance: u64, tick: u64, steps: Vec<StepVote>) -> VoteMsg {
        VoteMsg {
            robot: id(robot),
            instance,
            tick,
            steps,
            visibility: 1,
            quality: 1.0,
            worker: None,
            signature: vec![],
        }
    }

    /// A peer's share of a tick (instance 2, no landmarks): an embedding of `x`s if it
    /// sees the worker, its vote if it votes, its estimate of the worker.
    fn share(
        robot: &str,
        tick: u64,
        x: Option<f32>,
        vote: Option<Vec<StepVote>>,
        worker: Option<WorkerEstimate>,
    ) -> EmbeddingMsg {
        EmbeddingMsg {
            robot: id(robot),
            instance: 2,
            tick,
            embedding: x.map(|x| vec![x; EMBEDDING_DIM]),
            visibility: 3,
            vote: vote.map(|steps| vote_msg(robot, 2, tick, steps)),
            worker,
            facing: None,
            landmarks: Vec::new(),
            verdict: None,
        }
    }

    /// A peer's share of a tick in which it neither sees the worker nor votes.
    fn abstaining(robot: &str, tick: u64) -> Input {
        Input::Embedding(share(robot, tick, None, None, None))
    }

    fn one_step(class: Station) -> Vec<StepVote> {
        vec![StepVote { class, confidence: 1.0 }]
    }

    /// Our vote, in our share of the tick (and the same alone, for observers).
    fn take_vote(out: &[Output]) -> VoteMsg {
        let v = take_embedding(out).vote.expect("a vote");
        let alone = out.iter().find_map(|o| if let Output::Vote(v) = o { Some(v) } else { None });
        assert_eq!(alone, Some(&v), "the vote goes out alone too, for observers");
        v
    }

    fn take_embedding(out: &[Output]) -> EmbeddingMsg {
        out.iter()
            .find_map(|o| if let Output::Embedding(e) = o { Some(e.clone()) } else { None })
            .expect("an embedding")
    }

    #[test]
    fn a_lone_robot_decides_each_tick_at_once() {
        let set = models();
        let mut e = engine("a", &set);
        let out = e.handle(Input::Frame(frame("a", 1, true)), ms(0));
        assert!(take_embedding(&out).embedding.is_some());
        let v = take_vote(&out);
        assert_eq!(v.steps.len(), set.manifest.horizon + 1);
        let d = decisions(&out);
        assert_eq!(d.len(), 1);
        assert_eq!(d[0].decided_by, DecidedBy::AllVoted);
        assert_eq!(d[0].steps[0].class, v.steps[0].class);
        assert_eq!(d[0].voters, vec![id("a")]);
    }

    #[test]
    fn a_robot_that_does_not_see_the_worker_says_so_and_still_decides() {
        let set = models();
        let mut e = engine("a", &set);
        let out = e.handle(Input::Frame(frame("a", 1, false)), ms(0));
        let e = take_embedding(&out);
        assert_eq!((e.embedding, e.vote), (None, None));
        assert!(out.iter().all(|o| !matches!(o, Output::Vote(_))));
        assert!(decisions(&out)[0].steps.is_empty());
    }

    #[test]
    fn two_robots_wait_for_each_other_and_agree() {
        let set = models();
        let (mut a, mut b) = (engine("a", &set), engine("b", &set));
        for (x, other) in [(&mut a, "b"), (&mut b, "a")] {
            x.handle(Input::MemberJoined(id(other)), ms(0));
        }
        // Peers heard from before: both are active members.
        let warm_a = a.handle(Input::Frame(frame("a", 1, true)), ms(0));
        let warm_b = b.handle(Input::Frame(frame("b", 1, true)), ms(0));
        // a has not heard from b yet: it decides alone at once; so does b.
        assert_eq!(decisions(&warm_a).len(), 1);
        assert_eq!(decisions(&warm_b).len(), 1);

        // Tick 2: now both are active; each votes at once and decides on hearing the other.
        let out_a = a.handle(Input::Embedding(take_embedding(&warm_b)), ms(1)); // late for tick 1
        assert!(out_a.is_empty());
        assert_eq!(a.metrics.late_messages, 1);
        b.handle(Input::Embedding(take_embedding(&warm_a)), ms(1));
        let oa = a.handle(Input::Frame(frame("a", 2, true)), ms(100));
        let ob = b.handle(Input::Frame(frame("b", 2, true)), ms(100));
        take_vote(&oa);
        assert!(decisions(&oa).is_empty(), "a must wait for b's share of the tick");
        let da = a.handle(Input::Embedding(take_embedding(&ob)), ms(101));
        let db = b.handle(Input::Embedding(take_embedding(&oa)), ms(101));
        let (da, db) = (decisions(&da)[0], decisions(&db)[0]);
        assert_eq!(da.steps, db.steps, "same votes, same decision");
        assert_eq!(da.voters, vec![id("a"), id("b")]);
        assert_eq!(da.decided_by, DecidedBy::AllVoted);
    }

    #[test]
    fn a_silent_peer_is_waited_for_only_until_the_deadline() {
        let set = models();
        let mut a = engine("a", &set);
        a.handle(Input::MemberJoined(id("b")), ms(0));
        a.handle(Input::Frame(frame("a", 1, true)), ms(100));
        a.handle(abstaining("b", 1), ms(101));
        let out = a.handle(Input::Frame(frame("a", 2, true)), ms(200));
        take_vote(&out);
        assert!(decisions(&out).is_empty());
        assert_eq!(a.next_deadline(), Some(ms(260)));
        assert!(a.handle(Input::Poll, ms(259)).is_empty());
        let out = a.handle(Input::Poll, ms(260));
        assert_eq!(decisions(&out)[0].decided_by, DecidedBy::Deadline);
        assert_eq!(a.metrics.decisions_by_deadline, 1);
    }

    #[test]
    fn a_peer_that_leaves_is_not_waited_for_and_an_unseeing_peer_need_not_vote() {
        let set = models();
        let mut a = engine("a", &set);
        a.handle(Input::Frame(frame("a", 1, true)), ms(0));
        for r in ["b", "c"] {
            a.handle(Input::MemberJoined(id(r)), ms(0));
            a.handle(abstaining(r, 1), ms(0));
        }
        take_vote(&a.handle(Input::Frame(frame("a", 2, true)), ms(100)));
        // c does not see the worker: its vote is not expected.
        assert!(decisions(&a.handle(abstaining("c", 2), ms(101))).is_empty(), "b has not been heard");
        let out = a.handle(Input::MemberLeft(id("b")), ms(102));
        let d = decisions(&out);
        assert_eq!(d[0].decided_by, DecidedBy::AllVoted);
        assert_eq!(d[0].live_members, 2);
    }

    #[test]
    fn a_second_daemon_with_our_id_is_detected() {
        let set = models();
        let mut a = engine("a", &set);
        let ours = |instance| Input::Embedding(EmbeddingMsg { instance, ..share("a", 5, None, None, None) });
        a.handle(ours(1), ms(500));
        assert!(a.duplicates.is_empty(), "our own echo is not a clash");
        a.handle(ours(2), ms(500));
        assert_eq!(a.duplicates.iter().copied().collect::<Vec<_>>(), vec![2]);
        assert_eq!(a.metrics.duplicate_id_messages, 1);
    }

    #[test]
    fn ticks_off_our_clock_are_refused_and_counted_and_block_nothing() {
        let set = models();
        let mut a = engine("a", &set);
        a.handle(Input::MemberJoined(id("z")), ms(0));
        a.handle(Input::Frame(frame("a", 10, true)), ms(1000));
        assert!(a.handle(Input::Frame(frame("a", 10, true)), ms(1001)).is_empty());
        assert_eq!(a.metrics.stale_frames, 1, "the same tick's frame twice");
        // At 1050 ms our clock is in tick 10: we take ticks 5..=12. A member floods a
        // thousand messages for ticks far ahead, far behind, decided, and ahead of ours.
        let flood = [1u64 << 62, u64::MAX, 13, 0, 4, 10, 11, 12];
        for k in 0..1000 {
            let t = flood[k % flood.len()];
            a.handle(Input::Embedding(share("z", t, None, Some(one_step(Station::Storage)), None)), ms(1050));
        }
        let off = |a: &Engine, why| a.metrics.off_clock.get(&why).copied().unwrap_or(0);
        assert_eq!(off(&a, OffClock::MessageTooNew), 375, "every message counted: 3 of 8 too far ahead");
        assert_eq!(off(&a, OffClock::MessageTooOld), 250);
        assert_eq!(a.metrics.late_messages, 125, "tick 10 is decided");
        assert_eq!(a.open.keys().copied().collect::<Vec<_>>(), vec![11, 12], "only ticks near ours are open");
        assert_eq!(a.peer_clocks()[&id("z")].refused, 625);
        // z's early share of tick 11 moved no deadline: it runs from tick 11's start.
        assert_eq!(a.next_deadline(), Some(ms(1160)));
        // The ticks that follow are decided as they come, z's votes in.
        for t in 11..=12 {
            let d = a.handle(Input::Frame(frame("a", t, true)), ms(100 * t));
            assert_eq!(decisions(&d)[0].voters, vec![id("a"), id("z")], "tick {t}");
        }
        // A frame without a capture time, or stamped a day off, is refused and counted.
        for capture_us in [0, 86_400_000_000 + 1_300_000] {
            assert!(a.handle(Input::Frame(DetectionFrame { capture_us, ..frame("a", 13, true) }), ms(1300)).is_empty());
        }
        assert_eq!((off(&a, OffClock::FrameTooOld), off(&a, OffClock::FrameTooNew)), (1, 1));
        // What we remember of decided ticks reaches back as far as the window.
        a.handle(Input::Poll, ms(5000));
        assert!(a.decided.keys().all(|&t| t >= 45), "{:?}", a.decided.keys());
    }

    #[test]
    fn a_localised_robot_shares_its_worker_track_and_the_station_objects_it_sees() {
        let set = models();
        let mut a = engine("a", &set);
        let localised = |tick| DetectionFrame {
            pose: Some(FloorPose { position: [1.0, 2.0], heading: 0.5 }),
            ..frame("a", tick, true)
        };
        let mut last = None;
        for t in 1..=3 {
            last = Some(take_embedding(&a.handle(Input::Frame(localised(t)), ms(100 * t))));
        }
        let e = last.unwrap();
        let w = e.worker.expect("the worker's ankles are on the floor in view: an estimate");
        let range = (w.position[0] - 1.0).hypot(w.position[1] - 2.0);
        assert!((1.0..12.0).contains(&range), "in front of the camera: {w:?}");
        assert_eq!(e.landmarks.len(), 3, "crate, box and pallet mark the storage area");
        assert!(e.landmarks.iter().all(|l| l.station == Station::Storage));
        assert!(a.floor().own_map.station(Station::Storage).is_some(), "seen three times: on the map");
        // A frame without a pose shares nothing on the floor, and a peer's landmarks
        // reach the team map only.
        let out = a.handle(Input::Frame(frame("a", 4, true)), ms(400));
        assert!(take_embedding(&out).landmarks.is_empty());
        let peer = EmbeddingMsg {
            landmarks: vec![Landmark { station: Station::Manufacturing, position: [9.0, 9.0], sigma: 0.3 }; 3],
            ..share("b", 4, None, None, None)
        };
        a.handle(Input::Embedding(peer), ms(401));
        assert!(
            a.floor().team_map.station(Station::Manufacturing).is_some()
                && a.floor().own_map.station(Station::Manufacturing).is_none()
        );
    }

    #[test]
    fn a_robot_that_joins_is_sent_the_team_map_and_takes_it_for_what_it_has_not_seen() {
        let set = models();
        let (mut a, mut b) = (engine("a", &set), engine("b", &set));
        assert!(a.handle(Input::MemberJoined(id("b")), ms(0)).is_empty(), "nothing mapped, nothing to send");
        let sighting = |station, x: f32| Landmark { station, position: [x, 9.0], sigma: 0.3 };
        for l in [sighting(Station::Manufacturing, 9.0), sighting(Station::Storage, 2.0)] {
            for _ in 0..3 {
                a.floor.team_map.add(&l, 0);
            }
        }
        b.floor.team_map.borrow(&[None, None, None, Some([50.0, 50.0])]); // heard from another
        let map = |out: Vec<Output>| match out.as_slice() {
            [Output::Map(m)] => m.clone(),
            other => panic!("expected the map alone, got {other:?}"),
        };
        let sent = map(a.handle(Input::MemberJoined(id("c")), ms(1)));
        assert_eq!(sent.robot, id("a"));
        assert_eq!(sent.stations[Station::Manufacturing.index()], Some([9.0, 9.0]));
        assert!(a.handle(Input::MemberJoined(id("c")), ms(2)).is_empty(), "once per join");
        b.handle(Input::Map(sent.clone()), ms(3));
        assert_eq!(b.floor().team_map.station(Station::Storage), Some([2.0, 9.0]));
        assert_eq!(b.floor().team_map.station(Station::Manufacturing), Some([29.5, 29.5]), "the mean of two peers'");
        assert_eq!(b.floor().own_map.stations(), [None; 4], "its own map is its own sightings");
        let echo = MapMsg { robot: id("b"), stations: [Some([7.0, 7.0]), None, None, None], ..sent };
        assert!(b.handle(Input::Map(echo), ms(4)).is_empty());
        assert_eq!(b.floor().team_map.station(Station::Storage), Some([2.0, 9.0]), "its own echo is ignored");
        // A robot that left and comes back is sent the map again.
        a.handle(Input::MemberLeft(id("c")), ms(5));
        map(a.handle(Input::MemberJoined(id("c")), ms(6)));
    }

    #[test]
    fn a_relation_set_votes_from_a_fresh_track_and_says_so() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/relations");
        let set = ModelSet::load(&dir, Backend::Tract, None).unwrap();
        assert_eq!(set.manifest.row, RowLayout::Relations, "the shipped relations set reads relation rows");
        let mut a = engine("a", &set);
        let localised = |tick, seen| DetectionFrame {
            pose: Some(FloorPose { position: [1.0, 2.0], heading: 0.5 }),
            ..frame("a", tick, seen)
        };
        for t in 1..=3 {
            a.handle(Input::Frame(localised(t, true)), ms(100 * t));
        }
        // Tick 4: the worker is not seen, but the track is fresh: announce a vote and vote.
        let out = a.handle(Input::Frame(localised(4, false)), ms(400));
        let e = take_embedding(&out);
        assert!(e.embedding.is_none() && e.worker.is_some() && e.vote.is_some(), "{e:?}");
        assert!(!decisions(&out)[0].steps.is_empty(), "the team still has an answer");
        // Longer than FRESH_TICKS without the worker: the track is stale, no vote.
        let stale = 3 + floor::track::FRESH_TICKS + 1;
        let out = a.handle(Input::Frame(localised(stale, false)), ms(100 * stale));
        let e = take_embedding(&out);
        assert!(e.worker.is_none() && e.vote.is_none());
        // A peer is waited for until its share of the tick comes, with its vote or without.
        let mut b = engine("b", &set);
        b.handle(Input::MemberJoined(id("a")), ms(0));
        let from_a = |tick, votes: bool| {
            let vote =
                votes.then(|| VoteMsg { instance: e.instance, ..vote_msg("a", 1, tick, one_step(Station::Assembly)) });
            Input::Embedding(EmbeddingMsg { tick, vote, ..e.clone() })
        };
        b.handle(from_a(15, false), ms(1500)); // a is now an active member
        let out = b.handle(Input::Frame(DetectionFrame { robot: id("b"), ..localised(20, true) }), ms(1900));
        take_vote(&out);
        assert!(decisions(&out).is_empty(), "b waits for a's share of tick 20");
        let d = decisions(&b.handle(from_a(20, true), ms(1901)))[0].clone();
        assert_eq!(d.voters, vec![id("a"), id("b")]);
        b.handle(from_a(21, false), ms(2000));
        let out = b.handle(Input::Frame(DetectionFrame { robot: id("b"), ..localised(21, true) }), ms(2000));
        assert_eq!(decisions(&out)[0].voters, vec![id("b")], "a abstains from tick 21: b decides at once");
    }

    /// The last row of a collective window at tick `t`, as the GRU reads it.
    fn last_row(e: &Engine, t: u64) -> Vec<f32> {
        let mut x = Vec::new();
        e.window.input(t, TemporalModel::Collective, &mut x);
        x.split_off(x.len() - temporal::FACING_ROW_DIM)
    }

    fn default_set() -> Arc<ModelSet> {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/default");
        let set = ModelSet::load(&dir, Backend::Tract, None).unwrap();
        assert_eq!(set.manifest.row, RowLayout::RelationsFacing);
        set
    }

    fn localised(robot: &str, tick: u64, seen: bool) -> DetectionFrame {
        DetectionFrame { pose: Some(FloorPose { position: [1.0, 2.0], heading: 0.5 }), ..frame(robot, tick, seen) }
    }

    #[test]
    fn the_collective_reads_the_facing_its_peers_saw() {
        let set = default_set();
        let (mut a, mut b) = (engine("a", &set), engine("b", &set));
        b.handle(Input::MemberJoined(id("a")), ms(0));
        // a sees the worker, b does not: b's team track and facing are a's.
        let mut facing = None;
        for t in 1..=4 {
            let e = take_embedding(&a.handle(Input::Frame(localised("a", t, true)), ms(100 * t)));
            facing = e.facing;
            let e = if t == 4 { e } else { EmbeddingMsg { facing: None, ..e } };
            b.handle(Input::Embedding(e), ms(100 * t));
            let out = b.handle(Input::Frame(localised("b", t, false)), ms(100 * t + 1));
            assert!(take_embedding(&out).facing.is_none(), "b's frame shows no worker");
        }
        assert!(facing.is_some(), "a's frame shows the worker's shoulders: a shares where it faces");
        let (three, four) = (last_row(&b, 3), last_row(&b, 4));
        assert_eq!(three[KEYPOINT_VALUES], 1.0, "b holds the team's track from a's estimate");
        assert_eq!(three[temporal::RELATION_ROW_DIM], 0.0, "a sent no facing for tick 3");
        assert_eq!(four[temporal::RELATION_ROW_DIM], 1.0, "b reads the facing a saw in tick 4");
    }

    #[test]
    fn a_facing_set_reads_where_its_own_frame_shows_the_worker_facing() {
        let set = default_set();
        let mut a = engine("a", &set);
        for t in 1..=3 {
            take_vote(&a.handle(Input::Frame(localised("a", t, true)), ms(100 * t)));
        }
        let row = last_row(&a, 3);
        assert_eq!(row[KEYPOINT_VALUES], 1.0, "the worker is tracked");
        assert_eq!(row[temporal::RELATION_ROW_DIM], 1.0, "and its facing known from the frame");
        // Not seen: the fresh track still votes, but nothing shows where it faces.
        take_vote(&a.handle(Input::Frame(localised("a", 4, false)), ms(400)));
        let row = last_row(&a, 4);
        assert_eq!((row[KEYPOINT_VALUES], row[temporal::RELATION_ROW_DIM]), (1.0, 0.0));
    }

    fn relaying(robot: &str, set: &Arc<ModelSet>, relay_after: Option<Duration>) -> Engine {
        let mut e = engine(robot, set);
        e.cfg.relay_after = relay_after;
        e
    }

    /// Three robots that know each other, each having heard from the others.
    fn team_of_three(set: &Arc<ModelSet>, relay_after: Option<Duration>) -> Vec<Engine> {
        let mut team: Vec<Engine> = ["a", "b", "c"].iter().map(|r| relaying(r, set, relay_after)).collect();
        for i in 0..3 {
            for j in (0..3).filter(|&j| j != i) {
                let other = team[j].cfg.robot.clone();
                team[i].handle(Input::MemberJoined(other), ms(0));
            }
        }
        let warm: Vec<Vec<Output>> =
            (0..3).map(|i| team[i].handle(Input::Frame(frame(["a", "b", "c"][i], 1, false)), ms(0))).collect();
        // Each hears the others' embeddings.
        for (i, out) in warm.iter().enumerate() {
            for j in (0..3).filter(|&j| j != i) {
                team[j].handle(Input::Embedding(take_embedding(out)), ms(1));
            }
        }
        team
    }

    /// Tick `t` where all three see the worker and a's share never reaches b directly.
    /// Returns each robot's outputs of the tick so far.
    fn tick_losing_a_vote_to_b(team: &mut [Engine], t: u64) -> Vec<Vec<Output>> {
        let now = ms(100 * t);
        let mut outs: Vec<Vec<Output>> =
            (0..3).map(|i| team[i].handle(Input::Frame(frame(["a", "b", "c"][i], t, true)), now)).collect();
        let shares: Vec<Input> = outs.iter().map(|o| Input::Embedding(take_embedding(o))).collect();
        for i in 0..3 {
            for (j, e) in shares.iter().enumerate().filter(|(j, _)| *j != i && !(*j == 0 && i == 1)) {
                let said = team[i].handle(e.clone(), now + ms(1 + j as u64));
                outs[i].extend(said);
            }
        }
        outs
    }

    #[test]
    fn relayed_ballots_fill_in_a_vote_lost_on_our_link_and_the_digests_agree() {
        let set = models();
        let mut team = team_of_three(&set, Some(ms(40)));
        let outs = tick_losing_a_vote_to_b(&mut team, 2);
        let (da, dc) = (decisions(&outs[0]), decisions(&outs[2]));
        assert_eq!((da.len(), dc.len()), (1, 1), "a and c hold every vote: they decide at once");
        assert!(decisions(&outs[1]).is_empty(), "b waits for a's vote");
        // Deciding, c relays what it holds; b takes a's vote from it and decides the same.
        let relay = outs[2].iter().find(|o| matches!(o, Output::Ballots(_))).expect("c relays as it decides");
        let Output::Ballots(relay) = relay else { unreachable!() };
        assert_eq!(relay.votes.len(), 3);
        let ob = team[1].handle(Input::Ballots(relay.clone()), ms(215));
        let db = decisions(&ob);
        assert_eq!(db.len(), 1);
        assert_eq!(db[0].decided_by, DecidedBy::AllVoted);
        assert_eq!((db[0].digest, &db[0].steps), (da[0].digest, &da[0].steps));
        assert_eq!(dc[0].digest, da[0].digest);
        assert_eq!(team[1].metrics.relayed_ballots_used, 1);
        // A relay for a decided tick is counted, never applied.
        let mut late = relay.clone();
        late.votes.push(VoteMsg { robot: id("d"), ..late.votes[0].clone() });
        let out = team[1].handle(Input::Ballots(late), ms(230));
        assert!(out.is_empty());
        assert_eq!(team[1].metrics.late_relayed_ballots, 1, "d's vote arrived after b decided without it");
        // a's next embedding carries its verdict: the same digest, nothing counted as differing.
        let compared = team[1].metrics.agreement_compared;
        let next = take_embedding(&team[0].handle(Input::Frame(frame("a", 3, false)), ms(300)));
        assert_eq!(next.verdict, Some(Verdict::of(da[0])));
        team[1].handle(Input::Embedding(next), ms(301));
        let m = &team[1].metrics;
        assert_eq!((m.agreement_compared, m.agreement_same, m.ballot_sets_differ), (compared + 1, compared + 1, 0));
    }

    #[test]
    fn without_relays_a_robot_that_decided_on_fewer_ballots_counts_it() {
        let set = models();
        let mut team = team_of_three(&set, None);
        let outs = tick_losing_a_vote_to_b(&mut team, 2);
        assert!(outs.iter().flatten().all(|o| !matches!(o, Output::Ballots(_))), "relaying is off");
        // c's next embedding, carrying its verdict of tick 2 (all three ballots), reaches b
        // while b still waits for a's vote: it is compared once b decides.
        let from_c = take_embedding(&team[2].handle(Input::Frame(frame("c", 3, false)), ms(250)));
        assert_eq!(from_c.verdict.as_ref().map(|v| (v.tick, v.voters.len())), Some((2, 3)));
        let compared = team[1].metrics.agreement_compared;
        team[1].handle(Input::Embedding(from_c), ms(251));
        assert_eq!(team[1].metrics.agreement_compared, compared, "b has not decided tick 2");
        let ob = team[1].handle(Input::Poll, ms(260));
        let db = decisions(&ob);
        assert_eq!((db.len(), db[0].decided_by, db[0].voters.len()), (1, DecidedBy::Deadline, 2));
        let m = &team[1].metrics;
        assert_eq!((m.agreement_compared, m.ballot_sets_differ, m.decided_on_fewer_ballots), (compared + 1, 1, 1));
        // a's verdict comes after b decided: compared at once. a shares it once.
        let da = decisions(&outs[0])[0].clone();
        assert_ne!(da.digest, db[0].digest);
        let from_a = take_embedding(&team[0].handle(Input::Frame(frame("a", 3, false)), ms(300)));
        assert_eq!(from_a.verdict, Some(Verdict::of(&da)));
        team[1].handle(Input::Embedding(from_a), ms(301));
        let m = &team[1].metrics;
        assert_eq!((m.agreement_compared, m.ballot_sets_differ, m.decided_on_fewer_ballots), (compared + 2, 2, 2));
        let again = take_embedding(&team[0].handle(Input::Frame(frame("a", 4, false)), ms(400)));
        assert_eq!(again.verdict, None, "a decided nothing since: nothing to share");
    }

    #[test]
    fn relays_go_out_at_the_relay_time_when_the_tick_is_still_open() {
        let set = models();
        let mut a = relaying("a", &set, Some(ms(40)));
        a.handle(Input::MemberJoined(id("b")), ms(0));
        a.handle(Input::Embedding(share("b", 0, None, Some(one_step(Station::Workstation)), None)), ms(0));
        a.handle(Input::Poll, ms(99)); // tick 0, opened by b's share, is decided
                                       // b is an active member; a's own frame shows the worker at tick 1, b stays silent.
        let out = a.handle(Input::Frame(frame("a", 1, true)), ms(100));
        assert!(out.iter().all(|o| !matches!(o, Output::Ballots(_))));
        assert_eq!(a.next_deadline(), Some(ms(140)), "the relay comes first");
        let out = a.handle(Input::Poll, ms(140));
        let Some(Output::Ballots(b)) = out.first() else { panic!("a relay at 40 ms: {out:?}") };
        assert_eq!((b.tick, b.votes.len(), &b.votes[0].robot), (1, 1, &id("a")));
        // Still without b's vote, a asks for it, the asks spread to the deadline, then decides.
        let asks = a.cfg.ask_rounds;
        for k in 1..=asks {
            let at = ms(140) + ms(20) * k / (asks + 1);
            assert_eq!(a.next_deadline(), Some(at), "ask {k}");
            assert!(a.handle(Input::Poll, at - ms(1)).is_empty(), "not before its time");
            let out = a.handle(Input::Poll, at);
            assert!(matches!(out.as_slice(), [Output::Ballots(b)] if b.votes.len() == 1), "ask {k}: {out:?}");
        }
        assert_eq!(a.metrics.ballot_asks, u64::from(asks));
        assert_eq!(a.next_deadline(), Some(ms(160)), "no rounds left; the deadline is next");
        let out = a.handle(Input::Poll, ms(160));
        assert!(matches!(out.as_slice(), [Output::Decision(_)]), "{out:?}");
    }

    /// Hands every Ballots message among `outs[from]` to robot `to`; returns its outputs.
    fn hand_ballots(team: &mut [Engine], outs: &[Vec<Output>], from: usize, to: usize, now: Duration) -> Vec<Output> {
        let ballots: Vec<Input> = outs[from]
            .iter()
            .filter_map(|o| if let Output::Ballots(b) = o { Some(Input::Ballots(b.clone())) } else { None })
            .collect();
        ballots.into_iter().flat_map(|b| team[to].handle(b, now)).collect()
    }

    fn count_ballots(out: &[Output]) -> usize {
        out.iter().filter(|o| matches!(o, Output::Ballots(_))).count()
    }

    #[test]
    fn a_robot_whose_vote_and_relays_were_lost_asks_and_a_peer_that_decided_answers() {
        let set = models();
        let mut team = team_of_three(&set, Some(ms(40)));
        let outs = tick_losing_a_vote_to_b(&mut team, 2);
        let da = decisions(&outs[0])[0].clone();
        // a's and c's relays, sent as they decided, never reach b either. At the relay
        // time b relays what it holds, its own vote and c's: that shows a's is missing.
        let ob = team[1].handle(Input::Poll, ms(240));
        let Some(Output::Ballots(asked)) = ob.first() else { panic!("b relays at 40 ms: {ob:?}") };
        assert_eq!(asked.votes.iter().map(|v| v.robot.as_str()).collect::<Vec<_>>(), ["b", "c"]);
        // a decided tick 2 already; it answers with every vote it holds, a's among them.
        let answer = team[0].handle(Input::Ballots(asked.clone()), ms(241));
        let Some(Output::Ballots(answer)) = answer.first() else { panic!("a answers: {answer:?}") };
        assert_eq!(answer.votes.len(), 3);
        assert_eq!(team[0].metrics.ballot_answers, 1);
        let db = team[1].handle(Input::Ballots(answer.clone()), ms(242));
        let db = decisions(&db);
        assert_eq!(db.len(), 1);
        assert_eq!((db[0].decided_by, db[0].digest, &db[0].steps), (DecidedBy::AllVoted, da.digest, &da.steps));
        // Answers are bounded: a peer asking again and again gets ask_rounds of them.
        let more: usize =
            (0..5).map(|i| count_ballots(&team[0].handle(Input::Ballots(asked.clone()), ms(243 + i)))).sum();
        assert_eq!(more, (team[0].cfg.ask_rounds - 1) as usize);
        // A relayer that holds nothing the asker lacks does not answer.
        let mut full = answer.clone();
        full.robot = id("b");
        assert!(team[2].handle(Input::Ballots(full), ms(250)).is_empty());
    }

    #[test]
    fn on_links_that_lose_nothing_each_robot_relays_once_and_nobody_asks_or_answers() {
        let set = models();
        let mut team = team_of_three(&set, Some(ms(40)));
        for t in 2..6 {
            let now = ms(100 * t);
            let mut outs: Vec<Vec<Output>> =
                (0..3).map(|i| team[i].handle(Input::Frame(frame(["a", "b", "c"][i], t, true)), now)).collect();
            let shares: Vec<Input> = outs.iter().map(|o| Input::Embedding(take_embedding(o))).collect();
            for i in 0..3 {
                for (j, e) in shares.iter().enumerate().filter(|(j, _)| *j != i) {
                    let said = team[i].handle(e.clone(), now + ms(1 + j as u64));
                    outs[i].extend(said);
                }
            }
            assert!(outs.iter().all(|o| decisions(o).len() == 1 && count_ballots(o) == 1), "tick {t}: {outs:?}");
            for from in 0..3 {
                for to in (0..3).filter(|&to| to != from) {
                    let said = hand_ballots(&mut team, &outs, from, to, now + ms(5));
                    assert!(said.is_empty(), "tick {t}: {to} answers {from}'s relay: {said:?}");
                }
            }
            for e in team.iter_mut() {
                assert!(e.handle(Input::Poll, now + ms(99)).is_empty());
            }
        }
        assert!(team.iter().all(|e| e.metrics.ballot_asks == 0 && e.metrics.ballot_answers == 0));
    }

    #[test]
    fn a_few_members_relay_each_tick_a_different_few_each_time() {
        let set = models();
        let names = ["a", "b", "c", "d", "e", "f"];
        let mut team: Vec<Engine> = names
            .iter()
            .map(|r| {
                let mut e = relaying(r, &set, Some(ms(40)));
                e.cfg.relayers = 2;
                for other in names.iter().filter(|o| *o != r) {
                    e.live.insert(id(other));
                    e.active.insert(id(other));
                }
                e
            })
            .collect();
        let mut relayed = [0; 6];
        for t in 0..600 {
            let relayers: Vec<usize> = (0..6).filter(|&i| team[i].relays(t)).collect();
            assert_eq!(relayers.len(), 2, "tick {t}: every robot counts the same members, so exactly two relay");
            relayers.iter().for_each(|&i| relayed[i] += 1);
        }
        // 200 ticks each if the load is spread evenly (a binomial's sd is 11.5).
        assert!(relayed.iter().all(|n| (150..=250).contains(n)), "{relayed:?}");
        // A member we have not heard from yet is not counted: we relay whenever we did,
        // and on the ticks it ranked ahead of us too.
        let before: Vec<bool> = (0..600).map(|t| team[0].relays(t)).collect();
        team[0].active.remove(&id("f"));
        let after: Vec<bool> = (0..600).map(|t| team[0].relays(t)).collect();
        assert!(before.iter().zip(&after).all(|(b, a)| !b || *a));
        assert!(after.iter().filter(|a| **a).count() > relayed[0]);
        // No more members than relayers: every one relays, every tick.
        team[1].cfg.relayers = 6;
        assert!((0..100).all(|t| team[1].relays(t)));
    }

    #[test]
    fn a_frozen_camera_stops_voting_until_it_changes() {
        let set = models();
        let mut a = engine("a", &set);
        let frozen = frame("a", 1, true);
        for t in 1..=4 {
            let out = a.handle(
                Input::Frame(DetectionFrame { capture_us: DetectionFrame::capture_at_tick(t), ..frozen.clone() }),
                ms(100 * t),
            );
            take_vote(&out);
        }
        assert!(!a.feed_is_stale());
        for t in 5..=7 {
            let out = a.handle(
                Input::Frame(DetectionFrame { capture_us: DetectionFrame::capture_at_tick(t), ..frozen.clone() }),
                ms(100 * t),
            );
            let e = take_embedding(&out);
            assert!(e.embedding.is_none() && e.vote.is_none() && e.visibility == 0 && e.worker.is_none(), "{e:?}");
            assert!(decisions(&out)[0].steps.is_empty());
        }
        assert!(a.feed_is_stale());
        assert_eq!(a.metrics.repeated_frames, 3);
        let out = a.handle(Input::Frame(frame("a", 8, true)), ms(800));
        take_vote(&out);
        assert!(!a.feed_is_stale(), "the feed changed: voting again");
    }

    #[test]
    fn a_peer_whose_embedding_repeats_is_heard_as_abstaining() {
        let set = models();
        let mut b = engine("b", &set);
        b.handle(Input::MemberJoined(id("a")), ms(0));
        let frozen = take_embedding(&engine("a", &set).handle(Input::Frame(frame("a", 1, true)), ms(100)));
        let vote_of_a = |tick| VoteMsg {
            visibility: 9,
            ..vote_msg("a", 1, tick, vec![StepVote { class: Station::Manufacturing, confidence: 1.0 }; 21])
        };
        for t in 1..=7u64 {
            let now = ms(100 * t);
            b.handle(Input::Embedding(EmbeddingMsg { tick: t, vote: Some(vote_of_a(t)), ..frozen.clone() }), now);
            let out = b.handle(Input::Frame(frame("b", t, true)), now);
            let mine = take_vote(&out);
            let d = decisions(&out);
            if t < 5 {
                assert_eq!(d[0].voters, vec![id("a"), id("b")], "tick {t}: a's vote counts");
            } else {
                assert_eq!(d[0].voters, vec![id("b")], "tick {t}: a's feed repeats itself, its vote is left out");
                assert_eq!(d[0].steps[0].class, mine.steps[0].class);
            }
        }
        assert_eq!(b.stale_peers(), vec![id("a")]);
        assert_eq!(b.metrics.stale_peer_messages, 3, "three shares left out");
        let moving = take_embedding(&engine("a", &set).handle(Input::Frame(frame("a", 8, true)), ms(800)));
        b.handle(Input::Embedding(moving), ms(800));
        assert!(b.stale_peers().is_empty(), "a's feed moves again");
    }

    /// Robot a, which does not see the worker, hears b and c vote 1 and d vote 3 for
    /// 150 ticks: a decides from their votes and learns whom to trust.
    fn a_after_d_kept_disagreeing(set: &Arc<ModelSet>) -> Engine {
        let mut a = engine("a", set);
        for p in ["b", "c", "d"] {
            a.handle(Input::MemberJoined(id(p)), ms(0));
        }
        for t in 1..=150u64 {
            let now = ms(100 * t);
            a.handle(Input::Frame(frame("a", t, false)), now);
            for (p, class) in [("b", Station::Workstation), ("c", Station::Workstation), ("d", Station::Manufacturing)]
            {
                let steps = vec![StepVote { class, confidence: 0.8 }; 3];
                a.handle(Input::Embedding(share(p, t, None, Some(steps), None)), now);
            }
            a.handle(Input::Poll, now + ms(99));
        }
        a
    }

    #[test]
    fn a_peer_that_keeps_disagreeing_loses_our_trust_and_leaves_our_fusion() {
        let set = models();
        let a = a_after_d_kept_disagreeing(&set);
        assert_eq!(a.metrics.decisions, 150);
        let trust = a.trust();
        // d, judged by b and c together on ticks 2..=150 (on tick 1 nobody had been
        // heard from yet), lost 2/100 of its trust each time: 0.5 × 0.98^149, floored
        // at 0.1; b and c are not judged (each has one other agreeing, as trusted as
        // itself, and d against it) and keep what a voter starts with
        assert_eq!(trust[&id("d")], 0.1, "{trust:?}");
        assert_eq!((trust[&id("b")], trust[&id("c")]), (UNJUDGED, UNJUDGED), "{trust:?}");
        assert!(!trust.contains_key(&id("a")), "a never voted: not known as a voter");

        // Tick 152: a sees the worker and fuses its peers' latest embeddings (of tick
        // 151) into its row. What d sent changes nothing; what b sent does.
        let vote_with = |b: f32, d: f32| {
            let mut a = a_after_d_kept_disagreeing(&set);
            for (p, x) in [("b", b), ("c", 0.3), ("d", d)] {
                a.handle(Input::Embedding(share(p, 151, Some(x), None, None)), ms(15_100));
            }
            take_vote(&a.handle(Input::Frame(frame("a", 152, true)), ms(15_200)))
        };
        assert_eq!(vote_with(0.3, -0.9).steps, vote_with(0.3, 0.9).steps, "d is not fused");
        assert_ne!(vote_with(-0.9, 0.3).steps, vote_with(0.9, 0.3).steps, "b is");
    }

    #[test]
    fn a_peer_that_places_the_worker_where_nobody_else_does_loses_our_trust() {
        let set = models();
        let mut a = engine("a", &set);
        for p in ["b", "c", "d"] {
            a.handle(Input::MemberJoined(id(p)), ms(0));
        }
        let at = |x: f32| WorkerEstimate { position: [x, 2.0], velocity: [0.0; 2], covariance: [0.04, 0.0, 0.5] };
        for t in 1..=100u64 {
            let now = ms(100 * t);
            a.handle(Input::Frame(frame("a", t, false)), now);
            // b and c place the worker 0.3 m apart, d 4 m away; all three vote alike
            for (p, x) in [("b", 5.0), ("c", 5.3), ("d", 9.0)] {
                let mut e = share(p, t, None, Some(one_step(Station::Assembly)), None);
                e.vote.as_mut().unwrap().worker = Some(at(x));
                a.handle(Input::Embedding(e), now);
            }
            a.handle(Input::Poll, now + ms(99));
        }
        let trust = a.trust();
        // judged on the ballots of ticks 2..=100 (a decided tick 1 alone, before it
        // had heard anyone): every vote agrees (1 − 0.5 × 0.99^99 each), d's worker
        // estimate never does (0.98^99)
        let votes = 1.0 - 0.5 * 0.99f32.powi(99);
        assert!((trust[&id("d")] - votes * 0.98f32.powi(99)).abs() < 1e-3, "{trust:?}");
        assert!((trust[&id("b")] - votes).abs() < 1e-3 && (trust[&id("c")] - votes).abs() < 1e-3, "{trust:?}");
        assert_eq!(a.metrics.decisions, 100);
    }

    /// Robot `a` hears b and c vote `Workstation` at 0.8 every tick and d vote
    /// `Manufacturing` at confidence 1 claiming the fullest view and visibility: a
    /// confident liar. Returns a's decisions at t.
    fn with_a_confident_liar(a: &mut Engine, ticks: std::ops::RangeInclusive<u64>) -> Vec<Option<Station>> {
        let mut decided = Vec::new();
        let me = a.cfg.robot.to_string();
        for t in ticks {
            let now = ms(100 * t);
            a.handle(Input::Frame(frame(&me, t, false)), now);
            for (p, class, confidence) in
                [("b", Station::Workstation, 0.8), ("c", Station::Workstation, 0.8), ("d", Station::Manufacturing, 1.0)]
            {
                let mut e = share(p, t, None, Some(vec![StepVote { class, confidence }; 3]), None);
                if p == "d" {
                    let v = e.vote.as_mut().unwrap();
                    (v.visibility, v.quality) = (10_000, 1.0);
                }
                let out = a.handle(Input::Embedding(e), now + ms(1));
                decided.extend(decisions(&out).iter().map(|d| d.steps.first().map(|s| s.class)));
            }
        }
        decided
    }

    #[test]
    fn a_confident_liar_weighs_what_we_learned_of_it_and_stops_counting() {
        let set = models();
        let mut a = engine("a", &set);
        for p in ["b", "c", "d"] {
            a.handle(Input::MemberJoined(id(p)), ms(0));
        }
        let decided = with_a_confident_liar(&mut a, 1..=120);
        // As trusted as b and c at first, d outweighs both (e(1) = ln 297 = 5.7 against
        // 2 × ln 12 = 5.0), until b and c together judge it wrong a few times.
        let d = a.trust()[&id("d")];
        assert!(d < 0.5, "d disagreed with b and c for 12 s: {d}");
        assert!(a.metrics.votes_set_aside > 0, "d's votes are set aside once its trust falls below 0.5");
        // From its 4th second on (trust below 0.5), d decides nothing for the team.
        assert!(decided[70..].iter().all(|c| *c == Some(Station::Workstation)), "{:?}", &decided[70..]);
        let last = a.last_decision().unwrap();
        assert_eq!(last.voters, vec![id("b"), id("c")], "d is not counted");
        assert!(a.trust()[&id("b")] >= UNJUDGED, "the honest keep their trust: {:?}", a.trust());
    }

    #[test]
    fn robots_that_counted_the_same_ballots_weigh_them_alike() {
        let set = models();
        let (mut a, mut e) = (engine("a", &set), engine("e", &set));
        for x in [&mut a, &mut e] {
            for p in ["b", "c", "d"] {
                x.handle(Input::MemberJoined(id(p)), ms(0));
            }
        }
        let (da, de) = (with_a_confident_liar(&mut a, 1..=90), with_a_confident_liar(&mut e, 1..=90));
        assert_eq!(da, de);
        let (ta, te) = (a.trust(), e.trust());
        assert_eq!(ta, te);
        assert!(ta[&id("d")] < 0.5, "{ta:?}");
        assert_eq!(a.last_decision().unwrap().digest, e.last_decision().unwrap().digest);
    }

    #[test]
    fn a_relayed_vote_counts_only_for_its_origins_live_instance_and_its_own_copy_wins() {
        let set = models();
        let mut a = engine("a", &set);
        for p in ["b", "c"] {
            a.handle(Input::MemberJoined(id(p)), ms(0));
        }
        // b and c speak directly (instance 2); tick 1 is decided.
        a.handle(abstaining("b", 1), ms(100));
        a.handle(abstaining("c", 1), ms(100));
        a.handle(Input::Frame(frame("a", 1, false)), ms(100));
        // Tick 2: c relays a vote of b's earlier run (instance 9) and one of x, no member.
        let old_b = vote_msg("b", 9, 2, one_step(Station::Assembly));
        let stranger = vote_msg("x", 2, 2, one_step(Station::Assembly));
        a.handle(
            Input::Ballots(BallotsMsg { robot: id("c"), instance: 2, tick: 2, votes: vec![old_b, stranger] }),
            ms(201),
        );
        assert_eq!(a.metrics.foreign_votes, 2);
        // c relays b's live vote, changed; then b's own copy arrives, then another.
        let changed = vote_msg("b", 2, 2, one_step(Station::Manufacturing));
        a.handle(Input::Ballots(BallotsMsg { robot: id("c"), instance: 2, tick: 2, votes: vec![changed] }), ms(202));
        assert_eq!(a.metrics.relayed_ballots_used, 1);
        a.handle(Input::Embedding(share("b", 2, None, Some(one_step(Station::Workstation)), None)), ms(203));
        a.handle(Input::Embedding(share("b", 2, None, Some(one_step(Station::Storage)), None)), ms(204));
        a.handle(abstaining("c", 2), ms(205));
        let out = a.handle(Input::Frame(frame("a", 2, false)), ms(206));
        let d = decisions(&out)[0];
        assert_eq!(d.voters, vec![id("b")]);
        assert_eq!(d.steps[0].class, Station::Workstation, "b's own first copy, not the relayed one nor its second");
    }

    #[test]
    fn same_inputs_same_outputs() {
        let set = models();
        let run = || {
            let mut e = engine("a", &set);
            let mut all = Vec::new();
            for t in 0..30 {
                all.extend(e.handle(Input::Frame(frame("a", t, t % 7 != 3)), ms(t * 100)));
            }
            all
        };
        assert_eq!(run(), run());
    }
}
