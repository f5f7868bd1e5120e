//! The evaluation's fleet: one held-out episode, N real engines (the daemon's
//! `Engine`, with the daemon's default timing) on a virtual clock behind the in-memory
//! [`Bus`] and its fault model, as fast as the CPU goes. Each tick the world delivers
//! every live robot's frame; the engines exchange their shares of the tick (embedding
//! and vote in one message), relayed ballots and maps over the bus, and what they
//! publish — each robot's vote and team decision — is scored.
//! The ego-GRU and the baselines run as [`Observers`] beside them.

use super::bus::{Bus, Net};
use super::identity::{IdentityTally, IdentityTracker};
use super::observers::{Observers, Predictions};
use super::planner::Planner;
use super::score::{confuse, Confusion, Tally};
use super::EvalOptions;
use crate::faulty_camera::{LoopingCamera, StuckCamera};
use crate::measures::Agreement;
use anyhow::Result;
use spwi_core::engine::{Engine, EngineConfig, Input, Output};
use spwi_core::floor::FloorPlan;
use spwi_core::temporal::TemporalModel;
use spwi_core::vote;
use spwi_proto::{PersonShare, RobotId, Station, WorkerPhase, NUM_CLASSES};
use spwi_world::geometry::{norm, sub};
use spwi_world::layout::Layout;
use spwi_world::worker::route_bends;
use spwi_world::world::{stream, Stream, World};
use std::time::Duration;

/// The tick period, as the daemon lives it.
const TICK: Duration = spwi_proto::TICK_PERIOD;
/// Ticks into an episode after which `consensus_settled` scores (10 s).
pub const SETTLED_TICKS: usize = 100;

/// One robot's own models, tallied.
#[derive(Debug, Clone, Copy, Default)]
pub struct RobotTallies {
    pub gnn: Tally,
    pub ego: Tally,
    pub collective: Tally,
}

/// Tallies of one or more episodes.
#[derive(Debug, Clone, Default)]
pub struct Tallies {
    pub gnn: Tally,
    pub ego: Tally,
    pub collective: Tally,
    /// The collective GRU of the robots whose camera works (every robot without faults).
    pub healthy_collective: Tally,
    pub consensus: Tally,
    /// The same from [`SETTLED_TICKS`] into the episode on: what a fault that starts
    /// with the episode costs once the team has had 10 s to see it.
    pub consensus_settled: Tally,
    /// The team decision on every tick, a tick without one (nobody saw the worker)
    /// counting as wrong: what the fleet as a whole gets right.
    pub team_all_ticks: Tally,
    pub cvm: Tally,
    /// The constant-velocity model on the stations the robot's team mapped.
    pub cvm_mapped: Tally,
    /// The planning yardstick on the team's track, with the true work spots and with
    /// the team's map.
    pub planner: Tally,
    pub planner_mapped: Tally,
    /// The collective GRU on the ticks where the goal at t is missing from the robot's
    /// team map (no relation row describes it).
    pub collective_goal_unmapped: Tally,
    pub cnn1d: Tally,
    /// The collective and the team's decision on the same robot-ticks: those on which
    /// the robot's collective predicted and it decided a class (each figure above
    /// counts its own ticks).
    pub paired_collective: Tally,
    pub paired_consensus: Tally,
    /// How well the robots' team maps place the stations, over the scored robot-ticks.
    pub map: MapQuality,
    /// The same, on the ticks where the worker heads to a station of a close pair.
    pub close_pair: ClosePair,
    /// The same, by where the tick falls in the worker's cycle ([`Phase`]).
    pub by_phase: [PhaseTallies; Phase::ALL.len()],
    /// The long walks ([`Phase::Later`]) by the straight line to their goal ([`Route`]).
    pub long_walks: [PhaseTallies; Route::ALL.len()],
    /// Per robot slot, its own models.
    pub per_robot: Vec<RobotTallies>,
    /// Per robot slot: the sum over its votes of the trust the other robots held of it,
    /// and the number of its votes.
    pub vote_trust: Vec<(f64, u64)>,
    pub confusion_ego: Confusion,
    pub confusion_collective: Confusion,
    /// Ticks on which some robot decided something.
    pub decided_ticks: u64,
    /// Ticks on which some robot voted and none decided a class.
    pub voted_undecided_ticks: u64,
    /// Robot-ticks left without a class by the lone-voter rule, and because every voter
    /// was doubted (the engines' own counts).
    pub lone_stranger_robot_ticks: u64,
    pub doubted_only_robot_ticks: u64,
    /// Of those, the ticks on which every live robot decided the same class for t.
    pub agreement: Agreement,
    /// Whom the robots named which team worker, against the truth.
    pub identity: IdentityTally,
    /// Ticks evaluated.
    pub ticks: u64,
    /// Robot frames processed.
    pub frames: u64,
    /// Messages the robots published, and their encoded bytes.
    pub messages: u64,
    pub bytes: u64,
}

