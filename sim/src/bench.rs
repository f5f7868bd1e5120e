//! `spwi-sim bench`: how far one machine's fleet goes. The simulated world (in this
//! process) feeds N real `spwi-agent` processes over Zenoh on loopback, and an observer
//! session measures, per tick, the time from the world publishing the frames to the
//! last live robot publishing its decision; agreement; messages and bytes the agents
//! publish per tick; each agent's CPU and resident memory from /proc.
//!
//! The world ticks at 10 Hz on the fleet's clock, as deployed: a fleet decides one tick
//! per period of its clock, so there is no faster rate to measure.
//! `--secured` runs the fleet as deployed outside development: a fresh fleet directory
//! (CA, the world, one identity per agent), mutual TLS and access control on every link.
//! `--routers N` makes the robots Zenoh clients of N routers instead of a peer mesh;
//! `--router-down-at` kills the first router mid-run, to see how the fleet carries on.

use crate::loopback::{layout_with_slots, FleetOptions, LoopbackFleet, Usage};
use crate::measures::{Agreement, LatencyMs};
use anyhow::Result;
use serde::Serialize;
use spwi_agent::cli::init_tracing;
use spwi_agent::config::LogFormat;
use spwi_world::world::{Scenario, World};
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::{Duration, Instant};

pub struct BenchOptions {
    pub fleet: FleetOptions,
    pub duration: Duration,
    pub scenario: Scenario,
    /// Workers on the floor (`--workers`).
    pub workers: usize,
    /// Kill router 0 this long after the measurement starts.
    pub router_down_at: Option<Duration>,
}

/// `--json` keeps these keys.
#[derive(Debug, Clone, Serialize)]
pub struct BenchReport {
    pub robots: usize,
    /// Workers on the floor (`--workers`): frames carry everyone in view.
    pub workers: usize,
    /// Mutual TLS and access control on every link (`--secured`).
    pub secured: bool,
    /// 0: a peer mesh; N: the robots are clients of N routers (`--routers`).
    pub routers: usize,
    pub ticks: u64,
    pub ticks_per_second: f64,
    /// Frame published → the last live robot's decision published, per tick.
    pub latency_ms: LatencyMs,
    /// Ticks on which every robot decided the same class for t, among ticks all decided.
    pub agreement: f64,
    /// Ticks missing at least one robot's decision.
    pub incomplete_ticks: u64,
    /// With `--router-down-at`: seconds from the router's death to the end of the last
    /// incomplete tick after it (0: no tick went undecided).
    pub router_down_gap_s: Option<f64>,
    /// Fraction of one core, mean over agents.
    pub cpu_per_agent: f64,
    /// Fraction of one core, all routers together; none without routers or when one
    /// was killed during the run.
    pub cpu_routers: Option<f64>,
    pub rss_mb_per_agent: f64,
    pub msgs_per_tick_per_robot: f64,
    pub bytes_per_tick_per_robot: f64,
}

