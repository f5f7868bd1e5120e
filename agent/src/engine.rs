//! The per-robot decision engine: every input of a tick in, every message to publish
//! out. No I/O and no clock of its own — `now` comes with each input — so the daemon,
//! the replay of a recording and the tests drive the very same code, and the same
//! inputs give the same outputs bit for bit.
//!
//! One tick, as this robot lives it:
//!
//! ```text
//! frame ─► graph ─► GCN ─► Embedding out  (with the floor track and landmarks; says
//!                                          whether this robot will vote for the tick)
//!            peers' embeddings for the tick arrive
//! all active peers' embeddings in, or embedding_wait passed
//!       ─► window row (own ‖ mean(peers) ‖ keypoints) ─► GRU ─► Vote out
//!            peers' votes arrive
//! a vote from every active member that said it votes, or decision_deadline passed
//!       ─► consensus ─► Decision out
//! ```
//!
//! Deadlines run from the first thing this robot heard about the tick (its own frame
//! or a peer's message), so a robot whose own frame is lost still decides from its
//! peers' votes when the deadline passes. Membership decides whom to wait for: live
//! members (liveliness) that have spoken at least once ("counted from the first vote"),
//! so a peer that joins never stalls a tick, and one that leaves is not waited for.

use crate::consensus::{self, Ballot, Weights};
use crate::floor::{self, CameraCalibration, FloorView, RELATION_DIM};
use crate::graph::GraphBuilder;
use crate::metrics::{Metrics, Stage};
use crate::model::Inference;
use crate::temporal::{self, Row, RowLayout, TemporalModel, Window};
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
    /// How long to wait for peers' embeddings before running the GRU without them.
    pub embedding_wait: Duration,
    /// How long after a tick starts to decide with the votes at hand.
    pub decision_deadline: Duration,
    pub weights: Weights,
    /// Most ticks open at once; the oldest is dropped beyond.
    pub max_open_ticks: usize,
    /// The camera, for back-projecting detections onto the floor.
    #[serde(default)]
    pub camera: CameraCalibration,
}

impl EngineConfig {
    /// The rules a daemon runs with: timing from its `[tick]` config, consensus weights
    /// from there or else from the model set's manifest. The daemon and the evaluation
    /// both build their engines here, so the evaluation judges what robots run.
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
            embedding_wait: Duration::from_millis(tick.embedding_wait_ms),
            decision_deadline: Duration::from_millis(tick.decision_deadline_ms),
            weights: Weights {
                alpha: tick.alpha.unwrap_or(manifest.consensus.alpha),
                beta: tick.beta.unwrap_or(manifest.consensus.beta),
            },
            max_open_ticks: tick.max_open_ticks,
            camera: camera.clone(),
        }
    }
}

/// Everything that can happen to a robot.
#[derive(Debug, Clone, PartialEq)]
pub enum Input {
    Frame(DetectionFrame),
    Embedding(EmbeddingMsg),
    Vote(VoteMsg),
    /// A peer decision, compared with ours to measure agreement.
    Decision(DecisionMsg),
    MemberJoined(RobotId),
    MemberLeft(RobotId),
    /// Time passed: deadlines may have expired.
    Poll,
}

/// What the robot publishes.
#[derive(Debug, Clone, PartialEq)]
pub enum Output {
    Embedding(EmbeddingMsg),
    Vote(VoteMsg),
    Decision(DecisionMsg),
}

/// Our own part of a tick.
#[derive(Debug)]
struct Own {
    arrived: Duration,
    visibility: u32,
    /// `None` when the worker was not seen (or the GCN failed). Both move into the
    /// window at the vote step.
    embedding: Option<Vec<f32>>,
    keypoints: Option<Vec<f32>>,
    /// Our own track's estimate of the worker for this tick.
    worker: Option<WorkerEstimate>,
    /// We vote for this tick: we see the worker, or (relation rows) we track it.
    will_vote: bool,
    /// The vote step ran: the window row is in and, if the worker was seen, we voted.
    vote_step_done: bool,
}