impl Tallies {
    pub fn merge(&mut self, o: &Tallies) {
        for (a, b) in [
            (&mut self.gnn, &o.gnn),
            (&mut self.ego, &o.ego),
            (&mut self.collective, &o.collective),
            (&mut self.healthy_collective, &o.healthy_collective),
            (&mut self.consensus, &o.consensus),
            (&mut self.consensus_settled, &o.consensus_settled),
            (&mut self.team_all_ticks, &o.team_all_ticks),
            (&mut self.cvm, &o.cvm),
            (&mut self.cvm_mapped, &o.cvm_mapped),
            (&mut self.planner, &o.planner),
            (&mut self.planner_mapped, &o.planner_mapped),
            (&mut self.collective_goal_unmapped, &o.collective_goal_unmapped),
            (&mut self.cnn1d, &o.cnn1d),
            (&mut self.paired_collective, &o.paired_collective),
            (&mut self.paired_consensus, &o.paired_consensus),
            (&mut self.close_pair.ego, &o.close_pair.ego),
            (&mut self.close_pair.collective, &o.close_pair.collective),
            (&mut self.close_pair.consensus, &o.close_pair.consensus),
            (&mut self.close_pair.team_all_ticks, &o.close_pair.team_all_ticks),
            (&mut self.close_pair.cvm, &o.close_pair.cvm),
            (&mut self.close_pair.farther_collective, &o.close_pair.farther_collective),
            (&mut self.close_pair.farther_cvm, &o.close_pair.farther_cvm),
        ] {
            a.merge(b);
        }
        self.map.merge(&o.map);
        for (a, b) in self.by_phase.iter_mut().zip(&o.by_phase).chain(self.long_walks.iter_mut().zip(&o.long_walks)) {
            a.merge(b);
        }
        if self.per_robot.len() < o.per_robot.len() {
            self.per_robot.resize(o.per_robot.len(), Default::default());
        }
        for (a, b) in self.per_robot.iter_mut().zip(&o.per_robot) {
            a.gnn.merge(&b.gnn);
            a.ego.merge(&b.ego);
            a.collective.merge(&b.collective);
        }
        if self.vote_trust.len() < o.vote_trust.len() {
            self.vote_trust.resize(o.vote_trust.len(), (0.0, 0));
        }
        for (a, b) in self.vote_trust.iter_mut().zip(&o.vote_trust) {
            a.0 += b.0;
            a.1 += b.1;
        }
        for (a, b) in
            [(&mut self.confusion_ego, &o.confusion_ego), (&mut self.confusion_collective, &o.confusion_collective)]
        {
            for (ra, rb) in a.iter_mut().zip(b) {
                for (x, y) in ra.iter_mut().zip(rb) {
                    *x += y;
                }
            }
        }
        self.decided_ticks += o.decided_ticks;
        self.voted_undecided_ticks += o.voted_undecided_ticks;
        self.lone_stranger_robot_ticks += o.lone_stranger_robot_ticks;
        self.doubted_only_robot_ticks += o.doubted_only_robot_ticks;
        self.agreement += o.agreement;
        self.identity.merge(&o.identity);
        self.ticks += o.ticks;
        self.frames += o.frames;
        self.messages += o.messages;
        self.bytes += o.bytes;
    }
}

