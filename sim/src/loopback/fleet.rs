//! A fleet of real `spwi-agent` processes on one machine, for `spwi-sim bench` and its
//! soak: the simulated world's session is the hub every agent connects to (gossip
//! completes the mesh) — or, with routers, every agent and the hub are Zenoh clients
//! of `spwi-router` processes — and the hub observes what the agents publish
//! (decisions, message and byte counts) and who holds a liveliness token. Agents can be
//! stopped, started again and frozen; their CPU, memory and open files are read from
//! /proc.

use super::{AgentProcess, Decisions, Hub, Launch, Routers};
use anyhow::{anyhow, bail, Context, Result};
use spwi_agent::fleet::authority::ThrowawayFleet;
use spwi_proto::keys::{self, Topic};
use spwi_proto::{encode, FleetId, RobotId};
use spwi_world::layout::Layout;
use spwi_world::world::World;
use std::path::PathBuf;
use std::process::Command;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// How the fleet is made up.
#[derive(Debug, Clone)]
pub struct FleetOptions {
    pub robots: usize,
    /// The spwi-agent binary.
    pub agent: PathBuf,
    /// Model set folder for the agents (default: theirs).
    pub models: Option<PathBuf>,
    /// Mutual TLS and access control on every link, with a throw-away CA.
    pub secured: bool,
    /// Zenoh settings (`KEY:VALUE`) passed to every agent after the fleet's own.
    pub agent_cfg: Vec<String>,
    /// 0: the agents form a peer mesh. N: they are Zenoh clients of N `spwi-router`
    /// processes (from the binary next to `agent`), robot k at home on router k mod N.
    pub routers: usize,
}

/// What the hub counts of the agents' traffic besides their decisions.
#[derive(Default)]
pub struct Traffic {
    /// Messages and bytes the agents published (detections excluded).
    pub messages: u64,
    pub bytes: u64,
    /// Robots holding a liveliness token.
    pub members: usize,
}

pub struct LoopbackFleet {
    pub ids: Vec<RobotId>,
    pub hub: Hub,
    pub decisions: Decisions,
    pub traffic: Arc<Mutex<Traffic>>,
    options: FleetOptions,
    /// Keeps the throw-away fleet directory of a secured fleet.
    _secured: Option<ThrowawayFleet>,
    /// One slot per robot; `None` while its agent is stopped.
    agents: Vec<Option<AgentProcess>>,
    detection_keys: Vec<String>,
    _traffic: zenoh::pubsub::Subscriber<()>,
    _members: zenoh::pubsub::Subscriber<()>,
    /// Last, so they outlive the agents (fields drop in order).
    routers: Option<Routers>,
}