pub async fn run(o: &BenchOptions) -> Result<BenchReport> {
    let robots = o.fleet.robots;
    let mut fleet = LoopbackFleet::start(o.fleet.clone()).await?;
    let mut world = World::with_workers(layout_with_slots(robots), o.scenario, 1, robots, o.workers);
    let warmup = Duration::from_secs(2);
    let mut published: BTreeMap<u64, Instant> = BTreeMap::new();
    let (mut cpu0, mut routers_cpu0, mut measure_from) = (Vec::new(), 0.0, None);
    let mut router_down_tick = None;
    let started = Instant::now();
    let mut next = crate::loopback::next_tick_instant();
    loop {
        let now = Instant::now();
        if measure_from.is_none() && now - started >= warmup {
            cpu0 = (0..robots).map(|slot| fleet.usage(slot).cpu_s).collect();
            routers_cpu0 = fleet.routers_cpu_s();
            let mut traffic = fleet.traffic.lock().expect("traffic");
            (traffic.messages, traffic.bytes) = (0, 0);
            measure_from = Some((now, world.clock_tick() + 1));
        }
        if measure_from.is_some_and(|(t, _)| now - t >= o.duration) {
            break;
        }
        if let (Some(at), Some((since, _)), None) = (o.router_down_at, measure_from, router_down_tick) {
            if now - since >= at {
                fleet.kill_router(0)?;
                router_down_tick = Some(world.clock_tick() + 1);
            }
        }
        world.step();
        let sent = fleet.publish(&mut world).await?;
        published.insert(world.clock_tick(), sent);
        next += spwi_proto::TICK_PERIOD;
        tokio::time::sleep_until(tokio::time::Instant::from_std(next)).await;
    }
    let (measured_since, first_tick) = measure_from.expect("measured");
    let elapsed = measured_since.elapsed().as_secs_f64();
    tokio::time::sleep(Duration::from_millis(300)).await; // the last decisions
    let usage: Vec<Usage> = (0..robots).map(|slot| fleet.usage(slot)).collect();
    let routers_cpu = fleet.routers_cpu_s();
    let decisions = std::mem::take(&mut *fleet.decisions.lock());
    let (messages, bytes) = {
        let traffic = fleet.traffic.lock().expect("traffic");
        (traffic.messages, traffic.bytes)
    };
    drop(fleet);

    let last_tick = world.clock_tick();
    let ticks = last_tick + 1 - first_tick;
    let (mut latencies, mut agreement, mut incomplete) = (Vec::new(), Agreement::default(), 0u64);
    let mut last_incomplete = None;
    for t in first_tick..=last_tick {
        let Some(d) = decisions.get(&t).filter(|d| d.len() == robots) else {
            incomplete += 1;
            last_incomplete = Some(t);
            continue;
        };
        let last = d.values().map(|d| d.at).max().expect("robots > 0");
        latencies.push((last - published[&t]).as_secs_f64() * 1e3);
        agreement.tick(d.values().map(|d| d.class()));
    }
    let n = robots as f64;
    Ok(BenchReport {
        robots,
        workers: o.workers,
        secured: o.fleet.secured,
        routers: o.fleet.routers,
        ticks,
        ticks_per_second: ticks as f64 / elapsed,
        latency_ms: LatencyMs::of(latencies),
        agreement: agreement.share(),
        incomplete_ticks: incomplete,
        router_down_gap_s: router_down_tick.map(|down| {
            let gap_ticks = last_incomplete.filter(|&t| t >= down).map_or(0, |t| t + 1 - down);
            gap_ticks as f64 * spwi_proto::TICK_PERIOD.as_secs_f64()
        }),
        cpu_per_agent: usage.iter().zip(&cpu0).map(|(u, c0)| (u.cpu_s - c0) / elapsed).sum::<f64>() / n,
        cpu_routers: (o.fleet.routers > 0 && router_down_tick.is_none())
            .then(|| (routers_cpu - routers_cpu0) / elapsed),
        rss_mb_per_agent: usage.iter().map(|u| u.rss_mb).sum::<f64>() / n,
        msgs_per_tick_per_robot: messages as f64 / ticks as f64 / n,
        bytes_per_tick_per_robot: bytes as f64 / ticks as f64 / n,
    })
}

