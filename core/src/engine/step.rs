//! The frame and vote step: our own frame becomes a star graph, an embedding, a window
//! row and, through the GRU, our vote, published in one message with our share of the
//! tick; a peer's share is read as its latest view and its vote for the tick.
//!
//! One message a tick, not two: a robot votes as soon as its own frame is in, reading
//! its peers' latest shares (their worker estimates predicted to this tick, their
//! facings and embeddings, at most [`PEER_VIEW_TICKS`] old) instead of waiting for
//! theirs of this tick. So each robot hears each peer once a tick, not once for the
//! embedding and once more for the vote: half the messages every robot takes in, and
//! one exchange instead of two before a tick can be decided.
//!
//! A feed that repeats itself is set aside ([`crate::stale`]): our own frames showing
//! the worker identically `stale_after` times in a row count as not seeing the worker
//! (no embedding, no track, no vote) until they change; a peer whose embedding repeats
//! as often is heard as abstaining, its votes and floor estimates left out.

use super::{Engine, Output};
use crate::floor::{self, RELATION_DIM};
use crate::graph::OnFloor;
use crate::metrics::Stage;
use crate::temporal::{self, Row, TemporalModel};
use crate::vote;
use spwi_proto::*;
use std::time::{Duration, Instant};

/// How many ticks old a peer's share may be for our vote to read it (0.3 s): its
/// worker estimate is predicted forward to our tick, its embedding and facing read
/// as they are. The latest share of every peer is one tick old when our frame comes
/// in; older ones stand in for a few lost messages.
pub const PEER_VIEW_TICKS: u64 = 3;

/// A peer's latest share, until a newer one arrives: what our vote reads of it.
#[derive(Debug)]
pub(super) struct PeerView {
    tick: u64,
    /// `None` when it does not see the worker (or its feed is stale).
    embedding: Option<Vec<f32>>,
    worker: Option<WorkerEstimate>,
    facing: Option<f32>,
    /// The people it tracks, under the team's ids.
    people: Vec<PersonShare>,
}

/// What our own frame gave for a tick, until it is voted on.
pub(super) struct OwnView {
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

impl Engine {
    pub(super) fn on_frame(&mut self, mut f: DetectionFrame, now: Duration, out: &mut Vec<Output>) {
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
        // Of the people in view, the worker we track comes first (and alone counts).
        self.floor.follow(&mut f);
        let was_stale = self.feed_is_stale();
        let detection = f.worker().map(|h| {
            let b = h.bbox;
            [b.x, b.y, b.w, b.h].into_iter().chain(h.keypoints.iter().copied())
        });
        self.own_feed.see(detection);
        let stale = self.feed_is_stale();
        if stale != was_stale {
            if stale {
                tracing::warn!(
                    tick = tick,
                    repeats = self.cfg.stale_after,
                    "our camera repeats worker detections it showed before: a frozen or looping feed; not voting until it changes"
                );
            } else {
                tracing::info!(tick = tick, "our camera's feed changes again: voting");
            }
        }
        if stale {
            // Nothing of a frozen frame is evidence: not the worker, not the objects.
            self.metrics.repeated_frames += 1;
            f.humans.clear();
            f.objects.clear();
        }
        // The track first: a graph of floor relations places the objects against it.
        let (worker, landmarks) = if stale { (None, Vec::new()) } else { self.floor.observe(&f) };
        // Without a pose nobody is placed on the floor: we name and share nobody.
        let people = if stale || f.pose.is_none() { Vec::new() } else { self.name_people(tick) };
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
        let keypoints = f.worker().map(|h| temporal::normalise_keypoints(&h.keypoints, f.image_size));
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
            people,
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

    pub(super) fn on_embedding(&mut self, mut e: EmbeddingMsg, now: Duration, out: &mut Vec<Output>) {
        let from_peer = e.robot != self.cfg.robot;
        if !self.on_our_clock(&e.robot, e.tick, now) {
            return;
        }
        if from_peer && self.live.contains(&e.robot) {
            // What the peer says directly names its live instance.
            self.instances.insert(e.robot.clone(), e.instance);
        }
        if from_peer {
            self.peer_feeds.entry(e.robot.clone()).or_default().see(e.embedding.as_deref().map(|x| x.iter().copied()));
            if let Some(theirs) = e.verdict.take() {
                if self.live.contains(&e.robot) {
                    self.note_peer_decided(theirs.tick);
                }
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
                PeerView { tick: e.tick, embedding: None, worker: None, facing: None, people: Vec::new() }
            } else {
                PeerView { tick: e.tick, embedding: e.embedding, worker: e.worker, facing: e.facing, people: e.people }
            };
            self.peer_views.insert(e.robot.clone(), view);
        }
        match self.accept_peer(&e.robot, e.instance, e.tick, now) {
            Some(tick) => {
                match e.vote {
                    // A stale peer is heard as one that abstains. Its own copy of its
                    // vote wins over one a peer relayed; of its own copies, the first.
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
            // A peer's vote for a tick we decided joins what we learn from the tick.
            None => match e.vote {
                Some(v) if from_peer && !stale && self.is_live_instance(&e.robot, e.instance) => self.late_vote(v),
                _ => {}
            },
        }
    }

    /// Names the people we track at `t` with the team's ids (`floor/worker_ids.rs`),
    /// from our peers' latest lists, predicted to `t` (a stale peer's list is empty;
    /// trust does not filter them: `worker_ids.rs` says why).
    fn name_people(&mut self, t: u64) -> Vec<PersonShare> {
        let peers: Vec<floor::PeerList> = self
            .peer_views
            .iter()
            .filter(|(_, v)| v.tick <= t && t - v.tick <= PEER_VIEW_TICKS)
            .map(|(robot, v)| {
                let ahead = |p: &PersonShare| PersonShare { estimate: floor::predict(&p.estimate, t - v.tick), ..*p };
                floor::PeerList { robot, people: v.people.iter().map(ahead).collect() }
            })
            .collect();
        let rank = self.live.iter().filter(|r| **r < self.cfg.robot).count();
        let me = floor::Minter { robot: &self.cfg.robot, instance: self.cfg.instance, rank };
        self.floor.name_people(t, me, &peers)
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
        self.floor.observe_worker(t, own.worker.as_ref(), team.track.as_ref());
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
}