impl LoopbackFleet {
    /// Opens the hub, starts every agent and waits until all hold their tokens.
    pub async fn start(options: FleetOptions) -> Result<LoopbackFleet> {
        if !options.agent.is_file() {
            bail!(
                "{}: no spwi-agent binary there (cargo build --release builds it; or pass --agent)",
                options.agent.display()
            );
        }
        let fleet = format!("bench{}", std::process::id());
        let ids: Vec<RobotId> = (0..options.robots).map(|i| RobotId::new(format!("b{i}"))).collect::<Result<_, _>>()?;
        let routers = match options.routers {
            0 => None,
            n => Some(Routers::start(&options.agent.with_file_name("spwi-router"), n)?),
        };
        let (hub, secured) = if let Some(r) = &routers {
            if options.secured {
                bail!("a secured fleet of routers' clients is not supported yet: leave out --secured or --routers");
            }
            // At home on the last router: the simulated cameras' link is not the one
            // a router failure (`kill_router(0)`) cuts — on a robot its camera is local.
            (Hub::start_client(&fleet, &r.connect_from(r.endpoints.len() - 1)).await?, None)
        } else if options.secured {
            let secured = ThrowawayFleet::with_world("bench", &FleetId::new(&fleet)?, &ids)?;
            (Hub::start_secured(&secured.dir.root, "world").await?, Some(secured))
        } else {
            (Hub::start(&fleet).await?, None)
        };
        let decisions = Decisions::subscribe(&hub.session, &hub.fleet).await?;
        let traffic = Arc::new(Mutex::new(Traffic::default()));
        let counted = {
            let (traffic, fleet) = (traffic.clone(), hub.fleet.clone());
            hub.session
                .declare_subscriber(keys::all_robot_topics(&fleet))
                .callback(move |s| {
                    if keys::parse_robot_topic(&fleet, s.key_expr().as_str())
                        .is_some_and(|(_, t)| t != Topic::Detections)
                    {
                        let mut t = traffic.lock().expect("traffic");
                        t.messages += 1;
                        t.bytes += s.payload().len() as u64;
                    }
                })
                .await
                .map_err(|e| anyhow!(e))?
        };
        let members = {
            let (traffic, fleet) = (traffic.clone(), hub.fleet.clone());
            hub.session
                .liveliness()
                .declare_subscriber(keys::all_alive(&fleet))
                .history(true)
                .callback(move |s| {
                    if keys::parse_alive(&fleet, s.key_expr().as_str()).is_some() {
                        let mut t = traffic.lock().expect("traffic");
                        if s.kind() == zenoh::sample::SampleKind::Put {
                            t.members += 1;
                        } else {
                            t.members = t.members.saturating_sub(1);
                        }
                    }
                })
                .await
                .map_err(|e| anyhow!(e))?
        };
        let detection_keys = ids.iter().map(|id| keys::robot_topic(&hub.fleet, id, Topic::Detections)).collect();
        let mut f = LoopbackFleet {
            agents: (0..ids.len()).map(|_| None).collect(),
            ids,
            hub,
            decisions,
            traffic,
            options,
            _secured: secured,
            detection_keys,
            _traffic: counted,
            _members: members,
            routers,
        };
        for slot in 0..f.ids.len() {
            f.start_agent(slot)?;
        }
        let n = f.ids.len();
        f.wait_members(n, Duration::from_secs(30 + n as u64)).await?;
        Ok(f)
    }

    /// Starts the agent of `slot` (it must be stopped).
    pub fn start_agent(&mut self, slot: usize) -> Result<()> {
        assert!(self.agents[slot].is_none(), "agent {slot} is running");
        let launch = Launch {
            routers: self.routers.as_ref().map(|r| r.connect_from(slot % r.endpoints.len())).unwrap_or_default(),
            models: self.options.models.clone(),
            cfg: &self.options.agent_cfg,
            stderr: false,
            ..Launch::new(&self.hub, &self.ids[slot])
        };
        self.agents[slot] = Some(AgentProcess::spawn(Command::new(&self.options.agent), launch)?);
        Ok(())
    }

    /// Stops the agent of `slot` as an operator would (SIGTERM: it leaves the fleet
    /// cleanly) and waits for it to exit.
    pub async fn stop_agent(&mut self, slot: usize) -> Result<()> {
        let agent = self.agents[slot].take().with_context(|| format!("agent {slot} is not running"))?;
        agent.stop().await?;
        Ok(())
    }

    /// CPU seconds the fleet's running routers have used (0 without routers).
    pub fn routers_cpu_s(&self) -> f64 {
        self.routers.as_ref().map_or(0.0, Routers::cpu_s)
    }

    /// Kills router `i` (SIGKILL); its clients move to the next router they list.
    pub fn kill_router(&mut self, i: usize) -> Result<()> {
        self.routers.as_mut().context("this fleet has no routers")?.kill(i)
    }

    /// Sends `sig` (e.g. "STOP", "CONT") to the running agent of `slot`.
    pub fn signal_agent(&self, slot: usize, sig: &str) -> Result<()> {
        self.agents[slot].as_ref().with_context(|| format!("agent {slot} is not running"))?.signal(sig)
    }

    /// The process id of the agent of `slot`, if running.
    pub fn pid(&self, slot: usize) -> Option<u32> {
        self.agents[slot].as_ref().map(AgentProcess::pid)
    }

    /// What the agent of `slot` uses of the machine (zeros when it is not running).
    pub fn usage(&self, slot: usize) -> Usage {
        self.pid(slot).and_then(usage).unwrap_or_default()
    }