/// Per station: on how many robot-ticks the team map held it, and how far from its
/// true work spot (sum and count of placements more than [`MapQuality::FAR_M`] off).
#[derive(Debug, Clone, Copy, Default)]
pub struct MapQuality {
    pub robot_ticks: u64,
    pub mapped: [u64; NUM_CLASSES],
    pub error_sum: [f64; NUM_CLASSES],
    pub far: [u64; NUM_CLASSES],
}

impl MapQuality {
    /// A station placed farther than this from its work spot is misplaced: about the
    /// spread of its objects round the spot.
    pub const FAR_M: f32 = 2.0;

    fn add(&mut self, errors: &[Option<f32>; NUM_CLASSES]) {
        self.robot_ticks += 1;
        for (k, e) in errors.iter().enumerate() {
            if let Some(e) = e {
                self.mapped[k] += 1;
                self.error_sum[k] += f64::from(*e);
                self.far[k] += u64::from(*e > Self::FAR_M);
            }
        }
    }

    fn merge(&mut self, o: &MapQuality) {
        self.robot_ticks += o.robot_ticks;
        for k in 0..NUM_CLASSES {
            self.mapped[k] += o.mapped[k];
            self.error_sum[k] += o.error_sum[k];
            self.far[k] += o.far[k];
        }
    }
}

/// Tallies on the ticks where the true intent at t is a station of a close pair
/// (work spots within 3.5 m): the hard case.
#[derive(Debug, Clone, Default)]
pub struct ClosePair {
    pub ego: Tally,
    pub collective: Tally,
    pub consensus: Tally,
    pub team_all_ticks: Tally,
    pub cvm: Tally,
    /// The collective and the CVM on the ticks where the goal is the farther station
    /// of its pair from where the worker is (its walk passes the other one first):
    /// their recall of that station.
    pub farther_collective: Tally,
    pub farther_cvm: Tally,
}

/// Where a tick falls in the worker's cycle: at work, or walking so long after it
/// committed to its goal (the label changes in that very tick; a spawn is a commitment
/// too). The intent of a walk shows in the motion only as the motion builds up, so the
/// first second of a goal is where any predictor must be weakest.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    AtWork,
    FirstHalfSecond,
    SecondHalfSecond,
    OneToTwoSeconds,
    Later,
}

impl Phase {
    pub const ALL: [Phase; 5] =
        [Phase::AtWork, Phase::FirstHalfSecond, Phase::SecondHalfSecond, Phase::OneToTwoSeconds, Phase::Later];

    /// The phase of a tick `ticks_on_goal` ticks (10 Hz) after the goal was committed to.
    pub fn of(at_work: bool, ticks_on_goal: u64) -> Phase {
        match (at_work, ticks_on_goal) {
            (true, _) => Phase::AtWork,
            (false, 0..5) => Phase::FirstHalfSecond,
            (false, 5..10) => Phase::SecondHalfSecond,
            (false, 10..20) => Phase::OneToTwoSeconds,
            (false, _) => Phase::Later,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Phase::AtWork => "at work",
            Phase::FirstHalfSecond => "walking, first 0.5 s of the goal",
            Phase::SecondHalfSecond => "walking, 0.5–1 s",
            Phase::OneToTwoSeconds => "walking, 1–2 s",
            Phase::Later => "walking, after 2 s",
        }
    }
}

/// What the straight line from the worker to its goal crosses on a walk. The CVM and
/// the relation rows see the stations along straight lines, so a walk that passes
/// another station on its way, or bends around an obstacle, looks like a walk
/// elsewhere to both; splitting the long walks' ticks so says which misleads them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Route {
    Straight,
    PassesStation,
    Bends,
}

/// Another station's work spot within this of the straight line to the goal, before
/// the goal, lies on the way (m).
const ON_THE_WAY_M: f32 = 1.5;

impl Route {
    pub const ALL: [Route; 3] = [Route::Straight, Route::PassesStation, Route::Bends];

