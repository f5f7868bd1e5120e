//! `spwi-sim demo`: the simulated world and N real agents (the `spwi-agent` daemon
//! code, each with its own Zenoh session) in one process, peers on loopback, plus an
//! observer that shows, once a second, what the fleet decides against the truth, and
//! sums it up at the end. `--kill-after` / `--join-after` remove and add an agent
//! while it runs, so membership changes can be watched.

use crate::loopback::{Hub, InProcessAgent};
use crate::measures::{Agreement, LatencyMs};
use crate::service::{self, WorldOptions};
use crate::world_args::WorldArgs;
use anyhow::{anyhow, Result};
use serde::Serialize;
use spwi_agent::cli::{init_tracing, spawn_signal_handler};
use spwi_agent::config::AgentConfig;
use spwi_agent::config::LogFormat;
use spwi_core::floor::{self, StationMap};
use spwi_core::model::ModelSet;
use spwi_proto::keys::{self, Topic};
use spwi_proto::*;
use spwi_world::layout::Layout;
use spwi_world::world::Scenario;
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::sync::watch;

pub struct DemoOptions {
    pub robots: usize,
    pub scenario: Scenario,
    /// Workers on the floor (the truth describes the first).
    pub workers: usize,
    pub seed: u64,
    pub duration: Duration,
    pub kill_after: Option<Duration>,
    pub join_after: Option<Duration>,
    pub layout: Layout,
    pub agent: AgentConfig,
    /// Print the live view once a second.
    pub view: bool,
    /// Serve the live page on this address.
    pub http: Option<std::net::SocketAddr>,
    /// Told the page's bound address once it is served.
    pub on_http: Option<tokio::sync::oneshot::Sender<std::net::SocketAddr>>,
}

/// The summary printed at the end and written by `--json`.
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    pub robots: usize,
    pub ticks: u64,
    pub decisions: BTreeMap<String, u64>,
    /// Share of ticks on which every robot that decided chose the same class.
    pub agreement: f64,
    pub accuracy: Accuracy,
    /// From the world publishing a tick to a robot publishing its decision for it.
    pub latency_ms: LatencyMs,
    pub members_changes: Vec<MembersChange>,
    pub messages_per_tick: f64,
    pub bytes_per_tick: f64,
    /// True when the models are the random-weight fixtures: accuracy is then chance.
    pub fixture_models: bool,
}

