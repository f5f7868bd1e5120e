//! The evaluation's network: N real [`Engine`]s on a virtual clock behind an in-memory
//! bus. What one engine publishes reaches every other live engine after a delay,
//! unless the fault model loses it on the way to that receiver; each engine's
//! deadlines fire as [`Input::Poll`]s at the times it asks for. The decision logic is
//! the daemon's own — nothing of the tick is rebuilt here, only the network is.
//!
//! On request the bus records what each engine was given and what it said, so a test
//! can feed the same inputs to fresh engines and check they say the same: the bus
//! changes which messages arrive and when, never what an engine makes of them.

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use spwi_core::engine::{Engine, Input, Output};
use spwi_proto::{RobotId, Station, StepVote, VoteMsg, MAX_OBJECTS};
use std::collections::BTreeMap;
use std::time::Duration;

/// How the network between the robots behaves.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Net {
    /// Probability that a message is lost on its way to one receiver.
    pub loss: f64,
    /// Every message takes `delay` plus a uniform share of `jitter`.
    pub delay: Duration,
    pub jitter: Duration,
}

/// One engine's life on the bus: every input with its time, and every output.
pub type Log = Vec<(Duration, Input, Vec<Output>)>;

pub struct Bus {
    engines: Vec<Engine>,
    live: Vec<bool>,
    /// Pending deliveries by (time, sequence number): deterministic order.
    queue: BTreeMap<(Duration, u64), (usize, Input)>,
    seq: u64,
    /// The earliest Poll already queued for each engine.
    poll_at: Vec<Option<Duration>>,
    net: Net,
    rng: ChaCha8Rng,
    logs: Option<Vec<Log>>,
    /// Per engine: the station it lies about, if it lies ([`Bus::lie`]).
    lies: Vec<Option<Station>>,
    /// Per engine: how far its clock runs ahead of the bus's (ms; negative: behind).
    clock_offsets: Vec<i64>,
}

impl Bus {
    /// A bus between `engines` (all live, each knowing the others as members); `rng`
    /// draws the losses and delays.
    pub fn new(engines: Vec<Engine>, net: Net, rng: ChaCha8Rng, record: bool) -> Bus {
        let n = engines.len();
        let mut bus = Bus {
            engines,
            live: vec![true; n],
            queue: BTreeMap::new(),
            seq: 0,
            poll_at: vec![None; n],
            net,
            rng,
            logs: record.then(|| vec![Vec::new(); n]),
            lies: vec![None; n],
            clock_offsets: vec![0; n],
        };
        for me in 0..n {
            for other in (0..n).filter(|&o| o != me) {
                let id = bus.engines[other].config().robot.clone();
                bus.deliver(me, Input::MemberJoined(id), Duration::ZERO);
            }
        }
        bus
    }

    pub fn engine(&self, slot: usize) -> &Engine {
        &self.engines[slot]
    }

    pub fn is_live(&self, slot: usize) -> bool {
        self.live[slot]
    }

    /// From now on engine `slot` tells its peers it votes `station` for every step at
    /// confidence 1, with a full view and as many detections as a frame holds, in its
    /// share of every tick and in the ballots it relays (`None`: the truth again). Its
    /// own engine runs on unaware: the lie is in what the others receive.
    pub fn lie(&mut self, slot: usize, station: Option<Station>) {
        self.lies[slot] = station;
    }

    /// Engine `slot`'s clock runs `ms` ahead of everyone else's (negative: behind): it
    /// is handed every input at the time its own clock reads, and its deadlines are
    /// kept on that clock.
    pub fn shift_clock(&mut self, slot: usize, ms: i64) {
        self.clock_offsets[slot] = ms;
    }

    /// Queues `input` for engine `to` at time `at`.
    pub fn deliver(&mut self, to: usize, input: Input, at: Duration) {
        self.queue.insert((at, self.seq), (to, input));
        self.seq += 1;
    }

    /// Engine `slot` stops at `at` (a killed process: its peers see it go at once).
    pub fn leave(&mut self, slot: usize, at: Duration) {
        self.live[slot] = false;
        let id = self.engines[slot].config().robot.clone();
        let others: Vec<usize> = (0..self.engines.len()).filter(|&o| o != slot && self.live[o]).collect();
        for other in others {
            self.deliver(other, Input::MemberLeft(id.clone()), at);
        }
    }

    /// Runs every delivery due before `until`, in time order; `on_output` sees each
    /// output with the engine that made it and when.
    pub fn run_until(&mut self, until: Duration, mut on_output: impl FnMut(usize, Duration, &Output)) {
        while let Some(entry) = self.queue.first_entry() {
            let (at, _) = *entry.key();
            if at >= until {
                break;
            }
            let (to, input) = entry.remove();
            if !self.live[to] {
                continue;
            }
            if matches!(input, Input::Poll) && self.poll_at[to] == Some(at) {
                self.poll_at[to] = None;
            }
            let logged = self.logs.as_ref().map(|_| input.clone());
            let off = self.clock_offsets[to];
            let outputs = self.engines[to].handle(input, shifted(at, off));
            for o in &outputs {
                on_output(to, at, o);
                self.broadcast(to, at, o);
            }
            if let (Some(logs), Some(input)) = (self.logs.as_mut(), logged) {
                logs[to].push((shifted(at, off), input, outputs));
            }
            if let Some(d) = self.engines[to].next_deadline() {
                let d = shifted(d, -off).max(at);
                if self.poll_at[to].is_none_or(|p| d < p) {
                    self.poll_at[to] = Some(d);
                    self.deliver(to, Input::Poll, d);
                }
            }
        }
    }