    /// The route of a worker at `at` heading for `goal`, `spots` the true work spots,
    /// `bends` whether its straight line crosses an obstacle (that one counts first).
    pub fn of(at: [f32; 2], goal: Station, spots: &[[f32; 2]; NUM_CLASSES], bends: bool) -> Route {
        if bends {
            return Route::Bends;
        }
        let d = sub(spots[goal.index()], at);
        let len = norm(d);
        let on_the_way = |s: [f32; 2]| {
            let r = sub(s, at);
            let along = (r[0] * d[0] + r[1] * d[1]) / len;
            let aside = (r[0] * d[1] - r[1] * d[0]).abs() / len;
            along > 0.0 && along < len && aside <= ON_THE_WAY_M
        };
        let passes = len > 1e-3 && Station::ALL.iter().any(|&k| k != goal && on_the_way(spots[k.index()]));
        if passes {
            Route::PassesStation
        } else {
            Route::Straight
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Route::Straight => "straight, nothing on the way",
            Route::PassesStation => "passing another station",
            Route::Bends => "bending around an obstacle",
        }
    }
}

/// Ticks of one kind (a [`Phase`], or a [`Route`] of the long walks), and how the
/// collective, the ego, the CVM and the planner did on them.
#[derive(Debug, Clone, Copy, Default)]
pub struct PhaseTallies {
    pub ticks: u64,
    pub collective: Tally,
    pub ego: Tally,
    pub cvm: Tally,
    /// The planning yardstick on the true work spots, and on the team's map.
    pub planner: Tally,
    pub planner_mapped: Tally,
}

impl PhaseTallies {
    fn merge(&mut self, o: &PhaseTallies) {
        self.ticks += o.ticks;
        self.collective.merge(&o.collective);
        self.ego.merge(&o.ego);
        self.cvm.merge(&o.cvm);
        self.planner.merge(&o.planner);
        self.planner_mapped.merge(&o.planner_mapped);
    }

    /// One robot's predictions of a tick of this kind.
    fn add(&mut self, p: &Predictions, truth: &[Station]) {
        for (tally, predicted) in [
            (&mut self.ego, &p.ego),
            (&mut self.collective, &p.collective),
            (&mut self.cvm, &p.cvm),
            (&mut self.planner, &p.planner),
            (&mut self.planner_mapped, &p.planner_mapped),
        ] {
            if let Some(predicted) = predicted {
                tally.add(predicted, truth);
            }
        }
    }
}

/// Whether the worker at `at` heads for the farther station of a close pair.
fn heads_for_farther(at: [f32; 2], goal: Station, pairs: &[(Station, Station)], spots: &[[f32; 2]]) -> bool {
    let d = |k: Station| spwi_world::geometry::dist(at, spots[k.index()]);
    pairs.iter().any(|&(a, b)| (goal == a && d(a) > d(b)) || (goal == b && d(b) > d(a)))
}

/// What one tick left for scoring once the future truth is known.
struct TickRecord {
    per_robot: Vec<(usize, Predictions)>,
    /// Each live robot's team decision (class per step; empty if no votes or none
    /// made), by slot.
    decisions: Vec<(usize, Vec<Station>)>,
    /// Some robot voted for the tick.
    voted: bool,
    /// The worker heads for the farther station of a close pair.
    farther: bool,
    phase: Phase,
    /// On a long walk ([`Phase::Later`]), what the straight line to the goal crosses.
    route: Option<Route>,
}

/// The daemon's own engine, with the evaluation's `[tick]` settings, for robot `slot`.
/// With `--floor-plan`, the floor's plan (one for the whole fleet, as a factory has).
fn engine(slot: usize, o: &EvalOptions, layout: &Layout, plan: Option<&FloorPlan>) -> Result<Engine> {
    let id = RobotId::new(format!("r{slot}"))?;
    let camera = crate::calibration::of(&layout.camera);
    let mut cfg = EngineConfig::new(id, slot as u64 + 1, &o.tick, &camera, &o.models.manifest);
    cfg.floor_plan = plan.cloned();
    Ok(Engine::new(cfg, o.models.inference(TemporalModel::Collective)?))
}