pub fn print(r: &BenchReport) {
    println!(
        "{} robots at 10 Hz{}{}{}: {} ticks, {:.1} ticks/s · frame → every decision p50 {:.2} ms, p99 {:.2} ms, max {:.2} ms · agreement {:.1}% ({} ticks incomplete) · per agent {:.1}% CPU, {:.1} MB RSS, {:.1} msgs and {:.0} B per tick",
        r.robots,
        if r.workers > 1 { format!(", {} workers", r.workers) } else { String::new() },
        if r.secured { ", secured" } else { "" },
        match r.routers {
            0 => String::new(),
            n => format!(", clients of {n} router{}", if n == 1 { "" } else { "s" }),
        },
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
    if let Some(cpu) = r.cpu_routers {
        println!("routers: {:.1} % of a core together", 100.0 * cpu);
    }
    if let Some(gap) = r.router_down_gap_s {
        println!("router 0 killed: every robot deciding again {gap:.1} s after");
    }
}

/// The arguments of `spwi-sim bench`.
#[derive(clap::Args, Debug)]
pub struct BenchArgs {
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u64).range(1..=64))]
    pub robots: u64,
    /// How long to measure, after 2 s of warm-up (e.g. 20s).
    #[arg(long, default_value = "20s", value_parser = crate::durations::parse_duration)]
    pub duration: Duration,
    #[arg(long, default_value = "3", value_parser = crate::world_args::parse_scenario)]
    pub scenario: spwi_world::world::Scenario,
    /// Workers on the floor, each with its own work cycle (frames carry everyone in
    /// view); not in a soak.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u8).range(1..=spwi_world::world::MAX_WORKERS as i64))]
    pub workers: u8,
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
    /// A Zenoh setting for every agent, as `spwi-agent --cfg KEY:VALUE` takes it
    /// (repeatable): to measure a tuning before making it a default.
    #[arg(long = "agent-cfg", value_name = "KEY:VALUE")]
    pub agent_cfg: Vec<String>,
    /// The robots as Zenoh clients of this many `spwi-router` processes (next to the
    /// agent binary) instead of a peer mesh (0).
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u64).range(0..=4))]
    pub routers: u64,
    /// Kill the first router this long into the measurement (e.g. 10s; needs
    /// --routers 2 or more): its robots move to the next router; reports how long
    /// until all decide again.
    #[arg(long, value_parser = crate::durations::parse_duration)]
    pub router_down_at: Option<Duration>,
    /// A soak instead of a measurement: run this long (e.g. 30m) while robots leave,
    /// come back and freeze (see --churn); fails if the fleet did not stay up.
    #[arg(long, value_parser = crate::durations::parse_duration)]
    pub soak: Option<Duration>,
    /// In a soak: how often the last robot leaves or comes back.
    #[arg(long, default_value = "30s", value_parser = crate::durations::parse_duration)]
    pub churn: Duration,
    /// In a soak: how often the robot before it is frozen (SIGSTOP) for 5 s.
    #[arg(long, default_value = "2m", value_parser = crate::durations::parse_duration)]
    pub freeze_every: Duration,
    /// In a soak: the share of settled ticks that may go undecided (the target is 0).
    #[arg(long, default_value_t = 0.0)]
    pub max_undecided: f64,
}

/// `spwi-sim bench`: parses nothing more, runs the tool.
pub fn main(a: BenchArgs) -> Result<()> {
    let BenchArgs {
        robots,
        duration,
        scenario,
        workers,
        agent,
        models,
        json,
        secured,
        agent_cfg,
        routers,
        router_down_at,
        soak,
        churn,
        freeze_every,
        max_undecided,
    } = a;
    init_tracing(LogFormat::Human);
    let agent = match agent {
        Some(a) => a,
        None => std::env::current_exe()?.with_file_name("spwi-agent"),
    };
    if router_down_at.is_some() && routers < 2 {
        anyhow::bail!("--router-down-at needs --routers 2 or more: with one router there is no other to move to");
    }
    let fleet = FleetOptions { robots: robots as usize, agent, models, secured, agent_cfg, routers: routers as usize };
    let rt = tokio::runtime::Builder::new_multi_thread().enable_all().build()?;
    if let Some(duration) = soak {
        if workers != 1 {
            anyhow::bail!("--workers {workers} with --soak: a soak runs one worker");
        }
        let opts = crate::soak::SoakOptions { fleet, duration, churn, freeze_every, scenario };
        let report = rt.block_on(crate::soak::run(&opts))?;
        crate::soak::print(&report);
        write_json(json.as_deref(), &report)?;
        if let Some(why) = report.failure(max_undecided) {
            anyhow::bail!("the fleet did not stay up: {why}");
        }
        return Ok(());
    }
    let report =
        rt.block_on(run(&BenchOptions { fleet, duration, scenario, workers: usize::from(workers), router_down_at }))?;
    print(&report);
    write_json(json.as_deref(), &report)
}

/// `--json FILE`: the report, pretty-printed.
fn write_json(path: Option<&std::path::Path>, report: &impl Serialize) -> Result<()> {
    if let Some(path) = path {
        std::fs::write(path, serde_json::to_string_pretty(report)?)?;
    }
    Ok(())
}