    /// Waits until `n` robots hold their liveliness tokens; fails at once, in the
    /// agent's own words, if one of them has exited.
    pub async fn wait_members(&mut self, n: usize, limit: Duration) -> Result<()> {
        let since = Instant::now();
        let members = |f: &Self| f.traffic.lock().expect("traffic").members;
        while members(self) != n {
            for agent in self.agents.iter_mut().flatten() {
                if let Some(how) = agent.exited()? {
                    bail!("{how}");
                }
            }
            if since.elapsed() > limit {
                bail!("{} agents hold a token, {n} expected within {limit:?}", members(self));
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        Ok(())
    }

    /// Publishes the world's frames of its current tick to every robot slot, stamped
    /// with the fleet clock's tick now ([`World::follow_clock`]); returns when the first
    /// was published (simulating the cameras is not the fleet's work).
    pub async fn publish(&self, world: &mut World) -> Result<Instant> {
        world.follow_clock(spwi_core::clock::FleetClock::default().now());
        let frames: Vec<Vec<u8>> =
            self.ids.iter().enumerate().map(|(slot, id)| encode(&world.observe(slot, id))).collect();
        let sent = Instant::now();
        for (key, frame) in self.detection_keys.iter().zip(frames) {
            self.hub.session.put(key, frame).await.map_err(|e| anyhow!("{key}: {e}"))?;
        }
        Ok(sent)
    }
}

/// When the fleet clock's next period starts, plus 5 ms: a loop that publishes a
/// tick's frames every [`spwi_proto::TICK_PERIOD`] from then stamps each with its own
/// tick ([`LoopbackFleet::publish`]), never two with one.
pub fn next_tick_instant() -> Instant {
    let clock = spwi_core::clock::FleetClock::default();
    let at = spwi_proto::tick_start(spwi_proto::tick_at(clock.now()) + 1) + Duration::from_millis(5);
    Instant::now() + clock.until(at)
}

/// A layout with at least `n` robot slots: the file's slots, repeated with a small shift.
pub fn layout_with_slots(n: usize) -> Layout {
    let mut l = Layout::default_layout();
    let base = l.robots.clone();
    let mut k = 1;
    while l.robots.len() < n {
        for s in &base {
            if l.robots.len() == n {
                break;
            }
            let mut s = s.clone();
            let shift = 0.4 * k as f32;
            s.spawn = [s.spawn[0] + shift * 0.5, s.spawn[1] + shift * 0.3];
            s.patrol.iter_mut().for_each(|p| *p = [p[0] + shift * 0.5, p[1] + shift * 0.3]);
            l.robots.push(s);
        }
        k += 1;
    }
    l
}

/// A process's use of the machine, from /proc.
#[derive(Debug, Clone, Copy, Default)]
pub struct Usage {
    /// CPU seconds, user and system.
    pub cpu_s: f64,
    pub rss_mb: f64,
    /// The anonymous part of the RSS (heap, stacks): what a process itself allocates,
    /// unlike the binary's code pages, which grow as new code paths first run and are
    /// shared by every agent on the host.
    pub anon_mb: f64,
    pub open_files: usize,
}

pub fn usage(pid: u32) -> Option<Usage> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    let fields: Vec<&str> = stat.rsplit_once(')')?.1.split_whitespace().collect();
    let ticks: f64 = fields.get(11)?.parse::<f64>().ok()? + fields.get(12)?.parse::<f64>().ok()?;
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let kb = |field: &str| -> Option<f64> {
        status.lines().find(|l| l.starts_with(field))?.split_whitespace().nth(1)?.parse().ok()
    };
    let (rss_mb, anon_mb) = (kb("VmRSS:")? / 1024.0, kb("RssAnon:")? / 1024.0);
    let open_files = std::fs::read_dir(format!("/proc/{pid}/fd")).ok()?.count();
    Some(Usage { cpu_s: ticks / 100.0, rss_mb, anon_mb, open_files }) // USER_HZ is 100 on Linux
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layouts_grow_to_any_fleet_size() {
        assert_eq!(layout_with_slots(3).robots.len(), 8, "the file's 8 slots suffice");
        let l = layout_with_slots(32);
        assert_eq!(l.robots.len(), 32);
        assert_ne!(l.robots[8].spawn, l.robots[0].spawn);
    }

    #[test]
    fn usage_reads_this_process() {
        let u = usage(std::process::id()).unwrap();
        assert!(u.cpu_s >= 0.0 && u.rss_mb > 1.0 && u.open_files >= 3, "{u:?}");
    }
}
