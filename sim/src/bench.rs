//! `spwi-sim bench`: how far one machine's fleet goes. The simulated world (in this
//! process) feeds N real `spwi-agent` processes over Zenoh on loopback, and an observer
//! session measures, per tick, the time from the world publishing the frames to the
//! last live robot publishing its decision; agreement; messages and bytes the agents
//! publish per tick; each agent's CPU and resident memory from /proc.
//!
//! Paced mode ticks at 10 Hz, as deployed. `--free` publishes the next tick as soon as
//! every robot decided the last (or after 200 ms), giving the fleet's maximum rate.
//! `--secured` runs the fleet as deployed outside development: a fresh fleet directory
//! (CA, the world, one identity per agent), mutual TLS and access control on every link.

use crate::demo::percentile;
use anyhow::{anyhow, bail, Context, Result};
use serde::Serialize;
use spwi_agent::cli::init_tracing;
use spwi_agent::config::LogFormat;
use spwi_agent::fleet::authority::ThrowawayFleet;
use spwi_agent::fleet::{secure_or_warn, Role};
use spwi_agent::zenoh_config;
use spwi_proto::keys::{self, Topic};
use spwi_proto::*;
use spwi_world::layout::Layout;
use spwi_world::world::{Scenario, World};
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

pub struct BenchOptions {
    pub robots: usize,
    pub duration: Duration,
    pub free_running: bool,
    pub scenario: Scenario,
    pub agent: PathBuf,
    pub models: Option<PathBuf>,
    pub secured: bool,
}

#[derive(Debug, Clone, Serialize)]
pub struct LatencyMs {
    pub p50: f64,
    pub p99: f64,
    pub max: f64,
}

/// `--json` keeps these keys.
#[derive(Debug, Clone, Serialize)]
pub struct BenchReport {
    pub robots: usize,
    pub free_running: bool,
    /// Mutual TLS and access control on every link (`--secured`).
    pub secured: bool,
    pub ticks: u64,
    pub ticks_per_second: f64,
    /// Frame published → the last live robot's decision published, per tick.
    pub latency_ms: LatencyMs,
    /// Ticks on which every robot decided the same class for t, among ticks all decided.
    pub agreement: f64,
    /// Ticks missing at least one robot's decision.
    pub incomplete_ticks: u64,
    /// Fraction of one core, mean over agents.
    pub cpu_per_agent: f64,
    pub rss_mb_per_agent: f64,
    pub msgs_per_tick_per_robot: f64,
    pub bytes_per_tick_per_robot: f64,
}

#[derive(Default)]
struct Seen {
    /// tick → robot → (class at t, when received)
    decisions: BTreeMap<u64, BTreeMap<RobotId, (Option<u8>, Instant)>>,
    messages: u64,
    bytes: u64,
    members: usize,
}

/// A layout with at least `n` robot slots: the file's slots, repeated with a small shift.
fn layout_with_slots(n: usize) -> Layout {
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

/// CPU seconds (user + system) and resident MB of a process, from /proc.
fn proc_usage(pid: u32) -> Option<(f64, f64)> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    let fields: Vec<&str> = stat.rsplit_once(')')?.1.split_whitespace().collect();
    let ticks: f64 = fields.get(11)?.parse::<f64>().ok()? + fields.get(12)?.parse::<f64>().ok()?;
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let rss_kb: f64 = status.lines().find(|l| l.starts_with("VmRSS:"))?.split_whitespace().nth(1)?.parse().ok()?;
    Some((ticks / 100.0, rss_kb / 1024.0)) // USER_HZ is 100 on Linux
}

struct Agents(Vec<Child>);