/// The network of an evaluation: loopback-like (0.5 ms ± 0.5 ms) unless `--delay`.
pub fn net(f: &super::Faults) -> Net {
    let delay = Duration::from_secs_f64(f.delay_ms.max(0.5) / 1e3);
    Net { loss: f.loss, delay, jitter: delay }
}

/// Runs one episode of the evaluation on `layout` and returns its tallies.
pub fn episode(o: &EvalOptions, layout: &Layout, episode_seed: u64) -> Result<Tallies> {
    let n = o.robots;
    let ticks = o.ticks as usize;
    let horizon = o.models.manifest.horizon;
    let mut world = World::with_workers(layout.clone(), o.scenario, episode_seed, n, o.workers);
    let spots = Station::ALL.map(|k| layout.station(k).work_spot);
    let pairs = layout.close_pairs();
    let in_close_pair = Station::ALL.map(|k| pairs.iter().any(|&(a, b)| a == k || b == k));
    let plan = o.plan_error_m.map(|e| crate::floor_plan::of_layout(layout, e, episode_seed));
    let mut engines = (0..n).map(|slot| engine(slot, o, layout, plan.as_ref())).collect::<Result<Vec<_>>>()?;
    if o.warm_map_ticks > 0 {
        let seed = crate::team_floor::warm_up_seed(episode_seed);
        let warm = crate::team_floor::TeamFloor::warmed(layout, o.scenario, seed, n, o.warm_map_ticks)?;
        for (engine, (own, team)) in engines.iter_mut().zip(warm.maps()) {
            engine.adopt_maps(own.clone(), team.clone());
        }
    }
    let ids: Vec<RobotId> = engines.iter().map(|e| e.config().robot.clone()).collect();
    let mut observers = (0..n)
        .map(|_| {
            let planner = Planner::on_floor(layout, o.scenario.obstacles());
            Observers::new(&o.models, crate::calibration::of(&layout.camera), o.cnn1d, planner)
        })
        .collect::<Result<Vec<_>>>()?;
    let mut bus = Bus::new(engines, net(&o.faults), stream(episode_seed, Stream::Fault(1)), false);
    if o.faults.clock_offset_ms != 0 {
        bus.shift_clock(n - 1, o.faults.clock_offset_ms);
    }
    let mut stuck: Vec<StuckCamera> = (0..n).map(|_| StuckCamera::default()).collect();
    let mut looping: Vec<LoopingCamera> = (0..n).map(|_| LoopingCamera::default()).collect();
    let mut intents: Vec<Station> = Vec::with_capacity(ticks + horizon);
    let mut ticks_on_goal = 0u64;
    let mut records = Vec::with_capacity(ticks);
    let mut identity = IdentityTracker::new(n, world.workers.len());
    let mut tallies =
        Tallies { per_robot: vec![Default::default(); n], vote_trust: vec![(0.0, 0); n], ..Default::default() };

    // A fleet already running when the episode starts: one unscored tick in which every
    // robot hears from every other (a cold fleet's first tick is decided by each robot
    // alone, since peers count from their first message).
    for (slot, id) in ids.iter().enumerate() {
        bus.deliver(slot, Input::Frame(world.observe(slot, id)), Duration::ZERO);
    }
    bus.run_until(TICK, |_, _, _| {});

    for step in 0..ticks + horizon {
        world.step();
        ticks_on_goal = if intents.last().is_some_and(|&g| g != world.worker().goal) { 0 } else { ticks_on_goal + 1 };
        intents.push(world.worker().goal);
        if step >= ticks {
            continue;
        }
        let tick = world.tick;
        let now = TICK * tick as u32;
        // Liars vote a station the worker is not heading to, every tick.
        for slot in o.faults.liar_slots() {
            let wrong = Station::ALL[(world.worker().goal.index() + 1) % NUM_CLASSES];
            bus.lie(slot, Some(wrong));
        }
        if o.faults.dropouts > 0 && step == ticks / 2 {
            for slot in n.saturating_sub(o.faults.dropouts)..n {
                bus.leave(slot, now);
                world.set_in_fleet(slot, false);
            }
        }
        // Every live robot's camera delivers its frame to its engine.
        for (slot, obs) in observers.iter_mut().enumerate() {
            if !bus.is_live(slot) {
                continue;
            }
            let mut frame = world.observe(slot, &ids[slot]);
            if slot < o.faults.faulty {
                frame = stuck[slot].pass(frame);
            } else if slot < o.faults.lying() {
                frame = looping[slot].pass(frame);
            }
            if o.faults.pose_error_slot() == Some(slot) {
                // The localiser puts the camera pose_error_m off, always the same way.
                if let Some(p) = frame.pose.as_mut() {
                    let d = o.faults.pose_error_m as f32 * std::f32::consts::FRAC_1_SQRT_2;
                    p.position = [p.position[0] + d, p.position[1] + d];
                }
            }
            // The person the robot's engine will follow comes first, for the
            // observers as for the engine (which does the same again, to no effect).
            bus.engine(slot).floor().follow(&mut frame);
            obs.see(&frame);
            bus.deliver(slot, Input::Frame(frame), now);
            tallies.frames += 1;
        }
        // The tick plays out on the bus; the engines' own outputs are what is scored.
        let mut embeddings: Vec<Option<Vec<f32>>> = vec![None; n];
        let mut votes: Vec<Option<Vec<Station>>> = vec![None; n];
        let mut decided: Vec<Option<Vec<Station>>> = vec![None; n];
        let (mut messages, mut bytes) = (0, 0);
        bus.run_until(now + TICK, |slot, _, out| {
            messages += 1;
            bytes += out.to_wire().1.len();
            match out {
                Output::Embedding(e) if e.tick == tick => embeddings[slot] = e.embedding.clone(),
                Output::Vote(v) if v.tick == tick => votes[slot] = Some(v.steps.iter().map(|s| s.class).collect()),
                Output::Decision(d) if d.tick == tick => {
                    decided[slot] = Some(d.steps.iter().map(|s| s.class).collect())
                }
                _ => {}
            }
        });
        // What a vote weighed: the trust the other live robots hold of its voter.
        for slot in (0..n).filter(|&s| votes[s].is_some()) {
            let held: Vec<f64> = (0..n)
                .filter(|&j| j != slot && bus.is_live(j))
                .map(|j| {
                    f64::from(bus.engine(j).trust().get(&ids[slot]).copied().unwrap_or(spwi_core::trust::UNJUDGED))
                })
                .collect();
            if !held.is_empty() {
                tallies.vote_trust[slot].0 += held.iter().sum::<f64>() / held.len() as f64;
                tallies.vote_trust[slot].1 += 1;
            }
        }
        tallies.messages += messages;
        tallies.bytes += bytes as u64;
        // Whom each robot named which team worker this tick.
        let named: Vec<Option<&[PersonShare]>> = (0..n)
            .map(|slot| {
                let (at, people) = bus.engine(slot).floor().worker_ids().shared();
                (bus.is_live(slot) && at == tick).then_some(people)
            })
            .collect();
        let truly: Vec<[f32; 2]> = world.workers.iter().map(|w| w.position).collect();
        identity.tick(&truly, &named);
        let voted = votes.iter().any(Option::is_some);
        let mut per_robot = Vec::with_capacity(n);
        let mut decisions = Vec::with_capacity(n);
        for (slot, obs) in observers.iter_mut().enumerate() {
            if !bus.is_live(slot) {
                continue;
            }
            // Every model is scored on the ticks its robot sees the worker (the paper's
            // protocol, the same ticks for all); a vote from the track alone counts in
            // the team's decision only.
            let seen = embeddings[slot].is_some();
            let mut p = obs.predict(tick, embeddings[slot].take(), bus.engine(slot).floor(), &spots)?;
            p.gnn = bus.engine(slot).spatial_logits(tick).map(|l| vote::top_station(&l));
            p.collective = votes[slot].take().filter(|_| seen);
            per_robot.push((slot, p));
            // A liar's own decisions are not the team's to score.
            if !o.faults.liar_slots().contains(&slot) {
                decisions.push((slot, decided[slot].take().unwrap_or_default()));
            }
        }
        let farther = heads_for_farther(world.worker().position, world.worker().goal, &pairs, &spots);
        let phase = Phase::of(world.worker().phase == WorkerPhase::Stationary, ticks_on_goal);
        let route = (phase == Phase::Later).then(|| {
            let (at, goal) = (world.worker().position, world.worker().goal);
            Route::of(at, goal, &spots, route_bends(at, spots[goal.index()], layout, o.scenario.obstacles()))
        });
        records.push(TickRecord { per_robot, decisions, voted, farther, phase, route });
    }

    // Score now that the truth of every horizon is known.
    for (t, rec) in records.iter().enumerate() {
        let truth = &intents[t..=t + horizon];
        let close = in_close_pair[truth[0].index()];
        let phase = &mut tallies.by_phase[rec.phase as usize];
        phase.ticks += 1;
        let mut long_walk = rec.route.map(|r| &mut tallies.long_walks[r as usize]);
        if let Some(l) = long_walk.as_deref_mut() {
            l.ticks += 1;
        }
        for (slot, p) in &rec.per_robot {
            phase.add(p, truth);
            if let Some(l) = long_walk.as_deref_mut() {
                l.add(p, truth);
            }
            let pr = &mut tallies.per_robot[*slot];
            if let Some(g) = p.gnn {
                tallies.gnn.add(&[g], truth);
                pr.gnn.add(&[g], truth);
            }
            if let Some(e) = &p.ego {
                tallies.ego.add(e, truth);
                if close {
                    tallies.close_pair.ego.add(e, truth);
                }
                pr.ego.add(e, truth);
                confuse(&mut tallies.confusion_ego, e[0], truth[0]);
            }
            if let Some(c) = &p.collective {
                tallies.collective.add(c, truth);
                if *slot >= o.faults.untrue() {
                    tallies.healthy_collective.add(c, truth);
                }
                if close {
                    tallies.close_pair.collective.add(c, truth);
                }
                if rec.farther {
                    tallies.close_pair.farther_collective.add(c, truth);
                }
                tallies.map.add(&p.map_error);
                if !p.mapped(truth[0]) {
                    tallies.collective_goal_unmapped.add(c, truth);
                }
                pr.collective.add(c, truth);
                confuse(&mut tallies.confusion_collective, c[0], truth[0]);
            }
            if let Some(c) = &p.cnn1d {
                tallies.cnn1d.add(c, truth);
            }
            for (tally, predicted) in [
                (&mut tallies.cvm_mapped, &p.cvm_mapped),
                (&mut tallies.planner, &p.planner),
                (&mut tallies.planner_mapped, &p.planner_mapped),
            ] {
                if let Some(c) = predicted {
                    tally.add(c, truth);
                }
            }
            if let Some(c) = &p.cvm {
                tallies.cvm.add(c, truth);
                if close {
                    tallies.close_pair.cvm.add(c, truth);
                }
                if rec.farther {
                    tallies.close_pair.farther_cvm.add(c, truth);
                }
            }
        }
        // The robot-ticks with both a collective's prediction and a team decision.
        for (slot, p) in &rec.per_robot {
            let decision = rec.decisions.iter().find(|(s, _)| s == slot).map(|(_, d)| d);
            if let (Some(c), Some(d)) = (&p.collective, decision.filter(|d| !d.is_empty())) {
                tallies.paired_collective.add(c, truth);
                tallies.paired_consensus.add(d, truth);
            }
        }
        tallies.ticks += 1;
        for (_, d) in &rec.decisions {
            // A robot that decided nothing for the tick is wrong at every step.
            tallies.team_all_ticks.add_or_miss(d, truth);
            if close {
                tallies.close_pair.team_all_ticks.add_or_miss(d, truth);
            }
        }
        let decided: Vec<&Vec<Station>> = rec.decisions.iter().map(|(_, d)| d).filter(|d| !d.is_empty()).collect();
        tallies.voted_undecided_ticks += u64::from(decided.is_empty() && rec.voted);
        if !decided.is_empty() {
            tallies.decided_ticks += 1;
            // A live robot that decided nothing disagrees.
            tallies.agreement.tick(rec.decisions.iter().map(|(_, d)| d.first()));
            for d in decided {
                tallies.consensus.add(d, truth);
                if t >= SETTLED_TICKS {
                    tallies.consensus_settled.add(d, truth);
                }
                if close {
                    tallies.close_pair.consensus.add(d, truth);
                }
            }
        }
    }
    tallies.identity = identity.tally;
    for slot in (0..n).filter(|&s| bus.is_live(s)) {
        let m = bus.engine(slot).metrics();
        tallies.lone_stranger_robot_ticks += m.lone_stranger_ticks;
        tallies.doubted_only_robot_ticks += m.doubted_only_ticks;
    }
    Ok(tallies)
}