#[derive(Debug)]
struct Tick {
    started: Duration,
    own: Option<Own>,
    /// Peers' embedding messages: `None` inside means "does not see the worker".
    embeddings: BTreeMap<RobotId, Option<Vec<f32>>>,
    /// Peers' estimates of the worker for the tick.
    workers: BTreeMap<RobotId, WorkerEstimate>,
    /// Peers that said they will not vote for the tick.
    abstaining: BTreeSet<RobotId>,
    votes: BTreeMap<RobotId, VoteMsg>,
    /// Peers' decisions that arrived before ours: their class at t.
    peer_decisions: Vec<Option<u8>>,
}

impl Tick {
    fn new(started: Duration) -> Self {
        Tick {
            started,
            own: None,
            embeddings: BTreeMap::new(),
            workers: BTreeMap::new(),
            abstaining: BTreeSet::new(),
            votes: BTreeMap::new(),
            peer_decisions: Vec::new(),
        }
    }
}

/// How many decided ticks are remembered to recognise late messages.
const DECIDED_MEMORY: u64 = 1024;

pub struct Engine {
    cfg: EngineConfig,
    inference: Inference,
    graph: GraphBuilder,
    window: Window,
    row_layout: RowLayout,
    floor: FloorView,
    scratch: Vec<f32>,
    temperature: f32,
    /// Live peers per liveliness (never ourselves).
    live: BTreeSet<RobotId>,
    /// Peers heard from at least once.
    active: BTreeSet<RobotId>,
    open: BTreeMap<u64, Tick>,
    decided: BTreeMap<u64, Vec<TeamStep>>,
    pub metrics: Metrics,
    /// Instance ids of other daemons seen using our robot id.
    pub duplicates: BTreeSet<u64>,
    pub last_decision: Option<DecisionMsg>,
    /// The GCN's spatial-only logits for our latest frame that showed the worker.
    last_spatial: Option<(u64, [f32; NUM_CLASSES])>,
}

impl Engine {
    pub fn new(cfg: EngineConfig, inference: Inference) -> Self {
        let m = &inference.set().manifest;
        let graph = GraphBuilder::new(m.max_nodes, m.edge_weight);
        let window = Window::with_frames(m.window, m.frames(), m.row);
        let row_layout = m.row;
        let temperature = inference.set().temperature(cfg.temporal);
        let floor = FloorView::new(cfg.camera.clone());
        Engine {
            cfg,
            inference,
            graph,
            window,
            row_layout,
            floor,
            scratch: Vec::new(),
            temperature,
            live: BTreeSet::new(),
            active: BTreeSet::new(),
            open: BTreeMap::new(),
            decided: BTreeMap::new(),
            metrics: Metrics::default(),
            duplicates: BTreeSet::new(),
            last_decision: None,
            last_spatial: None,
        }
    }

