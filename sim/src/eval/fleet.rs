//! The evaluation's fleet: N robot pipelines in one process, ticking in lock step over
//! held-out episodes as fast as the CPU goes. Each robot hears its peers' embeddings and
//! votes as it would over Zenoh — minus any message the fault model loses — and decides
//! with the agent's own consensus over the votes it holds, as the daemon does.

use super::robot::{Predictions, RobotPipeline};
use super::score::{confuse, Confusion, Tally};
use super::EvalOptions;
use crate::world::World;
use anyhow::Result;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use spwi_agent::consensus::{decide, Ballot, Weights};
use spwi_agent::temporal;
use spwi_proto::{DetectionFrame, RobotId, RobotPose};

/// Tallies of one or more episodes.
#[derive(Debug, Clone, Default)]
pub struct Tallies {
    pub gnn: Tally,
    pub ego: Tally,
    pub collective: Tally,
    pub consensus: Tally,
    /// The team decision on every tick, a tick without one (nobody saw the worker)
    /// counting as wrong: what the fleet as a whole gets right.
    pub team_all_ticks: Tally,
    pub cvm: Tally,
    pub cnn1d: Tally,
    /// Per robot slot: gnn, ego, collective.
    pub per_robot: Vec<[Tally; 3]>,
    pub confusion_ego: Confusion,
    pub confusion_collective: Confusion,
    /// Ticks on which some robot decided something, and how many of them every live
    /// robot decided the same class for t.
    pub decided_ticks: u64,
    pub agreed_ticks: u64,
    /// Ticks evaluated.
    pub ticks: u64,
    /// Robot frames processed.
    pub frames: u64,
}