#[derive(Debug, Clone, Serialize)]
pub struct Accuracy {
    /// Team decision at t against the true intent at t.
    pub t: f64,
    /// Team forecast for t+h against the true intent at t+h, mean over h = 1..H.
    pub future: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct MembersChange {
    pub at_s: f64,
    pub event: String,
    pub robot: String,
}

#[derive(Default)]
struct Observed {
    truth: BTreeMap<u64, (Station, Instant)>,
    decisions: BTreeMap<u64, BTreeMap<RobotId, (DecisionMsg, Instant)>>,
    votes: BTreeMap<RobotId, VoteMsg>,
    last_truth: Option<TruthMsg>,
    trail: std::collections::VecDeque<[f32; 2]>,
    /// The robots' latest worker estimates (tick, estimate) and every landmark they
    /// shared: the team's track and station map, as any robot of the team holds them.
    estimates: BTreeMap<RobotId, (u64, WorkerEstimate)>,
    station_map: StationMap,
    messages: u64,
    bytes: u64,
}

/// What the live page shows, sent to it as JSON a few times a second.
#[derive(Serialize)]
struct PageState {
    tick: u64,
    scenario: u8,
    fixture_models: bool,
    worker: [f32; 2],
    trail: Vec<[f32; 2]>,
    truth: Station,
    /// The team's fused worker track (position, velocity, position sigma in m).
    team_track: Option<PageTrack>,
    /// Where the team has mapped each station (class order).
    stations: [Option<[f32; 2]>; NUM_CLASSES],
    robots: Vec<PageRobot>,
    decision: Option<Vec<Station>>,
    accuracy: f64,
    agreement: f64,
    series: Vec<SeriesPoint>,
}

#[derive(Serialize)]
struct PageRobot {
    robot: RobotId,
    position: [f32; 2],
    heading: f32,
    vote: Option<PageVote>,
}

#[derive(Serialize)]
struct PageTrack {
    position: [f32; 2],
    velocity: [f32; 2],
    sigma: f32,
}

/// A robot's latest vote as the live views show it.
#[derive(Serialize, Debug, PartialEq)]
struct PageVote {
    class: Station,
    confidence: f32,
    visibility: u32,
    /// Ticks between this vote and the tick the team last decided: 0 is a ballot of
    /// this tick; more means the robot did not vote this tick and this is its last.
    age_ticks: u64,
}

/// Votes older than this (ticks) are not shown at all.
const SHOWN_VOTE_AGE: u64 = 50;

/// `robot`'s last vote as seen at `current` (the tick the team last decided), or `None`
/// when it has not voted for [`SHOWN_VOTE_AGE`] ticks.
fn shown_vote(o: &Observed, robot: &RobotId, current: u64) -> Option<PageVote> {
    let v = o.votes.get(robot).filter(|v| v.tick + SHOWN_VOTE_AGE >= current)?;
    Some(PageVote {
        class: v.steps[0].class,
        confidence: v.steps[0].confidence,
        visibility: v.visibility,
        age_ticks: current.saturating_sub(v.tick),
    })
}

/// The tick the team last decided (the views' "this tick"), or the last truth's.
fn current_tick(o: &Observed) -> Option<u64> {
    o.decisions.keys().next_back().or(o.last_truth.as_ref().map(|t| &t.tick)).copied()
}

/// The terminal's line for one robot.
fn vote_line(robot: &RobotId, vote: Option<&PageVote>) -> String {
    match vote {
        Some(v) if v.age_ticks == 0 => {
            format!("   {robot:<10} votes {:<14} conf {:.2}  sees {}", v.class.name(), v.confidence, v.visibility)
        }
        Some(v) => format!(
            "   {robot:<10} no vote this tick (last: {}, {:.1} s ago)",
            v.class,
            v.age_ticks as f64 * TICK_PERIOD.as_secs_f64()
        ),
        None => format!("   {robot:<10} no vote"),
    }
}

#[derive(Serialize, Clone)]
struct SeriesPoint {
    accuracy: f64,
    agreement: f64,
}

fn page_state(o: &Observed, summary: &Summary, scenario: u8, series: &[SeriesPoint]) -> Option<PageState> {
    let t = o.last_truth.as_ref()?;
    let decision = o
        .decisions
        .iter()
        .next_back()
        .and_then(|(_, by)| by.values().next())
        .map(|(d, _)| d.steps.iter().map(|s| s.class).collect());
    let fresh = o.estimates.values().filter(|(tick, _)| tick + 2 >= t.tick).map(|(_, e)| e);
    let current = current_tick(o).unwrap_or(t.tick);
    let team_track = floor::fuse(fresh).map(|e| PageTrack {
        position: e.position,
        velocity: e.velocity,
        sigma: e.covariance[0].sqrt(),
    });
    Some(PageState {
        tick: t.tick,
        scenario,
        fixture_models: summary.fixture_models,
        worker: t.worker_position,
        trail: o.trail.iter().copied().collect(),
        truth: t.intent,
        team_track,
        stations: o.station_map.stations(),
        robots: t
            .robots
            .iter()
            .map(|r| PageRobot {
                robot: r.robot.clone(),
                position: r.position,
                heading: r.heading,
                vote: shown_vote(o, &r.robot, current),
            })
            .collect(),
        decision,
        accuracy: summary.accuracy.t,
        agreement: summary.agreement,
        series: series.to_vec(),
    })
}

fn summarise(o: &Observed, robots: usize, changes: &[MembersChange], fixture: bool) -> Summary {
    let mut decisions: BTreeMap<String, u64> = BTreeMap::new();
    let mut agreement = Agreement::default();
    let (mut correct, mut judged, mut fut_ok, mut fut_n) = (0u64, 0u64, 0u64, 0u64);
    let mut latencies = Vec::new();
    for (tick, by) in &o.decisions {
        for (r, (_, at)) in by {
            *decisions.entry(r.to_string()).or_default() += 1;
            if let Some((_, t0)) = o.truth.get(tick) {
                latencies.push(at.saturating_duration_since(*t0).as_secs_f64() * 1e3);
            }
        }
        agreement.tick(by.values().map(|(d, _)| d.steps.first().map(|s| s.class)));
        // the team's answer: the first robot's decision (they agree on nearly every tick)
        let Some((d, _)) = by.values().next() else { continue };
        if let (Some(step), Some((truth, _))) = (d.steps.first(), o.truth.get(tick)) {
            judged += 1;
            correct += u64::from(step.class == *truth);
        }
        for (h, s) in d.steps.iter().enumerate().skip(1) {
            if let Some((truth, _)) = o.truth.get(&(tick + h as u64)) {
                fut_n += 1;
                fut_ok += u64::from(s.class == *truth);
            }
        }
    }
    let ticks = o.truth.len().max(1) as f64;
    let ratio = |a: u64, b: u64| if b == 0 { 0.0 } else { a as f64 / b as f64 };
    Summary {
        robots,
        ticks: o.truth.len() as u64,
        decisions,
        agreement: agreement.share(),
        accuracy: Accuracy { t: ratio(correct, judged), future: ratio(fut_ok, fut_n) },
        latency_ms: LatencyMs::of(latencies),
        members_changes: changes.to_vec(),
        messages_per_tick: o.messages as f64 / ticks,
        bytes_per_tick: o.bytes as f64 / ticks,
        fixture_models: fixture,
    }
}

fn view(o: &Observed, elapsed: Duration, members: &[RobotId], summary: &Summary) {
    let Some((&tick, &(truth, _))) = o.truth.iter().next_back() else { return };
    println!("── t = {:>5.1} s  tick {tick}  members {}", elapsed.as_secs_f64(), members.len());
    let current = current_tick(o).unwrap_or(tick);
    for r in members {
        println!("{}", vote_line(r, shown_vote(o, r, current).as_ref()));
    }
    let decided = o.decisions.iter().rev().find_map(|(t, by)| by.values().next().map(|(d, _)| (*t, d.clone())));
    if let Some((t, d)) = decided {
        let forecast: Vec<&str> = d.steps.iter().skip(1).step_by(5).map(|s| s.class.name()).collect();
        let now = d.steps.first().map_or("(nobody sees the worker)", |s| s.class.name());
        println!("   team decision (tick {t}): {now}   forecast every 0.5 s: {}", forecast.join(" → "));
    }
    println!("   truth: heading to {truth}");
    println!(
        "   running accuracy at t {:.0}%, over the horizon {:.0}%, agreement {:.1}%",
        summary.accuracy.t * 100.0,
        summary.accuracy.future * 100.0,
        summary.agreement * 100.0
    );
}

fn robot_id(i: usize) -> Result<RobotId> {
    Ok(RobotId::new(format!("robot{i}"))?)
}

/// Runs the demo and returns its summary.
pub async fn run(mut opts: DemoOptions, models: Arc<ModelSet>, mut stop: watch::Receiver<bool>) -> Result<Summary> {
    let (web_stop, web_rx) = watch::channel(false);
    let mut web = None;
    if let Some(addr) = opts.http {
        let w = crate::demo_web::Web::new(serde_json::to_string(&opts.layout)?);
        let (bound, serving) = crate::demo_web::serve(addr, w.clone(), web_rx).await?;
        tokio::spawn(serving);
        println!("live view: http://{bound}/");
        if let Some(tx) = opts.on_http.take() {
            let _ = tx.send(bound);
        }
        web = Some(w);
    }
    let hub = Hub::start("demo").await?;
    let fleet = hub.fleet.clone();
    let observed = Arc::new(Mutex::new(Observed::default()));
    let o = observed.clone();
    let f = fleet.clone();
    let _all = hub
        .session
        .declare_subscriber(keys::everything(&fleet))
        .callback(move |s| {
            let key = s.key_expr().as_str().to_owned();
            let bytes = s.payload().to_bytes();
            let mut o = o.lock().expect("observer lock");
            o.messages += 1;
            o.bytes += bytes.len() as u64;
            if key == keys::truth(&f) {
                if let Ok(t) = decode::<TruthMsg>(&bytes) {
                    o.truth.insert(t.tick, (t.intent, Instant::now()));
                    o.trail.push_back(t.worker_position);
                    if o.trail.len() > 100 {
                        o.trail.pop_front();
                    }
                    o.last_truth = Some(t);
                }
            } else if let Some((robot, topic)) = keys::parse_robot_topic(&f, &key) {
                match topic {
                    Topic::Decision => {
                        if let Ok(d) = decode_from::<DecisionMsg>(&bytes, &robot) {
                            o.decisions.entry(d.tick).or_default().insert(robot, (d, Instant::now()));
                        }
                    }
                    Topic::Embedding => {
                        if let Ok(e) = decode_from::<EmbeddingMsg>(&bytes, &robot) {
                            for l in &e.landmarks {
                                o.station_map.add(l, e.tick);
                            }
                            if let Some(w) = e.worker {
                                o.estimates.insert(robot, (e.tick, w));
                            }
                        }
                    }
                    Topic::Vote => {
                        if let Ok(v) = decode_from::<VoteMsg>(&bytes, &robot) {
                            o.votes.insert(robot, v);
                        }
                    }
                    _ => {}
                }
            }
        })
        .await
        .map_err(|e| anyhow!(e))?;

    let mut agents = Vec::new();
    for i in 0..opts.robots {
        agents.push(InProcessAgent::start(&hub, &robot_id(i)?, &models, opts.agent.clone()).await?);
    }
    let (world_stop, world_rx) = watch::channel(false);
    let world = tokio::spawn(service::run(
        WorldOptions {
            fleet: fleet.clone(),
            workers: opts.workers,
            scenario: opts.scenario,
            seed: opts.seed,
            layout: opts.layout.clone(),
            zenoh: hub.peer_config()?,
            credentials: None,
            stuck_slot: None,
        },
        world_rx,
    ));

    let started = Instant::now();
    let mut changes = Vec::new();
    let (mut killed, mut joined) = (false, false);
    let mut next_id = opts.robots;
    // Five beats a second: the page moves smoothly, the terminal view prints every fifth.
    let mut beat = tokio::time::interval(Duration::from_millis(200));
    beat.tick().await;
    let mut beats = 0u64;
    let mut series: Vec<SeriesPoint> = Vec::new();
    while started.elapsed() < opts.duration {
        tokio::select! {
            _ = stop.changed() => break,
            _ = beat.tick() => {}
        }
        beats += 1;
        let elapsed = started.elapsed();
        if opts.kill_after.is_some_and(|k| elapsed >= k) && !killed && agents.len() > 1 {
            killed = true;
            let agent = agents.pop().expect("an agent");
            let robot = agent.robot.to_string();
            if let Err(e) = agent.stop().await {
                tracing::warn!("{robot} left uncleanly: {e:#}");
            }
            changes.push(MembersChange { at_s: elapsed.as_secs_f64(), event: "left".into(), robot });
        }
        if opts.join_after.is_some_and(|j| elapsed >= j) && !joined {
            joined = true;
            let a = InProcessAgent::start(&hub, &robot_id(next_id)?, &models, opts.agent.clone()).await?;
            next_id += 1;
            changes.push(MembersChange {
                at_s: elapsed.as_secs_f64(),
                event: "joined".into(),
                robot: a.robot.to_string(),
            });
            agents.push(a);
        }
        // One summary per beat, shared by the page and the terminal view.
        let second = beats.is_multiple_of(5);
        if web.is_some() || (opts.view && second) {
            let o = observed.lock().expect("observer lock");
            let summary = summarise(&o, opts.robots, &changes, models.manifest.fixture);
            if let Some(web) = &web {
                if second {
                    series.push(SeriesPoint { accuracy: summary.accuracy.t, agreement: summary.agreement });
                    if series.len() > 300 {
                        series.remove(0);
                    }
                }
                if let Some(state) = page_state(&o, &summary, opts.scenario as u8, &series) {
                    web.publish(serde_json::to_string(&state)?);
                }
            }
            if opts.view && second {
                let members: Vec<RobotId> = agents.iter().map(|a| a.robot.clone()).collect();
                view(&o, elapsed, &members, &summary);
            }
        }
    }
    let _ = web_stop.send(true);

    let _ = world_stop.send(true);
    let _ = world.await;
    for agent in agents {
        let robot = agent.robot.to_string();
        if let Err(e) = agent.stop().await {
            tracing::warn!("{robot} left uncleanly: {e:#}");
        }
    }
    drop(_all);
    let _ = hub.session.close().await;
    let o = observed.lock().expect("observer lock");
    Ok(summarise(&o, opts.robots, &changes, models.manifest.fixture))
}

/// The arguments of `spwi-sim demo`.
#[derive(clap::Args, Debug)]
pub struct DemoArgs {
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u64).range(1..=8))]
    pub robots: u64,
    #[command(flatten)]
    pub world: WorldArgs,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// How long to run (e.g. 60s, 2m).
    #[arg(long, default_value = "60s", value_parser = crate::durations::parse_duration)]
    pub duration: Duration,
    /// Stop one agent after this long, to watch the fleet shrink.
    #[arg(long, value_parser = crate::durations::parse_duration)]
    pub kill_after: Option<Duration>,
    /// Start one more agent after this long, to watch it join.
    #[arg(long, value_parser = crate::durations::parse_duration)]
    pub join_after: Option<Duration>,
    /// Model set folder (default: the agent's default).
    #[arg(long)]
    pub models: Option<PathBuf>,
    /// Write the summary as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// No live view, only the summary.
    #[arg(long)]
    pub quiet: bool,
    /// Serve a live page (floor map, votes, decision, accuracy) on this address.
    #[arg(long, value_name = "ADDR")]
    pub http: Option<std::net::SocketAddr>,
}

