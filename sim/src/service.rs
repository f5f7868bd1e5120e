//! `spwi-sim world`: the simulated world as a Zenoh service. It watches the fleet's
//! liveliness tokens; each robot that joins takes the next free robot slot of the
//! layout (its spawn pose and patrol), one that leaves frees it. Every tick of the
//! fleet's clock (10 Hz, the host's wall clock) it publishes each live robot's detection
//! frame stamped with the tick's start, exactly as a detector node on that robot would,
//! and the ground truth for scoring. `--stuck-slot S` freezes the camera
//! of whichever robot holds slot S on its first frame showing the worker (a fault for
//! end-to-end tests; robot ids in a container fleet are not known in advance, slots are).
//! In a secured fleet it takes a newer signed roster while it runs, as every member
//! does (`spwi_agent::fleet::live`): a revoked robot gets no more frames, and the
//! session reopens with the roster's access rules (the frames of that moment are lost).

use crate::faulty_camera::StuckCamera;
use crate::world_args::WorldArgs;
use anyhow::{anyhow, Result};
use spwi_agent::cli::{init_tracing, spawn_signal_handler};
use spwi_agent::config::LogFormat;
use spwi_agent::fleet::Role;
use spwi_proto::keys::{self, Topic};
use spwi_proto::*;
use spwi_world::layout::Layout;
use spwi_world::world::{Scenario, World};
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Duration;
use tokio::sync::{mpsc, watch};
use zenoh::sample::SampleKind;

pub struct WorldOptions {
    pub fleet: FleetId,
    pub scenario: Scenario,
    /// Workers on the floor (the truth describes the first).
    pub workers: usize,
    pub seed: u64,
    pub layout: Layout,
    pub zenoh: zenoh::Config,
    /// The fleet's credentials when it is secured: newer rosters are taken while running.
    pub credentials: Option<std::sync::Arc<spwi_agent::fleet::Credentials>>,
    /// The layout slot whose camera is stuck, if any.
    pub stuck_slot: Option<usize>,
}

/// Robot id → layout slot, giving each newcomer the lowest free slot.
#[derive(Debug, Default)]
pub struct Slots {
    taken: BTreeMap<RobotId, usize>,
    capacity: usize,
}

impl Slots {
    pub fn new(capacity: usize) -> Self {
        Slots { taken: BTreeMap::new(), capacity }
    }

    /// The slot of a robot that joined, or `None` when the layout has no room left.
    pub fn join(&mut self, robot: RobotId) -> Option<usize> {
        if let Some(&s) = self.taken.get(&robot) {
            return Some(s);
        }
        let free = (0..self.capacity).find(|s| !self.taken.values().any(|t| t == s))?;
        self.taken.insert(robot, free);
        Some(free)
    }

    pub fn leave(&mut self, robot: &RobotId) -> Option<usize> {
        self.taken.remove(robot)
    }

    /// (slot, robot) sorted by slot.
    pub fn assigned(&self) -> Vec<(usize, RobotId)> {
        let mut v: Vec<_> = self.taken.iter().map(|(r, &s)| (s, r.clone())).collect();
        v.sort();
        v
    }
}

/// The world's session and the membership its liveliness subscriber reports.
async fn open(
    zenoh: zenoh::Config,
    fleet: &FleetId,
) -> Result<(zenoh::Session, zenoh::pubsub::Subscriber<()>, mpsc::UnboundedReceiver<(RobotId, bool)>)> {
    let session = zenoh::open(zenoh).await.map_err(|e| anyhow!("cannot open the Zenoh session: {e}"))?;
    let (tx, rx) = mpsc::unbounded_channel();
    let fleet = fleet.clone();
    let membership = session
        .liveliness()
        .declare_subscriber(keys::all_alive(&fleet))
        .history(true)
        .callback(move |s| {
            if let Some(r) = keys::parse_alive(&fleet, s.key_expr().as_str()) {
                let _ = tx.send((r, s.kind() == SampleKind::Put));
            }
        })
        .await
        .map_err(|e| anyhow!(e))?;
    Ok((session, membership, rx))
}