    pub fn config(&self) -> &EngineConfig {
        &self.cfg
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

    /// The spatial-only prediction (GCN logits) for our frame of `tick`, if it showed
    /// the worker: what the evaluation scores as the GNN alone.
    pub fn spatial_logits(&self, tick: u64) -> Option<[f32; NUM_CLASSES]> {
        self.last_spatial.filter(|(t, _)| *t == tick).map(|(_, l)| l)
    }

    /// The earliest time at which [`Input::Poll`] could change something.
    pub fn next_deadline(&self) -> Option<Duration> {
        self.open
            .values()
            .map(|t| match &t.own {
                Some(o) if !o.vote_step_done => t.started + self.cfg.embedding_wait.min(self.cfg.decision_deadline),
                _ => t.started + self.cfg.decision_deadline,
            })
            .min()
    }

    /// Handles one input at time `now` and returns what to publish, in order.
    pub fn handle(&mut self, input: Input, now: Duration) -> Vec<Output> {
        let mut out = Vec::new();
        match input {
            Input::Frame(f) => self.on_frame(f, now, &mut out),
            Input::Embedding(e) => {
                if e.robot != self.cfg.robot {
                    // Where a peer saw station objects stays true after its tick.
                    self.floor.add_peer_landmarks(&e.landmarks);
                }
                if let Some(tick) = self.accept_peer(&e.robot, e.instance, e.tick, now) {
                    if let Some(w) = e.worker {
                        tick.workers.insert(e.robot.clone(), w);
                    }
                    if !e.votes {
                        tick.abstaining.insert(e.robot.clone());
                    }
                    tick.embeddings.insert(e.robot.clone(), e.embedding);
                    self.advance(e.tick, now, &mut out);
                }
            }
            Input::Vote(v) => {
                let t = v.tick;
                if let Some(tick) = self.accept_peer(&v.robot.clone(), v.instance, t, now) {
                    tick.votes.insert(v.robot.clone(), v);
                    self.advance(t, now, &mut out);
                }
            }
            Input::Decision(d) => self.compare(&d),
            Input::MemberJoined(r) => {
                if r != self.cfg.robot {
                    self.live.insert(r);
                }
            }
            Input::MemberLeft(r) => {
                self.live.remove(&r);
                self.active.remove(&r);
                self.advance_all(now, &mut out);
            }
            Input::Poll => self.advance_all(now, &mut out),
        }
        out
    }

    fn on_frame(&mut self, f: DetectionFrame, now: Duration, out: &mut Vec<Output>) {
        if f.robot != self.cfg.robot {
            return; // the daemon only subscribes to our own detections
        }
        if self.is_decided(f.tick) || self.open.get(&f.tick).is_some_and(|t| t.own.is_some()) {
            self.metrics.stale_frames += 1;
            return;
        }
        self.metrics.frames += 1;
        let t0 = Instant::now();
        let embedding = match self.graph.build(&f) {
            None => None,
            Some(g) => {
                self.metrics.frames_with_worker += 1;
                let t1 = Instant::now();
                self.metrics.observe(Stage::Graph, t1 - t0);
                let r = self.inference.gcn(g);
                self.metrics.observe(Stage::Gcn, t1.elapsed());
                match r {
                    Ok(o) => {
                        self.last_spatial = Some((f.tick, o.logits));
                        Some(o.embedding)
                    }
                    Err(e) => {
                        self.metrics.model_errors += 1;
                        tracing::error!(tick = f.tick, "GCN failed, not voting this tick: {e:#}");
                        None
                    }
                }
            }
        };
        let keypoints = f.human.as_ref().map(|h| temporal::normalise_keypoints(&h.keypoints, f.image_size));
        let visibility = f.visibility();
        let (worker, landmarks) = self.floor.observe(&f);
        // A set that reads relations votes from the worker's track while it is fresh:
        // the team keeps an answer through a few frames in which nobody sees the worker.
        let will_vote = embedding.is_some() || (self.row_layout == RowLayout::Relations && worker.is_some());
        out.push(Output::Embedding(EmbeddingMsg {
            robot: self.cfg.robot.clone(),
            instance: self.cfg.instance,
            tick: f.tick,
            embedding: embedding.clone(),
            visibility,
            votes: will_vote,
            worker,
            landmarks,
        }));
        let tick = self.open_tick(f.tick, now);
        tick.own =
            Some(Own { arrived: now, visibility, embedding, keypoints, worker, will_vote, vote_step_done: false });
        self.advance(f.tick, now, out);
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
        if self.is_decided(tick) {
            self.metrics.late_messages += 1;
            return None;
        }
        Some(self.open_tick(tick, now))
    }

    fn is_decided(&self, tick: u64) -> bool {
        self.decided.contains_key(&tick) || self.decided.keys().next().is_some_and(|&oldest| tick < oldest)
    }

    fn open_tick(&mut self, tick: u64, now: Duration) -> &mut Tick {
        if !self.open.contains_key(&tick) && self.open.len() >= self.cfg.max_open_ticks {
            if let Some((old, _)) = self.open.pop_first() {
                self.metrics.evicted_ticks += 1;
                tracing::warn!(tick = old, "dropping an undecided tick: too many open");
            }
        }
        self.open.entry(tick).or_insert_with(|| Tick::new(now))
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
        let expected_peers: Vec<RobotId> = self.live.intersection(&self.active).cloned().collect();

        // Phase 1: our vote, once the peers' embeddings are in (or waited for long enough).
        if tick.own.as_ref().is_some_and(|o| !o.vote_step_done) {
            let all_in = expected_peers.iter().all(|r| tick.embeddings.contains_key(r));
            if all_in || decision_due || now >= tick.started + self.cfg.embedding_wait {
                if let Some(v) = self.vote(t) {
                    self.open.get_mut(&t).expect("open").votes.insert(self.cfg.robot.clone(), v.clone());
                    out.push(Output::Vote(v));
                }
            }
        }

        // Phase 2: the decision, once every active member that said it votes voted.
        let tick = &self.open[&t];
        let Some(own) = &tick.own else {
            if decision_due {
                self.decide(t, DecidedBy::Deadline, now, out);
            }
            return;
        };
        if !own.vote_step_done {
            return;
        }
        let all_voted =
            expected_peers.iter().filter(|r| !tick.abstaining.contains(*r)).all(|r| tick.votes.contains_key(r));
        if all_voted {
            self.decide(t, DecidedBy::AllVoted, now, out);
        } else if decision_due {
            self.decide(t, DecidedBy::Deadline, now, out);
        }
    }

    /// Adds tick `t`'s window row and, if we vote for the tick, runs the GRU and votes.
    fn vote(&mut self, t: u64) -> Option<VoteMsg> {
        let tick = self.open.get_mut(&t).expect("open");
        let own = tick.own.as_mut().expect("own frame");
        own.vote_step_done = true;
        let peers_mean = temporal::mean(tick.embeddings.values().flatten().map(Vec::as_slice));
        let will_vote = own.will_vote;
        let relations = (self.row_layout == RowLayout::Relations).then(|| {
            let mut r = vec![0.0; RELATION_DIM];
            match self.cfg.temporal {
                TemporalModel::Ego => floor::relations(own.worker.as_ref(), &self.floor.own_map.stations(), &mut r),
                TemporalModel::Collective => {
                    let team = floor::fuse(own.worker.iter().chain(tick.workers.values()));
                    floor::relations(team.as_ref(), &self.floor.team_map.stations(), &mut r)
                }
            }
            r
        });
        // The row is the last use of our embedding and keypoints: move them, don't copy.
        let row = Row { own: own.embedding.take(), peers_mean, keypoints: own.keypoints.take(), relations };
        let visibility = own.visibility;
        self.window.insert(t, row);
        if !will_vote {
            return None;
        }
        self.window.input(t, self.cfg.temporal, &mut self.scratch);
        let t0 = Instant::now();
        let logits = self.inference.gru(&self.scratch);
        self.metrics.observe(Stage::Gru, t0.elapsed());
        match logits {
            Ok(l) => Some(VoteMsg {
                robot: self.cfg.robot.clone(),
                instance: self.cfg.instance,
                tick: t,
                steps: vote::vote(&l, self.temperature),
                visibility,
            }),
            Err(e) => {
                self.metrics.model_errors += 1;
                tracing::error!(tick = t, "GRU failed, not voting this tick: {e:#}");
                None
            }
        }
    }

    fn decide(&mut self, t: u64, by: DecidedBy, now: Duration, out: &mut Vec<Output>) {
        let tick = self.open.remove(&t).expect("open");
        let t0 = Instant::now();
        let mut ballots: Vec<Ballot<'_>> = tick
            .votes
            .values()
            .map(|v| Ballot { robot: &v.robot, visibility: v.visibility, steps: &v.steps })
            .collect();
        let steps = consensus::decide(&mut ballots, self.cfg.weights);
        let voters: Vec<RobotId> = ballots.iter().map(|b| b.robot.clone()).collect();
        self.metrics.observe(Stage::Consensus, t0.elapsed());
        if let Some(own) = &tick.own {
            self.metrics.observe(Stage::FrameToDecision, now.saturating_sub(own.arrived));
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
        };
        let ours = steps.first().map(|s| s.class);
        for theirs in &tick.peer_decisions {
            self.record_agreement(ours, *theirs);
        }
        self.decided.insert(t, steps);
        while self.decided.len() as u64 > DECIDED_MEMORY {
            self.decided.pop_first();
        }
        self.last_decision = Some(d.clone());
        out.push(Output::Decision(d));
    }

    fn compare(&mut self, d: &DecisionMsg) {
        if d.robot == self.cfg.robot {
            if d.instance != self.cfg.instance {
                self.metrics.duplicate_id_messages += 1;
                self.duplicates.insert(d.instance);
            }
            return;
        }
        let theirs = d.steps.first().map(|s| s.class);
        if let Some(ours) = self.decided.get(&d.tick) {
            let ours = ours.first().map(|s| s.class);
            self.record_agreement(ours, theirs);
        } else if let Some(tick) = self.open.get_mut(&d.tick) {
            tick.peer_decisions.push(theirs);
        }
    }

    fn record_agreement(&mut self, ours: Option<u8>, theirs: Option<u8>) {
        self.metrics.agreement_compared += 1;
        self.metrics.agreement_same += u64::from(ours == theirs);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{Backend, ModelSet};
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
            embedding_wait: Duration::from_millis(30),
            decision_deadline: Duration::from_millis(60),
            weights: Weights { alpha: 0.5, beta: 0.5 },
            max_open_ticks: 8,
            camera: CameraCalibration::default(),
        };
        Engine::new(cfg, set.inference(TemporalModel::Collective).unwrap())
    }