    fn broadcast(&mut self, from: usize, at: Duration, o: &Output) {
        // What peers read of it (not votes alone, not decisions), as a liar sends it.
        let Some(mut input) = o.to_peer() else { return };
        if let Some(s) = self.lies[from] {
            let horizon = self.engines[from].horizon();
            match &mut input {
                Input::Embedding(e) => {
                    e.vote = Some(lie(&e.robot, e.instance, e.tick, s, horizon));
                    e.visibility = MAX_OBJECTS as u32 + 1;
                }
                Input::Ballots(b) => {
                    b.votes.retain(|v| v.robot != b.robot);
                    b.votes.push(lie(&b.robot, b.instance, b.tick, s, horizon));
                }
                _ => {}
            }
        }
        for to in 0..self.engines.len() {
            if to == from || !self.live[to] {
                continue;
            }
            if self.net.loss > 0.0 && self.rng.gen::<f64>() < self.net.loss {
                continue;
            }
            let jitter = self.net.jitter.mul_f64(self.rng.gen::<f64>());
            self.deliver(to, input.clone(), at + self.net.delay + jitter);
        }
    }

    /// What each engine was given and said (when built with `record`).
    pub fn into_logs(self) -> Option<Vec<Log>> {
        self.logs
    }
}

/// `at` moved by `ms` milliseconds (never before 0).
fn shifted(at: Duration, ms: i64) -> Duration {
    let by = Duration::from_millis(ms.unsigned_abs());
    if ms >= 0 {
        at + by
    } else {
        at.saturating_sub(by)
    }
}

/// A liar's vote: `station` at every step, sure of it, seeing all.
fn lie(robot: &RobotId, instance: u64, tick: u64, station: Station, horizon: usize) -> VoteMsg {
    VoteMsg {
        robot: robot.clone(),
        instance,
        tick,
        steps: vec![StepVote { class: station, confidence: 1.0 }; horizon + 1],
        visibility: MAX_OBJECTS as u32 + 1,
        quality: 1.0,
        worker: None,
        signature: Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use spwi_core::engine::EngineConfig;
    use spwi_core::model::{Backend, ModelSet};
    use spwi_core::settings::TickConfig;
    use spwi_core::temporal::TemporalModel;
    use spwi_proto::{DecidedBy, RobotId};
    use spwi_world::layout::Layout;
    use spwi_world::world::{stream, Scenario, Stream, World};
    use std::sync::Arc;

    fn engine(slot: usize, models: &Arc<ModelSet>) -> Engine {
        let id = RobotId::new(format!("r{slot}")).unwrap();
        let cfg = EngineConfig::new(id, slot as u64 + 1, &TickConfig::default(), &Default::default(), &models.manifest);
        Engine::new(cfg, models.inference(TemporalModel::Collective).unwrap())
    }

    #[test]
    fn engines_on_a_lossy_bus_say_what_they_say_to_the_same_inputs_given_directly() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/fixture");
        let models = ModelSet::load(&dir, Backend::Tract, None).unwrap();
        let net = Net { loss: 0.3, delay: Duration::from_millis(1), jitter: Duration::from_millis(2) };
        let mut bus = Bus::new(vec![engine(0, &models), engine(1, &models)], net, stream(7, Stream::Fault(1)), true);
        let mut world = World::new(Layout::default_layout(), Scenario::Dynamic, 7, 2);
        let ids: Vec<RobotId> = (0..2).map(|s| bus.engine(s).config().robot.clone()).collect();
        let tick = spwi_proto::TICK_PERIOD;
        let mut decisions = [0, 0];
        for _ in 0..80 {
            world.step();
            let now = tick * world.tick as u32;
            for (slot, id) in ids.iter().enumerate() {
                bus.deliver(slot, Input::Frame(world.observe(slot, id)), now);
            }
            bus.run_until(now + tick, |slot, _, o| decisions[slot] += usize::from(matches!(o, Output::Decision(_))));
        }
        assert_eq!(decisions, [80, 80], "every robot decides every tick, whatever is lost");
        let logs = bus.into_logs().expect("recorded");
        let mut by_deadline = 0;
        for (slot, log) in logs.iter().enumerate() {
            let mut fresh = engine(slot, &models);
            for (at, input, said) in log {
                assert_eq!(&fresh.handle(input.clone(), *at), said, "engine {slot} at {at:?} on {input:?}");
                by_deadline += said
                    .iter()
                    .filter(|o| matches!(o, Output::Decision(d) if d.decided_by == DecidedBy::Deadline))
                    .count();
            }
        }
        assert!(by_deadline > 0, "30 % loss made no robot wait for a deadline: the bus lost nothing");
    }
}