pub async fn run(opts: WorldOptions, mut shutdown: watch::Receiver<bool>) -> Result<()> {
    let mut zenoh = opts.zenoh.clone();
    let (mut session, mut membership, mut rx) = open(zenoh.clone(), &opts.fleet).await?;
    let mut roster = opts.credentials.clone().map(spwi_agent::fleet::live::Watch::new);
    if let Some(w) = roster.as_mut() {
        w.listen(&session).await?;
    }
    let mut reopen_at: Option<tokio::time::Instant> = None;
    let mut world = World::with_workers(opts.layout, opts.scenario, opts.seed, 0, opts.workers);
    let mut slots = Slots::new(world.robots.len());
    let mut stuck = StuckCamera::default();
    let truth_key = keys::truth(&opts.fleet);
    // Frames are stamped on the fleet's clock, a few ms into each of its periods, as
    // cameras triggered on it would: a restarted world goes on at the current tick.
    let clock = spwi_core::clock::FleetClock::default();
    let into_next = tick_start(tick_at(clock.now()) + 1) + Duration::from_millis(5);
    let mut interval = tokio::time::interval_at(tokio::time::Instant::now() + clock.until(into_next), TICK_PERIOD);
    interval.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    tracing::info!(fleet = %opts.fleet, scenario = opts.scenario as u8, seed = opts.seed, "world running");
    loop {
        tokio::select! {
            _ = shutdown.changed() => break,
            adopted = spwi_agent::fleet::live::adopted(roster.as_mut(), &session) => {
                let adopted = adopted?;
                for robot in &adopted.revoked {
                    if let Some(s) = slots.leave(robot) {
                        world.set_in_fleet(s, false);
                        tracing::info!(%robot, slot = s, "robot revoked");
                    }
                }
                spwi_agent::fleet::secure::apply(&mut zenoh, &adopted.credentials)?;
                spwi_agent::fleet::live::for_reopening(&mut zenoh)?;
                let delay = spwi_agent::fleet::live::reopen_delay(&adopted.credentials.identity.name);
                reopen_at = Some(tokio::time::Instant::now() + delay);
            }
            _ = async { tokio::time::sleep_until(reopen_at.expect("guarded")).await }, if reopen_at.is_some() => {
                reopen_at = None;
                drop(membership);
                let _ = session.close().await;
                (session, membership, rx) = open(zenoh.clone(), &opts.fleet).await?;
                if let Some(w) = roster.as_mut() {
                    w.listen(&session).await?;
                }
                tracing::info!("reopened the session with the new roster's access rules");
            }
            Some((robot, alive)) = rx.recv() => {
                let admitted = roster.as_ref().is_none_or(|w| w.credentials().admits_robot(&robot));
                if alive && !admitted {
                    continue; // revoked, until the reopened session's rules cut it off
                }
                if alive {
                    match slots.join(robot.clone()) {
                        Some(s) => { world.set_in_fleet(s, true); tracing::info!(%robot, slot = s, "robot joined"); }
                        None => tracing::warn!(%robot, "no free robot slot in the layout: this robot gets no frames"),
                    }
                } else if let Some(s) = slots.leave(&robot) {
                    world.set_in_fleet(s, false);
                    tracing::info!(%robot, slot = s, "robot left");
                }
            }
            _ = interval.tick() => {
                world.step();
                world.follow_clock(clock.now());
                let assigned = slots.assigned();
                for (slot, robot) in &assigned {
                    let mut frame = world.observe(*slot, robot);
                    if opts.stuck_slot == Some(*slot) {
                        frame = stuck.pass(frame);
                    }
                    let key = keys::robot_topic(&opts.fleet, robot, Topic::Detections);
                    if let Err(e) = session.put(&key, encode(&frame)).await {
                        tracing::warn!("publishing {key}: {e}");
                    }
                }
                let _ = session.put(&truth_key, encode(&world.truth(&assigned))).await;
            }
        }
    }
    drop(membership);
    let _ = session.close().await;
    Ok(())
}