#[cfg(test)]
mod tests {
    use super::{heads_for_farther, Phase, Route};
    use spwi_proto::Station::*;

    #[test]
    fn a_tick_s_phase_is_at_work_or_how_long_the_goal_has_held() {
        assert_eq!(Phase::of(true, 0), Phase::AtWork, "arrived: at work whatever the goal's age");
        assert_eq!(Phase::of(true, 300), Phase::AtWork);
        assert_eq!(Phase::of(false, 0), Phase::FirstHalfSecond, "the tick of the commitment");
        assert_eq!(Phase::of(false, 4), Phase::FirstHalfSecond);
        assert_eq!(Phase::of(false, 5), Phase::SecondHalfSecond);
        assert_eq!(Phase::of(false, 10), Phase::OneToTwoSeconds);
        assert_eq!(Phase::of(false, 19), Phase::OneToTwoSeconds);
        assert_eq!(Phase::of(false, 20), Phase::Later);
        assert!(Phase::ALL.iter().enumerate().all(|(k, &p)| p as usize == k), "ALL indexes the tallies");
    }

    #[test]
    fn a_walk_passes_a_station_that_lies_on_its_straight_line_before_the_goal() {
        let spots = [[0.0, 0.0], [10.0, 1.0], [20.0, 0.0], [5.0, 8.0]];
        assert_eq!(Route::of([0.0, 0.0], Assembly, &spots, false), Route::PassesStation, "workstation on the way");
        assert_eq!(Route::of([0.0, 0.0], Workstation, &spots, false), Route::Straight, "assembly lies beyond the goal");
        assert_eq!(Route::of([0.0, 0.0], Manufacturing, &spots, false), Route::Straight, "nothing near the line");
        assert_eq!(Route::of([30.0, 0.0], Storage, &spots, false), Route::PassesStation, "from the other side");
        assert_eq!(Route::of([0.0, 0.0], Manufacturing, &spots, true), Route::Bends, "an obstacle counts first");
        assert_eq!(Route::of([0.0, 0.0], Storage, &spots, false), Route::Straight, "at the goal");
        assert!(Route::ALL.iter().enumerate().all(|(k, &r)| r as usize == k), "ALL indexes the tallies");
    }

    #[test]
    fn the_farther_station_of_a_pair_is_the_one_the_walk_reaches_second() {
        let spots = [[0.0, 0.0], [10.0, 0.0], [12.5, 0.0], [5.0, 9.0]];
        let pairs = [(Workstation, Assembly)];
        assert!(heads_for_farther([2.0, 0.0], Assembly, &pairs, &spots), "past 1 to reach 2");
        assert!(!heads_for_farther([2.0, 0.0], Workstation, &pairs, &spots), "1 is the nearer");
        assert!(heads_for_farther([20.0, 0.0], Workstation, &pairs, &spots), "from the other side, 1 is farther");
        assert!(!heads_for_farther([2.0, 0.0], Manufacturing, &pairs, &spots), "3 is in no close pair");
    }
}