    /// A frame whose features depend on (robot, tick) so robots disagree sometimes.
    pub(crate) fn frame(robot: &str, tick: u64, seen: bool) -> DetectionFrame {
        let seed = tick as f32 * 0.37 + robot.len() as f32;
        let feat = |k: f32| (0..FEATURE_DIM).map(|i| (i as f32 * 0.1 + k + seed).sin()).collect::<Vec<_>>();
        DetectionFrame {
            robot: id(robot),
            tick,
            pose: None,
            image_size: [640.0, 480.0],
            human: seen.then(|| HumanDetection {
                bbox: BBox { x: 300.0, y: 200.0, w: 40.0, h: 120.0 },
                keypoints: (0..KEYPOINT_VALUES).map(|i| 300.0 + i as f32).collect(),
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

    fn take_vote(out: &[Output]) -> VoteMsg {
        out.iter().find_map(|o| if let Output::Vote(v) = o { Some(v.clone()) } else { None }).expect("a vote")
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
        assert_eq!(take_embedding(&out).embedding, None);
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

        // Tick 2: now both are active; nobody decides before hearing the other.
        let out_a = a.handle(Input::Embedding(take_embedding(&warm_b)), ms(1)); // late for tick 1
        assert!(out_a.is_empty());
        assert_eq!(a.metrics.late_messages, 1);
        b.handle(Input::Embedding(take_embedding(&warm_a)), ms(1));
        let oa = a.handle(Input::Frame(frame("a", 2, true)), ms(100));
        let ob = b.handle(Input::Frame(frame("b", 2, true)), ms(100));
        assert!(oa.iter().all(|o| matches!(o, Output::Embedding(_))), "a must wait for b's embedding");
        let oa2 = a.handle(Input::Embedding(take_embedding(&ob)), ms(101));
        let ob2 = b.handle(Input::Embedding(take_embedding(&oa)), ms(101));
        let (va, vb) = (take_vote(&oa2), take_vote(&ob2));
        assert!(decisions(&oa2).is_empty(), "a must wait for b's vote");
        let da = a.handle(Input::Vote(vb), ms(102));
        let db = b.handle(Input::Vote(va), ms(102));
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
        a.handle(Input::Frame(frame("a", 1, true)), ms(0));
        a.handle(
            Input::Embedding(EmbeddingMsg {
                robot: id("b"),
                instance: 9,
                tick: 1,
                embedding: None,
                visibility: 0,
                votes: false,
                worker: None,
                landmarks: vec![],
            }),
            ms(1),
        );
        let out = a.handle(Input::Frame(frame("a", 2, true)), ms(100));
        assert!(decisions(&out).is_empty());
        assert_eq!(a.next_deadline(), Some(ms(130)));
        let out = a.handle(Input::Poll, ms(130));
        take_vote(&out);
        assert!(decisions(&out).is_empty());
        assert_eq!(a.next_deadline(), Some(ms(160)));
        let out = a.handle(Input::Poll, ms(160));
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
            a.handle(
                Input::Embedding(EmbeddingMsg {
                    robot: id(r),
                    instance: 9,
                    tick: 1,
                    embedding: None,
                    visibility: 0,
                    votes: false,
                    worker: None,
                    landmarks: vec![],
                }),
                ms(0),
            );
        }
        a.handle(Input::Frame(frame("a", 2, true)), ms(100));
        // c does not see the worker: its vote is not expected.
        a.handle(
            Input::Embedding(EmbeddingMsg {
                robot: id("c"),
                instance: 9,
                tick: 2,
                embedding: None,
                visibility: 1,
                votes: false,
                worker: None,
                landmarks: vec![],
            }),
            ms(101),
        );
        let out = a.handle(Input::MemberLeft(id("b")), ms(102));
        take_vote(&out);
        let d = decisions(&out);
        assert_eq!(d[0].decided_by, DecidedBy::AllVoted);
        assert_eq!(d[0].live_members, 2);
    }

    #[test]
    fn a_second_daemon_with_our_id_is_detected() {
        let set = models();
        let mut a = engine("a", &set);
        a.handle(Input::Vote(VoteMsg { robot: id("a"), instance: 1, tick: 5, steps: vec![], visibility: 1 }), ms(0));
        assert!(a.duplicates.is_empty(), "our own echo is not a clash");
        a.handle(Input::Vote(VoteMsg { robot: id("a"), instance: 2, tick: 5, steps: vec![], visibility: 1 }), ms(0));
        assert_eq!(a.duplicates.iter().copied().collect::<Vec<_>>(), vec![2]);
        assert_eq!(a.metrics.duplicate_id_messages, 1);
    }

    #[test]
    fn duplicate_frames_are_stale_and_open_ticks_are_bounded() {
        let set = models();
        let mut a = engine("a", &set);
        a.handle(Input::Frame(frame("a", 1, true)), ms(0));
        assert!(a.handle(Input::Frame(frame("a", 1, true)), ms(1)).is_empty());
        assert_eq!(a.metrics.stale_frames, 1);
        for t in 100..120 {
            a.handle(
                Input::Vote(VoteMsg {
                    robot: id("z"),
                    instance: 3,
                    tick: t,
                    steps: vec![StepVote { class: 0, confidence: 1.0 }],
                    visibility: 1,
                }),
                ms(2),
            );
        }
        assert_eq!(a.open.len(), 8);
        assert_eq!(a.metrics.evicted_ticks, 12);
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
        assert!(e.landmarks.iter().all(|l| l.station == 0));
        assert!(a.floor().own_map.station(0).is_some(), "seen three times: on the map");
        // A frame without a pose shares nothing on the floor, and a peer's landmarks
        // reach the team map only.
        let out = a.handle(Input::Frame(frame("a", 4, true)), ms(400));
        assert!(take_embedding(&out).landmarks.is_empty());
        let peer = EmbeddingMsg {
            robot: id("b"),
            instance: 2,
            tick: 4,
            embedding: None,
            visibility: 1,
            votes: false,
            worker: None,
            landmarks: vec![Landmark { station: 3, position: [9.0, 9.0], sigma: 0.3 }; 3],
        };
        a.handle(Input::Embedding(peer), ms(401));
        assert!(a.floor().team_map.station(3).is_some() && a.floor().own_map.station(3).is_none());
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