/// The arguments of `spwi-sim world`.
#[derive(clap::Args, Debug)]
pub struct WorldServiceArgs {
    /// The fleet: `default` unless given, or the one of --fleet-dir.
    #[arg(long, env = "SPWI_FLEET")]
    pub fleet: Option<FleetId>,
    /// The fleet directory: join with mutual TLS and the roster's access rules.
    #[arg(long, env = "SPWI_FLEET_DIR")]
    pub fleet_dir: Option<PathBuf>,
    /// Whose certificate to present from --fleet-dir (a member of role world).
    #[arg(long, env = "SPWI_IDENTITY", default_value = "world", requires = "fleet_dir")]
    pub identity: String,
    #[command(flatten)]
    pub world: WorldArgs,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Zenoh's own config file (json5).
    #[arg(long, env = "ZENOH_CONFIG")]
    pub zenoh_config: Option<PathBuf>,
    /// Zenoh setting override KEY:VALUE (VALUE in json5), repeatable.
    #[arg(long = "cfg", value_name = "KEY:VALUE")]
    pub cfg: Vec<String>,
    /// Freeze the camera of the robot in this layout slot on its first frame that shows
    /// the worker (a fault to test the fleet with).
    #[arg(long, value_name = "SLOT")]
    pub stuck_slot: Option<usize>,
}

/// `spwi-sim world`: parses nothing more, runs the tool.
pub fn main(a: WorldServiceArgs) -> Result<()> {
    let WorldServiceArgs { fleet, fleet_dir, identity, world, seed, zenoh_config, cfg, stuck_slot } = a;
    init_tracing(LogFormat::Human);
    let mut zenoh = spwi_agent::zenoh_config::build(zenoh_config.as_deref(), &cfg)?;
    let credentials =
        spwi_agent::fleet::secure_or_warn(&mut zenoh, fleet_dir.as_deref(), &identity, Role::World, "spwi-sim world")?;
    let fleet = spwi_agent::fleet::fleet_id(fleet, credentials.as_deref())?;
    let floor = world.floor()?;
    if let Some(s) = stuck_slot {
        if s >= floor.layout.robots.len() {
            anyhow::bail!("--stuck-slot {s}: the floor has robot slots 0..{}", floor.layout.robots.len());
        }
        tracing::warn!(slot = s, "the camera of the robot in slot {s} will freeze on its first sight of the worker");
    }
    let workers = usize::from(world.workers);
    let opts = crate::service::WorldOptions {
        fleet,
        scenario: world.scenario,
        workers,
        seed,
        layout: floor.layout,
        zenoh,
        credentials,
        stuck_slot,
    };
    let rt = tokio::runtime::Builder::new_multi_thread().enable_all().build()?;
    rt.block_on(async {
        let (tx, rx) = tokio::sync::watch::channel(false);
        spawn_signal_handler(tx);
        crate::service::run(opts, rx).await
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn newcomers_take_the_lowest_free_slot_and_leavers_free_theirs() {
        let mut s = Slots::new(2);
        let (a, b, c) = (RobotId::new("a").unwrap(), RobotId::new("b").unwrap(), RobotId::new("c").unwrap());
        assert_eq!(s.join(a.clone()), Some(0));
        assert_eq!(s.join(b.clone()), Some(1));
        assert_eq!(s.join(c.clone()), None, "layout full");
        assert_eq!(s.join(a.clone()), Some(0), "joining twice keeps the slot");
        assert_eq!(s.leave(&a), Some(0));
        assert_eq!(s.join(c.clone()), Some(0));
        assert_eq!(s.assigned(), vec![(0, c), (1, b)]);
    }
}