impl Drop for Agents {
    fn drop(&mut self) {
        for c in &mut self.0 {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

pub async fn run(o: &BenchOptions) -> Result<BenchReport> {
    if !o.agent.is_file() {
        bail!("{}: no spwi-agent binary there (cargo build --release builds it; or pass --agent)", o.agent.display());
    }
    let fleet = FleetId::new(format!("bench{}", std::process::id()))?;
    let ids: Vec<RobotId> = (0..o.robots).map(|i| RobotId::new(format!("b{i}"))).collect::<Result<_, _>>()?;
    // A secured bench: a throw-away fleet of the world and every agent.
    let secured = if o.secured {
        let members: Vec<(&str, Role)> =
            std::iter::once(("world", Role::World)).chain(ids.iter().map(|r| (r.as_str(), Role::Robot))).collect();
        Some(ThrowawayFleet::create("bench", &fleet, &members)?)
    } else {
        None
    };
    // The world's session is the hub the agents connect to; gossip completes the mesh.
    let mut hub_config = zenoh_config::loopback_peer(&[])?;
    if let Some(s) = &secured {
        secure_or_warn(&mut hub_config, Some(&s.dir.root), "world", Role::World, "spwi-sim bench")?;
    }
    let session = zenoh::open(hub_config).await.map_err(|e| anyhow!("zenoh: {e}"))?;
    let hub = session
        .info()
        .locators()
        .await
        .into_iter()
        .next()
        .ok_or_else(|| anyhow!("the world's session listens nowhere"))?
        .to_string();
    let seen = Arc::new(Mutex::new(Seen::default()));
    let _agent_traffic = {
        let (seen, fleet) = (seen.clone(), fleet.clone());
        session
            .declare_subscriber(keys::all_robot_topics(&fleet))
            .callback(move |s| {
                let Some((robot, topic)) = keys::parse_robot_topic(&fleet, s.key_expr().as_str()) else { return };
                if topic == Topic::Detections {
                    return;
                }
                let bytes = s.payload().to_bytes();
                let mut st = seen.lock().expect("bench state");
                st.messages += 1;
                st.bytes += bytes.len() as u64;
                if topic == Topic::Decision {
                    if let Ok(d) = decode_from::<DecisionMsg>(&bytes, &robot) {
                        let class = d.steps.first().map(|s| s.class);
                        st.decisions.entry(d.tick).or_default().insert(robot, (class, Instant::now()));
                    }
                }
            })
            .await
            .map_err(|e| anyhow!(e))?
    };
    let _members = {
        let (seen, fleet) = (seen.clone(), fleet.clone());
        session
            .liveliness()
            .declare_subscriber(keys::all_alive(&fleet))
            .history(true)
            .callback(move |s| {
                if keys::parse_alive(&fleet, s.key_expr().as_str()).is_some() {
                    let mut st = seen.lock().expect("bench state");
                    if s.kind() == zenoh::sample::SampleKind::Put {
                        st.members += 1;
                    } else {
                        st.members = st.members.saturating_sub(1);
                    }
                }
            })
            .await
            .map_err(|e| anyhow!(e))?
    };

    let mut agents = Agents(Vec::new());
    for id in &ids {
        let mut cmd = Command::new(&o.agent);
        cmd.args(["--robot-id", id.as_str(), "--fleet", fleet.as_str()])
            .args(["--cfg", r#"listen/endpoints:["tcp/127.0.0.1:0"]"#])
            .args(["--cfg", &format!(r#"connect/endpoints:["{hub}"]"#)])
            .args(["--cfg", "scouting/multicast/enabled:false"])
            .env("RUST_LOG", "warn,zenoh=error")
            .stdout(Stdio::null())
            .stderr(Stdio::null());
        if let Some(m) = &o.models {
            cmd.args(["--models", &m.display().to_string()]);
        }
        if let Some(s) = &secured {
            cmd.arg("--fleet-dir").arg(&s.dir.root);
        }
        agents.0.push(cmd.spawn().with_context(|| format!("starting {}", o.agent.display()))?);
    }
    let joined = Instant::now();
    while seen.lock().expect("bench state").members < o.robots {
        if joined.elapsed() > Duration::from_secs(30 + o.robots as u64) {
            bail!(
                "only {} of {} agents joined within the time allowed",
                seen.lock().expect("bench state").members,
                o.robots
            );
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }

    let mut world = World::new(layout_with_slots(o.robots), o.scenario, 1, o.robots);
    let keys: Vec<String> = ids.iter().map(|id| keys::robot_topic(&fleet, id, Topic::Detections)).collect();
    let warmup = Duration::from_secs(2);
    let mut published: BTreeMap<u64, Instant> = BTreeMap::new();
    let (mut cpu0, mut measure_from) = (Vec::new(), None);
    let started = Instant::now();
    let mut next = Instant::now();
    loop {
        let now = Instant::now();
        if measure_from.is_none() && now - started >= warmup {
            cpu0 = agents.0.iter().map(|c| proc_usage(c.id()).map_or(0.0, |u| u.0)).collect();
            let mut st = seen.lock().expect("bench state");
            (st.messages, st.bytes) = (0, 0);
            measure_from = Some((now, world.tick + 1));
        }
        if measure_from.is_some_and(|(t, _)| now - t >= o.duration) {
            break;
        }
        world.step();
        let t = world.tick;
        // Simulating the cameras is not the fleet's work: frames first, then the clock
        // starts as the first one is published.
        let frames: Vec<Vec<u8>> = ids.iter().enumerate().map(|(slot, id)| encode(&world.observe(slot, id))).collect();
        let sent = Instant::now();
        for (key, frame) in keys.iter().zip(frames) {
            session.put(key, frame).await.map_err(|e| anyhow!("{key}: {e}"))?;
        }
        published.insert(t, sent);
        if o.free_running {
            let deadline = sent + Duration::from_millis(200);
            while Instant::now() < deadline
                && seen.lock().expect("bench state").decisions.get(&t).is_none_or(|d| d.len() < o.robots)
            {
                tokio::time::sleep(Duration::from_micros(200)).await;
            }
        } else {
            next += spwi_proto::TICK_PERIOD;
            tokio::time::sleep_until(tokio::time::Instant::from_std(next)).await;
        }
    }
    let (measured_since, first_tick) = measure_from.expect("measured");
    let elapsed = measured_since.elapsed().as_secs_f64();
    tokio::time::sleep(Duration::from_millis(300)).await; // the last decisions
    let usage: Vec<(f64, f64)> = agents.0.iter().map(|c| proc_usage(c.id()).unwrap_or((0.0, 0.0))).collect();
    drop(agents);

    let st = seen.lock().expect("bench state");
    let last_tick = world.tick;
    let ticks = last_tick + 1 - first_tick;
    let (mut latencies, mut agreed, mut complete, mut incomplete) = (Vec::new(), 0u64, 0u64, 0u64);
    for t in first_tick..=last_tick {
        let Some(d) = st.decisions.get(&t).filter(|d| d.len() == o.robots) else {
            incomplete += 1;
            continue;
        };
        complete += 1;
        let last = d.values().map(|(_, at)| *at).max().expect("robots > 0");
        latencies.push((last - published[&t]).as_secs_f64() * 1e3);
        let first = d.values().next().expect("robots > 0").0;
        agreed += u64::from(d.values().all(|(c, _)| *c == first));
    }
    latencies.sort_by(f64::total_cmp);
    let n = o.robots as f64;
    Ok(BenchReport {
        robots: o.robots,
        free_running: o.free_running,
        secured: o.secured,
        ticks,
        ticks_per_second: ticks as f64 / elapsed,
        latency_ms: LatencyMs {
            p50: percentile(&latencies, 0.5),
            p99: percentile(&latencies, 0.99),
            max: latencies.last().copied().unwrap_or(0.0),
        },
        agreement: if complete == 0 { 0.0 } else { agreed as f64 / complete as f64 },
        incomplete_ticks: incomplete,
        cpu_per_agent: usage.iter().zip(&cpu0).map(|((c, _), c0)| (c - c0) / elapsed).sum::<f64>() / n,
        rss_mb_per_agent: usage.iter().map(|(_, r)| r).sum::<f64>() / n,
        msgs_per_tick_per_robot: st.messages as f64 / ticks as f64 / n,
        bytes_per_tick_per_robot: st.bytes as f64 / ticks as f64 / n,
    })
}

pub fn print(r: &BenchReport) {
    println!(
        "{} robots{}{}: {} ticks, {:.1} ticks/s · frame → every decision p50 {:.2} ms, p99 {:.2} ms, max {:.2} ms · agreement {:.1}% ({} ticks incomplete) · per agent {:.1}% CPU, {:.1} MB RSS, {:.1} msgs and {:.0} B per tick",
        r.robots,
        if r.free_running { " (free-running)" } else { " at 10 Hz" },
        if r.secured { ", secured" } else { "" },
        r.ticks,
        r.ticks_per_second,
        r.latency_ms.p50,
        r.latency_ms.p99,
        r.latency_ms.max,
        100.0 * r.agreement,
        r.incomplete_ticks,
        100.0 * r.cpu_per_agent,
        r.rss_mb_per_agent,
        r.msgs_per_tick_per_robot,
        r.bytes_per_tick_per_robot
    );
}

/// The arguments of `spwi-sim bench`.
#[derive(clap::Args, Debug)]
pub struct BenchArgs {
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u64).range(1..=64))]
    pub robots: u64,
    /// How long to measure, after 2 s of warm-up (e.g. 20s).
    #[arg(long, default_value = "20s", value_parser = crate::demo::parse_duration)]
    pub duration: Duration,
    /// Publish the next tick as soon as every robot decided (the maximum rate).
    #[arg(long)]
    pub free: bool,
    #[arg(long, default_value = "3", value_parser = crate::world_args::parse_scenario)]
    pub scenario: spwi_world::world::Scenario,
    /// The spwi-agent binary (default: next to this one).
    #[arg(long)]
    pub agent: Option<PathBuf>,
    /// Model set folder for the agents (default: theirs).
    #[arg(long)]
    pub models: Option<PathBuf>,
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Run the fleet secured (mutual TLS, access control), with a throw-away CA.
    #[arg(long)]
    pub secured: bool,
}

/// `spwi-sim bench`: parses nothing more, runs the tool.
pub fn main(a: BenchArgs) -> Result<()> {
    let BenchArgs { robots, duration, free, scenario, agent, models, json, secured } = a;
    init_tracing(LogFormat::Human);
    let agent = match agent {
        Some(a) => a,
        None => std::env::current_exe()?.with_file_name("spwi-agent"),
    };
    let opts = crate::bench::BenchOptions {
        robots: robots as usize,
        duration,
        free_running: free,
        scenario,
        agent,
        models,
        secured,
    };
    let rt = tokio::runtime::Builder::new_multi_thread().enable_all().build()?;
    let report = rt.block_on(crate::bench::run(&opts))?;
    crate::bench::print(&report);
    if let Some(path) = json {
        std::fs::write(&path, serde_json::to_string_pretty(&report)?)?;
    }
    Ok(())
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
    fn proc_usage_reads_this_process() {
        let (cpu, rss) = proc_usage(std::process::id()).unwrap();
        assert!(cpu >= 0.0 && rss > 1.0, "{cpu} s, {rss} MB");
    }
}