impl Tallies {
    pub fn merge(&mut self, o: &Tallies) {
        for (a, b) in [
            (&mut self.gnn, &o.gnn),
            (&mut self.ego, &o.ego),
            (&mut self.collective, &o.collective),
            (&mut self.consensus, &o.consensus),
            (&mut self.team_all_ticks, &o.team_all_ticks),
            (&mut self.cvm, &o.cvm),
            (&mut self.cnn1d, &o.cnn1d),
        ] {
            a.merge(b);
        }
        if self.per_robot.len() < o.per_robot.len() {
            self.per_robot.resize(o.per_robot.len(), Default::default());
        }
        for (a, b) in self.per_robot.iter_mut().zip(&o.per_robot) {
            for (x, y) in a.iter_mut().zip(b) {
                x.merge(y);
            }
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
        self.agreed_ticks += o.agreed_ticks;
        self.ticks += o.ticks;
        self.frames += o.frames;
    }
}

/// What one tick left for scoring once the future truth is known.
struct TickRecord {
    per_robot: Vec<(usize, Predictions)>,
    /// Each live robot's team decision (class per step; empty if no votes).
    decisions: Vec<Vec<u8>>,
}

/// Runs episode `e` of the evaluation and returns its tallies.
pub fn episode(o: &EvalOptions, episode_seed: u64) -> Result<Tallies> {
    let n = o.robots;
    let ticks = o.ticks as usize;
    let horizon = o.models.manifest.horizon;
    let mut world = World::new(o.layout.clone(), o.scenario, episode_seed, n);
    let spots: Vec<[f32; 2]> = {
        let mut s: Vec<_> = o.layout.stations.iter().map(|s| (s.id, s.work_spot)).collect();
        s.sort_by_key(|(id, _)| *id);
        s.into_iter().map(|(_, p)| p).collect()
    };
    let mut robots: Vec<RobotPipeline> = (0..n)
        .map(|slot| RobotPipeline::new(RobotId::new(format!("r{slot}"))?, slot, &o.models))
        .collect::<Result<_>>()?;
    let ids: Vec<RobotId> = robots.iter().map(|r| r.id.clone()).collect();
    let mut live = vec![true; n];
    let mut loss_rng = ChaCha8Rng::seed_from_u64(episode_seed ^ 0x5eed_1055);
    let mut stuck: Vec<Option<DetectionFrame>> = vec![None; n];
    let weights = Weights { alpha: o.models.manifest.consensus.alpha, beta: o.models.manifest.consensus.beta };
    let mut intents = Vec::with_capacity(ticks + horizon);
    let mut records = Vec::with_capacity(ticks);
    let mut tallies = Tallies { per_robot: vec![Default::default(); n], ..Default::default() };

    for t in 0..(ticks + horizon) as u64 {
        world.step();
        intents.push(world.worker.goal);
        if t >= ticks as u64 {
            continue;
        }
        if o.faults.dropouts > 0 && t == ticks as u64 / 2 {
            let first_leaver = n.saturating_sub(o.faults.dropouts);
            for (slot, alive) in live.iter_mut().enumerate().skip(first_leaver) {
                *alive = false;
                world.set_present(slot, false);
            }
        }
        // 1. every live robot perceives
        let mut perceptions = Vec::with_capacity(n);
        for (slot, r) in robots.iter_mut().enumerate() {
            if !live[slot] {
                continue;
            }
            let mut frame = world.observe(slot, &r.id);
            if slot < o.faults.faulty {
                frame = stuck_camera(&mut stuck[slot], frame);
            }
            let pose = RobotPose {
                robot: r.id.clone(),
                position: world.robots[slot].pose.position,
                heading: world.robots[slot].pose.heading,
            };
            perceptions.push((slot, r.perceive(&frame, &pose, &o.layout.camera)?));
            tallies.frames += 1;
        }
        // 2. embeddings cross the network (some lost), each robot predicts and votes
        let embeddings: Vec<(usize, Option<Vec<f32>>)> =
            perceptions.iter().map(|(s, p)| (*s, p.embedding.clone())).collect();
        let mut per_robot = Vec::with_capacity(perceptions.len());
        for (slot, p) in perceptions {
            let heard: Vec<&[f32]> = embeddings
                .iter()
                .filter(|(s, e)| *s != slot && e.is_some() && !lost(&mut loss_rng, o.faults.loss))
                .filter_map(|(_, e)| e.as_deref())
                .collect();
            let peers_mean = temporal::mean(heard);
            let visibility = p.visibility;
            per_robot.push((slot, visibility, robots[slot].predict(t, p, peers_mean, &spots)?));
        }
        // 3. votes cross the network; every robot decides over the votes it holds
        let mut decisions = Vec::with_capacity(per_robot.len());
        for &(me, _, _) in &per_robot {
            let mut ballots: Vec<Ballot<'_>> = per_robot
                .iter()
                .filter(|(s, _, _)| *s == me || !lost(&mut loss_rng, o.faults.loss))
                .filter_map(|(s, visibility, pr)| {
                    pr.vote.as_deref().map(|steps| Ballot { robot: &ids[*s], visibility: *visibility, steps })
                })
                .collect();
            decisions.push(decide(&mut ballots, weights).iter().map(|s| s.class).collect::<Vec<u8>>());
        }
        let per_robot = per_robot.into_iter().map(|(s, _, p)| (s, p)).collect();
        records.push(TickRecord { per_robot, decisions });
    }

    // Score now that the truth of every horizon is known.
    for (t, rec) in records.iter().enumerate() {
        let truth = &intents[t..=t + horizon];
        for (slot, p) in &rec.per_robot {
            let pr = &mut tallies.per_robot[*slot];
            if let Some(g) = p.gnn {
                tallies.gnn.add(&[g], truth);
                pr[0].add(&[g], truth);
            }
            if let Some(e) = &p.ego {
                tallies.ego.add(e, truth);
                pr[1].add(e, truth);
                confuse(&mut tallies.confusion_ego, e[0], truth[0]);
            }
            if let Some(c) = &p.collective {
                tallies.collective.add(c, truth);
                pr[2].add(c, truth);
                confuse(&mut tallies.confusion_collective, c[0], truth[0]);
            }
            if let Some(c) = &p.cnn1d {
                tallies.cnn1d.add(c, truth);
            }
            if let Some(c) = &p.cvm {
                tallies.cvm.add(c, truth);
            }
        }
        tallies.ticks += 1;
        for d in &rec.decisions {
            let undecided = vec![u8::MAX; horizon + 1]; // matches no class
            tallies.team_all_ticks.add(if d.is_empty() { &undecided } else { d }, truth);
        }
        let decided: Vec<&Vec<u8>> = rec.decisions.iter().filter(|d| !d.is_empty()).collect();
        if !decided.is_empty() {
            tallies.decided_ticks += 1;
            let all_same = decided.len() == rec.decisions.len() && decided.iter().all(|d| d[0] == decided[0][0]);
            tallies.agreed_ticks += u64::from(all_same);
            for d in decided {
                tallies.consensus.add(d, truth);
            }
        }
    }
    Ok(tallies)
}

fn lost(rng: &mut ChaCha8Rng, p: f64) -> bool {
    p > 0.0 && rng.gen::<f64>() < p
}

/// A stuck camera: once it has seen the worker, it keeps returning that frame (with the
/// current tick) — confident, plausible and wrong.
fn stuck_camera(stuck: &mut Option<DetectionFrame>, frame: DetectionFrame) -> DetectionFrame {
    match stuck {
        Some(s) => DetectionFrame { tick: frame.tick, ..s.clone() },
        None => {
            if frame.human.is_some() {
                *stuck = Some(frame.clone());
            }
            frame
        }
    }
}