/// `spwi-sim demo`: parses nothing more, runs the tool.
pub fn main(a: DemoArgs) -> Result<()> {
    let DemoArgs { robots, world, seed, duration, kill_after, join_after, models, json, quiet, http } = a;
    init_tracing(LogFormat::Human);
    let mut agent = spwi_agent::config::AgentConfig::load(None)?;
    if let Some(m) = models {
        agent.models.dir = Some(m);
    }
    let set = spwi_agent::daemon::load_models(&agent)?;
    let opts = crate::demo::DemoOptions {
        robots: robots as usize,
        scenario: world.scenario,
        workers: usize::from(world.workers),
        seed,
        duration,
        kill_after,
        join_after,
        layout: world.floor()?.layout,
        agent,
        view: !quiet,
        http,
        on_http: None,
    };
    let rt = tokio::runtime::Builder::new_multi_thread().enable_all().build()?;
    let summary = rt.block_on(async {
        let (tx, rx) = tokio::sync::watch::channel(false);
        spawn_signal_handler(tx);
        crate::demo::run(opts, set, rx).await
    })?;
    println!("\n{}", serde_json::to_string_pretty(&summary)?);
    if let Some(path) = json {
        std::fs::write(&path, serde_json::to_string_pretty(&summary)?)
            .map_err(|e| anyhow::anyhow!("--json {}: {e}", path.display()))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_robot_that_did_not_vote_this_tick_is_shown_with_its_last_vote_and_its_age() {
        let (fresh, quiet, gone) =
            (RobotId::new("r1").unwrap(), RobotId::new("r2").unwrap(), RobotId::new("r3").unwrap());
        let vote = |robot: &RobotId, tick: u64, class: Station| VoteMsg {
            robot: robot.clone(),
            instance: 1,
            tick,
            steps: vec![StepVote { class, confidence: 0.8 }],
            visibility: 2,
            worker: None,
            quality: 1.0,
            signature: Vec::new(),
        };
        let mut o = Observed::default();
        for v in [
            vote(&fresh, 100, Station::Assembly),
            vote(&quiet, 93, Station::Workstation),
            vote(&gone, 100 - SHOWN_VOTE_AGE - 1, Station::Storage),
        ] {
            o.votes.insert(v.robot.clone(), v);
        }
        let decision = DecisionMsg {
            robot: fresh.clone(),
            instance: 1,
            tick: 100,
            steps: vec![TeamStep { class: Station::Assembly, score: 1.0 }],
            voters: vec![fresh.clone()],
            live_members: 3,
            decided_by: DecidedBy::AllVoted,
            digest: 0,
        };
        o.decisions.entry(100).or_default().insert(fresh.clone(), (decision, Instant::now()));
        let now = current_tick(&o).unwrap();
        assert_eq!(now, 100);
        assert_eq!(shown_vote(&o, &fresh, now).map(|v| v.age_ticks), Some(0));
        assert_eq!(shown_vote(&o, &quiet, now).map(|v| v.age_ticks), Some(7));
        assert_eq!(shown_vote(&o, &gone, now), None, "too old to show");
        assert!(vote_line(&fresh, shown_vote(&o, &fresh, now).as_ref()).contains("votes assembly"));
        let line = vote_line(&quiet, shown_vote(&o, &quiet, now).as_ref());
        assert!(line.contains("no vote this tick (last: workstation, 0.7 s ago)"), "{line}");
        assert!(vote_line(&gone, None).ends_with("no vote"));
    }
}
