//! `spwi-sim eval`: the paper's tables from held-out simulated episodes, computed by the
//! daemon's own decision engine — N `Engine`s on a virtual clock behind an in-memory
//! bus with the fault model — plus the ego-GRU and the two baselines beside them, and
//! the fault studies.
//!
//! - `bus.rs`: the engines' network (delay, loss, leaving robots), deadlines as polls;
//! - `observers.rs`: the ego-GRU and the baselines; `cvm.rs`: the constant-velocity model;
//! - `fleet.rs`: one episode — the world's frames in, the engines' votes and decisions scored;
//!   `identity.rs`: whether the robots name each worker alike and keep the name;
//! - `score.rs`: tallies, accuracies and their intervals; `studies.rs`: the runs of `--all`;
//!   `page.rs`: docs/RESULTS.md from them, `figures.rs`: how a figure reads there,
//!   `reading.rs`: that page's reading of the targets and of what bounds them;
//! - `command.rs`: the command line of `spwi-sim eval`;
//!   `plots.rs`: the PNG figures of `--plots`.
//!
//! Held-out honesty: the episode seeds evaluated are checked against the training
//! episodes recorded in the model set's manifest, and refused if any is shared.
//!
//! Statistics: episodes are independent draws, ticks of one episode are not, so every
//! figure carries a 95 % bootstrap interval from resampling whole episodes
//! ([`score::estimate`]). Episodes run on every core; the figures do not depend on how
//! many (each episode's randomness is its own, and the tallies are pooled in order).

pub mod bus;
pub mod command;
pub mod cvm;
mod figures;
pub mod fleet;
pub mod identity;
pub mod observers;
pub mod page;
pub mod planner;
pub mod plots;
pub mod reading;
pub mod score;
pub mod scored;
pub mod studies;

use crate::episodes::episode_seed;
use anyhow::{bail, Context, Result};
use score::{estimate, Accuracy, Confusion, Tally};
pub use scored::Scored;
use serde::Serialize;
use spwi_core::manifest::Manifest;
use spwi_core::model::ModelSet;
use spwi_core::settings::TickConfig;
use spwi_proto::Station;
use spwi_world::generate::NamedLayout;
use spwi_world::layout::CameraPolicy;
use spwi_world::world::Scenario;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

/// Default evaluation seed: far from the training seeds (10 N + scenario).
pub const DEFAULT_SEED: u64 = 1000;
/// Episodes per configuration by default: ±2-3 points at 95 % on one configuration.
pub const DEFAULT_EPISODES: u32 = 300;

/// What goes wrong in the fleet during an evaluation.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Faults {
    /// Robots (the highest slots) that leave half-way through every episode.
    pub dropouts: usize,
    /// Probability that any one message between two robots is lost.
    pub loss: f64,
    /// Mean delay of a message between two robots, ms (loopback-like 0.5 ms when
    /// smaller; every message takes this plus up to as much again).
    pub delay_ms: f64,
    /// Robots (the lowest slots) whose camera is stuck on an old frame that shows the
    /// worker: confident, plausible, wrong.
    pub faulty: usize,
    /// Robots (the slots after the stuck ones) whose camera loops an old clip of the
    /// worker: every frame changes, none is true.
    pub looping: usize,
    /// Robots (the slots after the lying cameras) that vote a wrong station for every
    /// step of every tick at confidence 1, claiming a full view of the worker and as
    /// many detections as a frame may hold: a member whose certificate is valid and
    /// whose word is false. Its own decisions are not scored.
    #[serde(default)]
    pub liars: usize,
    /// How far off the floor pose of one robot (the slot after the liars) is, metres
    /// (0: none): its localiser is wrong, so are its worker estimates and landmarks.
    #[serde(default)]
    pub pose_error_m: f64,
    /// How far the clock of one robot (the highest slot) runs ahead of the others', ms
    /// (negative: behind).
    #[serde(default)]
    pub clock_offset_ms: i64,
}

impl Faults {
    /// A fleet where nothing goes wrong.
    pub fn none() -> Faults {
        Faults::default()
    }

    /// Robots whose camera lies (stuck or looping): the lowest slots.
    pub fn lying(&self) -> usize {
        self.faulty + self.looping
    }

    /// Robots that lie, by camera, by vote or by pose: the lowest slots.
    pub fn untrue(&self) -> usize {
        self.lying() + self.liars + usize::from(self.pose_error_m > 0.0)
    }

    /// The slots of the robots that vote falsely.
    pub fn liar_slots(&self) -> std::ops::Range<usize> {
        self.lying()..self.lying() + self.liars
    }

    /// The slot of the robot whose pose is off, if one is.
    pub fn pose_error_slot(&self) -> Option<usize> {
        (self.pose_error_m > 0.0).then(|| self.lying() + self.liars)
    }
}

pub struct EvalOptions {
    pub scenario: Scenario,
    /// Workers on the floor (the first is scored).
    pub workers: usize,
    pub robots: usize,
    pub models: Arc<ModelSet>,
    /// Episode e runs on floor e mod floors.len().
    pub floors: Vec<NamedLayout>,
    /// How the floors were named (`factory.toml (built in)`, `heldout:0..50`, a file).
    pub floors_name: String,
    pub episodes: u32,
    pub seed: u64,
    /// Ticks per episode (10 per second).
    pub ticks: u32,
    pub faults: Faults,
    /// The robots' `[tick]` settings (relay, stale feeds, deadlines): the daemon's
    /// defaults unless an agent config says otherwise.
    pub tick: TickConfig,
    /// Ticks the fleet worked on the floor before each episode, building its station
    /// maps (0: they start empty). See `team_floor`.
    pub warm_map_ticks: u32,
    /// Give each robot the floor's plan, each station displaced by up to this many
    /// metres (`None`: no plan, the stations mapped from detections alone).
    pub plan_error_m: Option<f32>,
    /// Score the 1D-CNN baseline too (when the set ships one). `--all` asks for it only
    /// in the tables that show it: elsewhere it was a quarter of the run's time.
    pub cnn1d: bool,
}

#[derive(Debug, Clone, Serialize)]
pub struct PerRobot {
    pub robot: String,
    /// The mean trust its votes carried (its agreement with the others' decisions).
    pub trust: Option<f64>,
    pub gnn: f64,
    pub ego: Accuracy,
    pub collective: Accuracy,
}

/// Every figure of one evaluation; `--json` writes it as is.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    #[serde(serialize_with = "scenario_number")]
    pub scenario: Scenario,
    pub robots: usize,
    pub window: usize,
    pub frames: usize,
    pub horizon: usize,
    pub episodes: u32,
    pub ticks_per_episode: u32,
    pub seed: u64,
    pub model_set: String,
    pub floors: String,
    /// The camera policy of every floor, when they share one.
    pub cameras: Option<CameraPolicy>,
    pub faults: Faults,
    pub tick: TickConfig,
    /// Seconds the fleet worked on each floor before an episode (its maps warm).
    pub warm_map_s: f64,
    /// The robots had the floor's plan, each station up to this far off (m).
    pub floor_plan_error_m: Option<f32>,
    /// gnn (t only), ego, collective, consensus (collective votes + consensus, on the
    /// ticks some robot decided), team_all_ticks (the same decision over every tick, no
    /// decision counting as wrong), cvm, cnn1d. Each model is scored on the ticks where
    /// it predicts: a robot's models when it sees the worker.
    pub models: BTreeMap<Scored, Accuracy>,
    /// The same models on the ticks where the worker heads to a station of a close
    /// pair (work spots within 3.5 m); absent when no floor has one.
    pub close_pair: BTreeMap<Scored, Accuracy>,
    /// The collective, the ego and the CVM by where the tick falls in the worker's
    /// cycle: at work, or walking so long after committing to its goal.
    pub by_phase: Vec<PhaseAccuracy>,
    /// The same on the long walks (after 2 s), by what the straight line to the goal
    /// crosses (`fleet::Route`); `phase` names the route, `share` is of the long walks.
    pub long_walks: Vec<PhaseAccuracy>,
    pub per_robot: Vec<PerRobot>,
    /// Share of decided ticks on which every live robot decided the same class for t.
    pub agreement: f64,
    /// Whether the robots name each worker alike and keep the name ([`identity`]).
    pub identity: identity::Identity,
    /// Share of ticks on which the team had a decision (some robot saw the worker or,
    /// with a relation set, still tracked it).
    pub coverage: f64,
    /// Share of ticks on which some robot voted but the team decided no class; and the
    /// share of robot-ticks its lone-voter rule, and its doubt of every voter, left
    /// without a class (the engines' own counts).
    pub voted_undecided: f64,
    pub lone_stranger: f64,
    pub doubted_only: f64,
    /// Messages each robot published per tick (embedding, vote, relayed ballots,
    /// decision), and their bytes as the codec writes them.
    pub messages_per_robot_tick: f64,
    pub bytes_per_robot_tick: f64,
    /// Rows: true class; columns: predicted class (at t).
    pub confusion: BTreeMap<Scored, Confusion>,
    /// Predictions at t scored for the collective GRU (robot-ticks seeing the worker).
    pub samples: u64,
    /// Share of those on which the goal at t was missing from the robot's team map.
    pub goal_unmapped_share: f64,
    /// Per station, how the robots' team maps placed it on those robot-ticks.
    pub map: Vec<StationPlacement>,
    pub seconds: f64,
    /// Wall time per robot frame (world, all models, consensus), microseconds.
    pub per_frame_us: f64,
}

/// The models on the ticks of one phase of the worker's cycle ([`fleet::Phase`]), or
/// of one route of its long walks ([`fleet::Route`]).
#[derive(Debug, Clone, Serialize)]
pub struct PhaseAccuracy {
    /// The phase, or for the long walks the route (`fleet::Route`).
    pub phase: &'static str,
    /// Share of the ticks it is one kind of: all ticks for a phase, the long walks' for
    /// a route.
    pub share: f64,
    /// Share of all the collective's predictions that fall in it: its errors here cost
    /// the collective's accuracy this share of them.
    pub collective_share: f64,
    pub collective: Accuracy,
    pub ego: Accuracy,
    pub cvm: Accuracy,
    /// The planning yardstick on the true work spots, and on the team's map.
    pub planner: Accuracy,
    pub planner_mapped: Accuracy,
}

/// How the robots' team maps placed one station (over the scored robot-ticks).
#[derive(Debug, Clone, Serialize)]
pub struct StationPlacement {
    pub station: &'static str,
    /// Share of robot-ticks on which the team map held it.
    pub mapped: f64,
    /// Mean distance from its true work spot where mapped (m).
    pub mean_error_m: Option<f64>,
    /// Share of its placements farther than `MapQuality::FAR_M` from the work spot.
    pub far: Option<f64>,
}

fn placements(q: &fleet::MapQuality) -> Vec<StationPlacement> {
    Station::ALL
        .map(|s| {
            let (k, n) = (s.index(), q.mapped[s.index()]);
            StationPlacement {
                station: s.name(),
                mapped: n as f64 / q.robot_ticks.max(1) as f64,
                mean_error_m: (n > 0).then(|| q.error_sum[k] / n as f64),
                far: (n > 0).then(|| q.far[k] as f64 / n as f64),
            }
        })
        .to_vec()
}

/// Refuses an evaluation whose episodes include any the models were trained on.
pub fn check_held_out(manifest: &Manifest, seed: u64, episodes: u32) -> Result<()> {
    let Some(exports) = manifest.extra.get("dataset").and_then(|d| d.get("exports")).and_then(|e| e.as_array()) else {
        if manifest.fixture {
            return Ok(()); // random weights: nothing was trained
        }
        bail!(
            "model set {:?} records no training exports (dataset.exports in its manifest): cannot check that the evaluation is held out",
            manifest.name
        );
    };
    let mut trained = BTreeSet::new();
    for ex in exports {
        let (Some(s), Some(n)) = (ex["seed"].as_u64(), ex["episodes"].as_u64()) else {
            bail!("model set {:?}: a dataset export without seed or episodes", manifest.name);
        };
        if let Some(l) = ex["layouts"].as_str().filter(|l| l.contains("heldout:")) {
            bail!(
                "model set {:?} was trained on held-out floors ({l}): no evaluation of it is held out",
                manifest.name
            );
        }
        trained.extend((0..n as u32).map(|e| episode_seed(s, e)));
    }
    if let Some(e) = (0..episodes).find(|&e| trained.contains(&episode_seed(seed, e))) {
        bail!(
            "--seed {seed}: episode {e} (world seed {}) was used to train model set {:?}; pick another seed",
            episode_seed(seed, e),
            manifest.name
        );
    }
    Ok(())
}

/// Runs one evaluation.
pub fn run(o: &EvalOptions) -> Result<Report> {
    check_held_out(&o.models.manifest, o.seed, o.episodes)?;
    if o.floors.is_empty() {
        bail!("no floor to evaluate on");
    }
    let started = Instant::now();
    let episodes = run_episodes(o)?;
    let seconds = started.elapsed().as_secs_f64();
    let mut all = fleet::Tallies::default();
    episodes.iter().for_each(|e| all.merge(e));
    let of = |f: &dyn Fn(&fleet::Tallies) -> &Tally| estimate(&episodes.iter().map(|e| *f(e)).collect::<Vec<_>>());
    let m = &o.models.manifest;
    let mut models = BTreeMap::new();
    models.insert(Scored::Gnn, of(&|e| &e.gnn));
    models.insert(Scored::Ego, of(&|e| &e.ego));
    models.insert(Scored::Collective, of(&|e| &e.collective));
    models.insert(Scored::HealthyCollective, of(&|e| &e.healthy_collective));
    models.insert(Scored::Consensus, of(&|e| &e.consensus));
    models.insert(Scored::ConsensusSettled, of(&|e| &e.consensus_settled));
    models.insert(Scored::TeamAllTicks, of(&|e| &e.team_all_ticks));
    models.insert(Scored::Cvm, of(&|e| &e.cvm));
    models.insert(Scored::CvmMapped, of(&|e| &e.cvm_mapped));
    models.insert(Scored::Planner, of(&|e| &e.planner));
    models.insert(Scored::PlannerMapped, of(&|e| &e.planner_mapped));
    models.insert(Scored::CollectiveGoalUnmapped, of(&|e| &e.collective_goal_unmapped));
    models.insert(Scored::CollectivePaired, of(&|e| &e.paired_collective));
    models.insert(Scored::ConsensusPaired, of(&|e| &e.paired_consensus));
    if o.cnn1d && m.models.cnn1d.is_some() {
        models.insert(Scored::Cnn1d, of(&|e| &e.cnn1d));
    }
    let mut close_pair = BTreeMap::new();
    if all.close_pair.team_all_ticks.samples() > 0 {
        close_pair.insert(Scored::Ego, of(&|e| &e.close_pair.ego));
        close_pair.insert(Scored::Collective, of(&|e| &e.close_pair.collective));
        close_pair.insert(Scored::Consensus, of(&|e| &e.close_pair.consensus));
        close_pair.insert(Scored::TeamAllTicks, of(&|e| &e.close_pair.team_all_ticks));
        close_pair.insert(Scored::Cvm, of(&|e| &e.close_pair.cvm));
        close_pair.insert(Scored::CollectiveFarther, of(&|e| &e.close_pair.farther_collective));
        close_pair.insert(Scored::CvmFarther, of(&|e| &e.close_pair.farther_cvm));
    }
    // Ticks of one kind (`pick` finds its tallies among an episode's), `share` of `of_ticks`.
    let kind =
        |name: &'static str, of_ticks: u64, pick: &dyn Fn(&fleet::Tallies) -> &fleet::PhaseTallies| PhaseAccuracy {
            phase: name,
            share: pick(&all).ticks as f64 / of_ticks.max(1) as f64,
            collective_share: pick(&all).collective.samples() as f64 / all.collective.samples().max(1) as f64,
            collective: of(&|e| &pick(e).collective),
            ego: of(&|e| &pick(e).ego),
            cvm: of(&|e| &pick(e).cvm),
            planner: of(&|e| &pick(e).planner),
            planner_mapped: of(&|e| &pick(e).planner_mapped),
        };
    let by_phase = fleet::Phase::ALL.iter().map(|&p| kind(p.name(), all.ticks, &|e| &e.by_phase[p as usize])).collect();
    let long_walk_ticks = all.long_walks.iter().map(|l| l.ticks).sum();
    let long_walks =
        fleet::Route::ALL.iter().map(|&r| kind(r.name(), long_walk_ticks, &|e| &e.long_walks[r as usize])).collect();
    let per_robot = (0..all.per_robot.len())
        .map(|slot| {
            let model = |pick: fn(&fleet::RobotTallies) -> &Tally| of(&|e| e.per_robot.get(slot).map_or(&EMPTY, pick));
            let (sum, votes) = all.vote_trust.get(slot).copied().unwrap_or_default();
            let trust = (votes > 0).then(|| sum / votes as f64);
            PerRobot {
                robot: format!("r{slot}"),
                trust,
                gnn: model(|r| &r.gnn).t,
                ego: model(|r| &r.ego),
                collective: model(|r| &r.collective),
            }
        })
        .collect();
    Ok(Report {
        scenario: o.scenario,
        robots: o.robots,
        window: m.window,
        frames: m.frames(),
        horizon: m.horizon,
        episodes: o.episodes,
        ticks_per_episode: o.ticks,
        seed: o.seed,
        model_set: m.name.clone(),
        floors: o.floors_name.clone(),
        cameras: shared_camera_policy(&o.floors),
        faults: o.faults.clone(),
        tick: o.tick.clone(),
        warm_map_s: f64::from(o.warm_map_ticks) / f64::from(spwi_proto::TICKS_PER_SECOND),
        floor_plan_error_m: o.plan_error_m,
        models,
        close_pair,
        by_phase,
        long_walks,
        per_robot,
        agreement: all.agreement.share(),
        identity: identity::Identity::of(&all.identity),
        coverage: all.decided_ticks as f64 / all.ticks.max(1) as f64,
        voted_undecided: all.voted_undecided_ticks as f64 / all.ticks.max(1) as f64,
        lone_stranger: all.lone_stranger_robot_ticks as f64 / (all.ticks * o.robots as u64).max(1) as f64,
        doubted_only: all.doubted_only_robot_ticks as f64 / (all.ticks * o.robots as u64).max(1) as f64,
        messages_per_robot_tick: all.messages as f64 / all.frames.max(1) as f64,
        bytes_per_robot_tick: all.bytes as f64 / all.frames.max(1) as f64,
        confusion: BTreeMap::from([(Scored::Ego, all.confusion_ego), (Scored::Collective, all.confusion_collective)]),
        samples: all.collective.samples(),
        goal_unmapped_share: all.collective_goal_unmapped.samples() as f64 / all.collective.samples().max(1) as f64,
        map: placements(&all.map),
        seconds,
        per_frame_us: seconds * 1e6 / all.frames.max(1) as f64,
    })
}

static EMPTY: Tally = Tally::EMPTY;

/// A scenario as the JSON names it: by its number, as the paper does.
fn scenario_number<S: serde::Serializer>(s: &Scenario, ser: S) -> Result<S::Ok, S::Error> {
    ser.serialize_u8(*s as u8)
}

/// Every episode's tallies, in episode order, computed on every core.
fn run_episodes(o: &EvalOptions) -> Result<Vec<fleet::Tallies>> {
    let workers = std::thread::available_parallelism().map_or(1, |n| n.get()).clamp(1, o.episodes.max(1) as usize);
    let progress = &crate::progress::Progress::new("episodes evaluated", u64::from(o.episodes), 0);
    let done: Vec<Result<Vec<(u32, fleet::Tallies)>>> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..workers)
            .map(|w| {
                s.spawn(move || {
                    (w as u32..o.episodes)
                        .step_by(workers)
                        .map(|e| {
                            let floor = &o.floors[e as usize % o.floors.len()];
                            let tallies = fleet::episode(o, &floor.layout, episode_seed(o.seed, e))
                                .with_context(|| format!("episode {e} on floor {}", floor.name));
                            progress.inc();
                            tallies.map(|t| (e, t))
                        })
                        .collect()
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().expect("an evaluation worker panicked")).collect()
    });
    let mut episodes = Vec::with_capacity(o.episodes as usize);
    for d in done {
        episodes.extend(d?);
    }
    episodes.sort_by_key(|(e, _)| *e);
    Ok(episodes.into_iter().map(|(_, t)| t).collect())
}

/// The model set under `root` for W, H and frames: `default` if it matches, else the
/// first set (by name) whose manifest does.
pub fn find_model_set(root: &Path, window: usize, horizon: usize, frames: Option<usize>) -> Result<PathBuf> {
    let frames = frames.unwrap_or(window);
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(root)
        .with_context(|| format!("cannot list model sets in {}", root.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.join("manifest.json").is_file())
        .collect();
    dirs.sort_by_key(|p| (p.file_name().is_none_or(|n| n != "default"), p.clone()));
    for d in &dirs {
        let text = std::fs::read_to_string(d.join("manifest.json"))?;
        let v: serde_json::Value = serde_json::from_str(&text)?;
        let w = v["window"].as_u64().unwrap_or(0) as usize;
        let f = v["frames"].as_u64().map_or(w, |f| f as usize);
        if w == window && f == frames && v["horizon"].as_u64() == Some(horizon as u64) && v["fixture"] != true {
            return Ok(d.clone());
        }
    }
    bail!(
        "no trained model set in {} has window {window}, {frames} frames and horizon {horizon} (models/train.sh builds them)",
        root.display()
    )
}

/// The camera policy all of `floors` share, if they do.
fn shared_camera_policy(floors: &[NamedLayout]) -> Option<CameraPolicy> {
    let first = floors.first()?.layout.camera.policy;
    floors.iter().all(|f| f.layout.camera.policy == first).then_some(first)
}

/// The human-readable summary of one report.
pub fn print(r: &Report) {
    let pct = |v: f64| format!("{:5.1}", 100.0 * v);
    println!(
        "scenario {} · {} robots · {} ticks ({} frames) → {} ahead · model set {} · floors {} · {} episodes × {} ticks, seed {}",
        r.scenario as u8,
        r.robots,
        r.window,
        r.frames,
        r.horizon,
        r.model_set,
        r.floors,
        r.episodes,
        r.ticks_per_episode,
        r.seed
    );
    if let Some(e) = r.floor_plan_error_m {
        println!("floor plan: every robot had the floor's plan, each station up to {e} m off");
    }
    if r.warm_map_s > 0.0 {
        println!("station maps warm: the fleet worked {} s on each floor before each episode", r.warm_map_s);
    }
    if r.faults != Faults::default() {
        println!(
            "faults: {} dropping out half-way, {:.0}% messages lost, {} stuck and {} looping cameras, {} liars, one pose {} m off, one clock {} ms off, {} ms delay",
            r.faults.dropouts,
            100.0 * r.faults.loss,
            r.faults.faulty,
            r.faults.looping,
            r.faults.liars,
            r.faults.pose_error_m,
            r.faults.clock_offset_ms,
            r.faults.delay_ms
        );
    }
    let ci = |a: &Accuracy| format!("{} [{}–{}]", pct(a.t), pct(a.t_ci95[0]), pct(a.t_ci95[1]));
    let ci_future = |a: &Accuracy| match (a.future, a.future_ci95) {
        (Some(f), Some([lo, hi])) => format!("{} [{}–{}]", pct(f), pct(lo), pct(hi)),
        _ => "–".into(),
    };
    println!("  {:<15} {:>21} {:>21}   (95 % CI by episode)", "model", "at t %", "t+1..H %");
    let extra =
        [Scored::ConsensusSettled, Scored::CollectiveGoalUnmapped, Scored::CollectivePaired, Scored::ConsensusPaired];
    for name in Scored::LISTED.into_iter().chain(extra) {
        if let Some(a) = r.models.get(&name) {
            println!("  {:<15} {:>21} {:>21}", name, ci(a), ci_future(a));
        }
    }
    println!("  goal at t missing from the team's map on {} of the collective's ticks", pct(r.goal_unmapped_share));
    for p in &r.map {
        println!(
            "  map: {:<14} on the team map {:>5}% of robot-ticks · {} m from its work spot on average · {}% > {} m off",
            p.station,
            pct(p.mapped),
            p.mean_error_m.map_or("–".into(), |e| format!("{e:.2}")),
            p.far.map_or("–".into(), pct),
            fleet::MapQuality::FAR_M
        );
    }
    if !r.close_pair.is_empty() {
        println!("  heading to a station of a close pair:");
        for (name, a) in &r.close_pair {
            println!("    {:<13} {:>21} {:>21}", name, ci(a), ci_future(a));
        }
    }
    // One line per kind of tick: its share, then the collective, the ego, the CVM and the
    // planner (on the true spots, on the team's map) at t.
    let print_kinds = |kinds: &[PhaseAccuracy]| {
        for p in kinds {
            println!(
                "    {:<33} {:>5}% {:>21} {:>21} {:>21} {:>21} {:>21}",
                p.phase,
                pct(p.share),
                ci(&p.collective),
                ci(&p.ego),
                ci(&p.cvm),
                ci(&p.planner),
                ci(&p.planner_mapped)
            );
        }
    };
    println!("  by phase of the worker's cycle (share of ticks · collective · ego · CVM · planner · planner on the team's map, at t):");
    print_kinds(&r.by_phase);
    println!(
        "  the long walks by what the straight line to the goal crosses (share of them · collective · ego · CVM · planner · planner on the team's map):"
    );
    print_kinds(&r.long_walks);
    for p in &r.per_robot {
        println!(
            "  robot {:<4} trust {} · gnn {} · ego {} / {} · collective {} / {}",
            p.robot,
            p.trust.map_or("–".into(), |t| format!("{t:.2}")),
            pct(p.gnn),
            pct(p.ego.t),
            pct(p.ego.future.unwrap_or(0.0)),
            pct(p.collective.t),
            pct(p.collective.future.unwrap_or(0.0))
        );
    }
    println!(
        "  agreement {:.1}% · coverage {:.1}% · {:.2} messages, {:.0} bytes per robot tick · {} scored predictions · {:.1} s ({:.0} µs per robot frame)",
        100.0 * r.agreement,
        100.0 * r.coverage,
        r.messages_per_robot_tick,
        r.bytes_per_robot_tick,
        r.samples,
        r.seconds,
        r.per_frame_us
    );
    let id = &r.identity;
    println!(
        "  identity: the team's id for a worker switched {:.2} times per worker-minute ({:.2} per robot-minute); one id on {:.1}% of the worker-ticks two robots or more named ({:.1}% named)",
        id.switches_per_worker_minute,
        id.robot_switches_per_minute,
        100.0 * id.same_id,
        100.0 * id.named
    );
    println!(
        "  without a class though someone voted: {:.1}% of ticks (left so by the lone-voter rule {:.1}%, every voter doubted {:.1}% of robot-ticks)",
        100.0 * r.voted_undecided,
        100.0 * r.lone_stranger,
        100.0 * r.doubted_only
    );
}

#[cfg(test)]
mod tests {
    use super::*;
    use spwi_core::model::Backend;

    fn fixture() -> Arc<ModelSet> {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/fixture");
        ModelSet::load(&dir, Backend::Tract, None).unwrap()
    }

    fn options(models: Arc<ModelSet>, faults: Faults) -> EvalOptions {
        EvalOptions {
            scenario: Scenario::Dynamic,
            workers: 1,
            robots: 3,
            models,
            floors: vec![NamedLayout { name: "test".into(), layout: spwi_world::layout::Layout::default_layout() }],
            floors_name: "test".into(),
            episodes: 3,
            seed: 5,
            ticks: 60,
            faults,
            tick: TickConfig::default(),
            warm_map_ticks: 0,
            plan_error_m: None,
            cnn1d: true,
        }
    }

    fn without_timings(r: &Report) -> serde_json::Value {
        let mut v = serde_json::to_value(r).unwrap();
        v["seconds"] = 0.into();
        v["per_frame_us"] = 0.into();
        v
    }

    #[test]
    fn the_same_seed_gives_the_same_figures() {
        let m = fixture();
        let faults = Faults { loss: 0.2, dropouts: 1, faulty: 1, delay_ms: 5.0, ..Faults::none() };
        let a = run(&options(m.clone(), faults.clone())).unwrap();
        let b = run(&options(m, faults)).unwrap();
        assert_eq!(without_timings(&a), without_timings(&b));
        assert!(a.samples > 0, "some robot saw the worker");
        for key in [Scored::Gnn, Scored::Ego, Scored::Collective, Scored::Consensus, Scored::Cvm] {
            let acc = a.models[&key];
            assert!((0.0..=1.0).contains(&acc.t), "{key}: {acc:?}");
        }
        assert_eq!(a.per_robot.len(), 3);
    }

    #[test]
    fn the_robots_name_two_workers_alike_and_keep_their_names() {
        // Two workers, three robots with cameras that track, 6 s each: every robot's
        // person under the team's ids, scored against where the workers truly stand.
        let mut o = EvalOptions { workers: 2, ticks: 60, ..options(fixture(), Faults::none()) };
        o.floors[0].layout.camera.policy = spwi_world::layout::CameraPolicy::Track;
        let r = run(&o).unwrap();
        let id = r.identity;
        assert!(id.named > 0.5, "the robots named the workers on few ticks: {id:?}");
        assert!(id.same_id > 0.9, "robots named one worker differently: {id:?}");
        assert!(id.switches_per_worker_minute < 3.0, "ids changed often: {id:?}");
    }

    #[test]
    fn the_paired_figures_score_the_collective_and_the_consensus_on_the_same_robot_ticks() {
        let episodes = run_episodes(&options(fixture(), Faults::none())).unwrap();
        let total: u64 = episodes.iter().map(|e| e.paired_collective.samples()).sum();
        assert!(total > 0, "some robot predicted and decided");
        for e in &episodes {
            assert_eq!(e.paired_collective.samples(), e.paired_consensus.samples(), "the same robot-ticks");
            assert!(e.paired_collective.samples() <= e.collective.samples());
            assert!(e.paired_consensus.samples() <= e.consensus.samples());
        }
    }

    #[test]
    fn the_1d_cnn_baseline_is_scored_when_asked_and_changes_no_other_figure() {
        // The default set ships the baseline (the fixture does not).
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/default");
        let set = ModelSet::load(&dir, Backend::Tract, None).unwrap();
        let with = run(&EvalOptions { episodes: 1, ..options(set.clone(), Faults::none()) }).unwrap();
        let without = run(&EvalOptions { episodes: 1, cnn1d: false, ..options(set, Faults::none()) }).unwrap();
        assert!(with.models.contains_key(&Scored::Cnn1d) && !without.models.contains_key(&Scored::Cnn1d));
        let mut with = without_timings(&with);
        with["models"].as_object_mut().unwrap().remove("cnn1d");
        assert_eq!(with, without_timings(&without));
    }

    #[test]
    fn the_team_map_places_what_the_cameras_see_near_its_work_spot() {
        // On the built-in floor the first three robots' cameras keep the assembly bench
        // in view; its place on the team map is the centre of the objects that mark it.
        let r = run(&options(fixture(), Faults::none())).unwrap();
        let assembly = &r.map[2];
        assert_eq!(assembly.station, "assembly");
        assert!(assembly.mapped > 0.5, "{assembly:?}");
        assert!(assembly.mean_error_m.unwrap() < 1.5 && assembly.far == Some(0.0), "{assembly:?}");
        assert!(r.map.iter().all(|p| (0.0..=1.0).contains(&p.mapped)), "{:?}", r.map);
    }

    #[test]
    fn a_fleet_given_the_floor_plan_has_every_station_mapped_from_the_first_tick() {
        let cold = run(&options(fixture(), Faults::none())).unwrap();
        let planned = run(&EvalOptions { plan_error_m: Some(0.0), ..options(fixture(), Faults::none()) }).unwrap();
        assert_eq!(planned.floor_plan_error_m, Some(0.0));
        assert!(cold.map.iter().any(|p| p.mapped < 1.0), "without a plan some station is mapped late: {:?}", cold.map);
        for p in &planned.map {
            assert_eq!(p.mapped, 1.0, "{p:?}");
            // A station stands where the plan puts it (its work spot) until the robots
            // learn the spot themselves, which is where it stands too.
            assert!(p.mean_error_m.unwrap() < 0.5, "{p:?}");
        }
        assert_eq!(planned.goal_unmapped_share, 0.0);
        let off = run(&EvalOptions { plan_error_m: Some(1.0), ..options(fixture(), Faults::none()) }).unwrap();
        assert!(off.map.iter().all(|p| p.mean_error_m.unwrap() < 1.5), "{:?}", off.map);
        assert!(off.map.iter().any(|p| p.mean_error_m.unwrap() > 0.05), "a displaced plan shows: {:?}", off.map);
    }

    #[test]
    fn a_fleet_that_worked_on_the_floor_before_starts_with_its_stations_mapped() {
        let cold = run(&options(fixture(), Faults::none())).unwrap();
        let warm = run(&EvalOptions { warm_map_ticks: 300, ..options(fixture(), Faults::none()) }).unwrap();
        assert_eq!(warm.warm_map_s, 30.0);
        // With empty maps the first ticks of an episode find the assembly bench not yet
        // seen three times; after 30 s of work it is on every robot's map from the start.
        let assembly = |r: &Report| r.map[2].mapped;
        assert!(assembly(&cold) < 1.0 && assembly(&warm) == 1.0, "{:?} / {:?}", cold.map, warm.map);
        assert_eq!(warm.samples, cold.samples, "the same episodes scored");

        // The results page sets each warm run beside its cold twin.
        let settings = studies::Settings {
            models_root: "models".into(),
            floors: Vec::new(),
            floors_name: "test".into(),
            camera: None,
            episodes: 3,
            seed: 5,
            ticks: 60,
        };
        let st = studies::Studies {
            scenarios: Vec::new(),
            robots: Vec::new(),
            horizons: Vec::new(),
            resolution: Vec::new(),
            faults: Vec::new(),
            generalisation: vec![cold],
            designs: Vec::new(),
            warm_maps: vec![warm],
            fresh: Vec::new(),
        };
        let page = page::markdown(&st, "spwi-sim eval --all", &settings, None);
        let rows: Vec<&str> = page.lines().filter(|l| l.starts_with("| test | 3 |")).collect();
        assert_eq!(rows.len(), 2, "{page}");
        assert!(rows[0].contains("| empty |") && rows[1].contains("| warm, 30 s |"), "{rows:?}");

        // Run on the held-out floors, the page reads the targets off both.
        let mut st = st;
        for r in st.generalisation.iter_mut().chain(st.warm_maps.iter_mut()) {
            r.floors = studies::with_cameras(studies::HELDOUT_FLOORS, CameraPolicy::Fixed);
        }
        let page = page::markdown(&st, "spwi-sim eval --all", &settings, None);
        for maps in ["empty", "warm, 30 s"] {
            let row = format!("| collective − CVM at t | ≥ +10 pts | fixed | {maps} |");
            assert!(page.contains(&row), "no row {row:?} in\n{page}");
        }
        assert!(!page.contains("A fresh sample"), "no fresh sample run, no section");
        // ... and says where the collective's points go: a row's parts add up to the
        // points it loses, and each missed target gets its paragraph.
        let cold = &st.generalisation[0];
        let bounds =
            page.lines().find(|l| l.starts_with("| fixed | empty |")).expect("a row of what bounds the targets");
        let lost: f64 = bounds
            .split(" | ")
            .filter(|cell| cell.contains(" / ") && cell.contains('('))
            .map(|cell| cell.split(' ').next().unwrap().parse::<f64>().unwrap())
            .sum();
        assert!((lost - 100.0 * (1.0 - cold.models[&Scored::Collective].t)).abs() < 0.3, "{lost} in {bounds}");
        let missed = page.contains("- **Collective − CVM ≥ +10** (missed in 2 of 2 settings)");
        assert_eq!(missed, cold.models[&Scored::Collective].t < cold.models[&Scored::Cvm].t + 0.10, "{page}");
        let mut leading = st.clone();
        for r in leading.generalisation.iter_mut().chain(leading.warm_maps.iter_mut()) {
            r.models.get_mut(&Scored::Collective).unwrap().t = r.models[&Scored::Cvm].t + 0.2;
        }
        let page_leading = page::markdown(&leading, "spwi-sim eval --all", &settings, None);
        assert!(!page_leading.contains("- **Collective − CVM ≥ +10**"), "met: no paragraph\n{page_leading}");

        // Where the fresh sample ran, its run follows its twin and every target read
        // off the held-out floors alone is read off it too.
        let mut fresh = st.generalisation[0].clone();
        fresh.floors = studies::with_cameras(studies::FRESH_FLOORS, CameraPolicy::Fixed);
        fresh.seed += studies::FRESH_SEED_OFFSET;
        fresh.models.get_mut(&Scored::Collective).unwrap().t = fresh.models[&Scored::Cvm].t + 0.123;
        st.fresh.push(fresh);
        let page = page::markdown(&st, "spwi-sim eval --all", &settings, None);
        let seeds = [" | 5 | ".to_owned(), format!(" | {} | ", 5 + studies::FRESH_SEED_OFFSET)];
        let section: Vec<&str> =
            page.lines().filter(|l| l.starts_with("| heldout:") && seeds.iter().any(|s| l.contains(s))).collect();
        assert_eq!(section.len(), 2, "{page}");
        assert!(
            section[0].starts_with("| heldout:0..50") && section[1].starts_with("| heldout:50..100"),
            "{section:?}"
        );
        assert!(section[1].contains(&format!("| {} | empty |", 5 + studies::FRESH_SEED_OFFSET)), "{section:?}");
        let reading =
            page.lines().find(|l| l.starts_with("| collective − CVM at t | ≥ +10 pts | fixed | empty |")).unwrap();
        assert!(reading.ends_with("| +12.3, met |"), "{reading}");
        let warm_reading =
            page.lines().find(|l| l.starts_with("| collective − CVM at t | ≥ +10 pts | fixed | warm")).unwrap();
        assert!(warm_reading.ends_with("| – |"), "no fresh run with warm maps: {warm_reading}");
        st.fresh.clear();

        // A floor is read against the held-out floors under its own cameras only.
        let (heldout, moved) = (st.generalisation[0].clone(), st.generalisation[0].clone());
        let tracked = |mut r: Report, floors: &str, collective: f64| {
            r.floors = studies::with_cameras(floors, CameraPolicy::Track);
            r.cameras = Some(CameraPolicy::Track);
            r.models.get_mut(&Scored::Collective).unwrap().t = collective;
            r
        };
        st.generalisation.push(tracked(heldout, studies::HELDOUT_FLOORS, 0.85));
        st.generalisation.push(tracked(moved, studies::MOVED_FLOORS, 0.81));
        let page = page::markdown(&st, "spwi-sim eval --all", &settings, None);
        let moved: Vec<&str> = page.lines().filter(|l| l.starts_with("| collective at t on factory-moved")).collect();
        assert_eq!(moved.len(), 1, "{page}");
        assert!(
            moved[0].contains("| track | empty | 4.0 (collective 81.0") && moved[0].ends_with("| met | – |"),
            "{moved:?}"
        );
    }

    #[test]
    fn every_tick_falls_in_one_phase_and_the_first_half_second_of_a_goal_is_the_hard_part() {
        let r = run(&EvalOptions { episodes: 2, ticks: 300, ..options(fixture(), Faults::none()) }).unwrap();
        assert_eq!(r.by_phase.len(), fleet::Phase::ALL.len());
        assert!(r.by_phase.iter().all(|p| p.share > 0.0), "10 s episodes hold every phase: {:?}", r.by_phase);
        assert!((r.by_phase.iter().map(|p| p.share).sum::<f64>() - 1.0).abs() < 1e-9);
        // Each phase's share of the collective's predictions weighs its accuracy into the whole.
        assert!((r.by_phase.iter().map(|p| p.collective_share).sum::<f64>() - 1.0).abs() < 1e-9);
        let weighed: f64 = r.by_phase.iter().map(|p| p.collective_share * p.collective.t).sum();
        assert!(
            (weighed - r.models[&Scored::Collective].t).abs() < 1e-9,
            "{weighed} vs {}",
            r.models[&Scored::Collective].t
        );
        assert_eq!(r.long_walks.len(), fleet::Route::ALL.len());
        assert!((r.long_walks.iter().map(|p| p.share).sum::<f64>() - 1.0).abs() < 1e-9, "{:?}", r.long_walks);
        // The worker standing at its station shows its intent; one that has just left
        // shows the station it leaves, so the constant-velocity model names that one.
        let (at_work, leaving) = (r.by_phase[0].cvm.t, r.by_phase[1].cvm.t);
        assert!(at_work > leaving + 0.3, "CVM at work {at_work}, first 0.5 s of a goal {leaving}");
    }

    #[test]
    fn without_faults_every_robot_reaches_the_same_decision() {
        let r = run(&options(fixture(), Faults::none())).unwrap();
        assert_eq!(r.agreement, 1.0, "same votes, same deterministic consensus");
    }

    #[test]
    fn relayed_ballots_keep_the_robots_agreeing_when_messages_are_lost() {
        let lossy = Faults { loss: 0.3, ..Faults::none() };
        let mut plain = options(fixture(), lossy.clone());
        plain.tick.relay_ms = 0;
        let plain = run(&plain).unwrap();
        let relayed = run(&options(fixture(), lossy)).unwrap();
        assert!(plain.agreement < 0.95, "without relays, robots holding different votes disagree: {}", plain.agreement);
        assert!(
            relayed.agreement > plain.agreement + 0.5 * (1.0 - plain.agreement),
            "relays halve the disagreement at least: {} -> {}",
            plain.agreement,
            relayed.agreement
        );
        assert!(relayed.messages_per_robot_tick > plain.messages_per_robot_tick, "relays cost messages");
    }

    #[test]
    fn a_stuck_camera_is_set_aside() {
        let stuck = Faults { faulty: 1, ..Faults::none() };
        let mut unchecked = options(fixture(), stuck.clone());
        unchecked.tick.stale_after_frames = 0;
        let unchecked = run(&unchecked).unwrap();
        let checked = run(&options(fixture(), stuck)).unwrap();
        // Robot 0 votes on every tick from its stuck frame unless its engine sets the
        // frame aside; the other robots see what they see either way.
        assert!(
            checked.samples < unchecked.samples,
            "robot 0's frozen frames are not scored as seeing the worker: {} vs {}",
            checked.samples,
            unchecked.samples
        );
    }

    #[test]
    fn a_camera_looping_an_old_clip_is_set_aside_and_unchecked_earns_less_trust() {
        // 4 robots, 30 s episodes: robot 0 records 5 s after it first sees the worker,
        // then replays them. Its engine recognises detections it showed before and
        // stops voting; without that check its estimates of the worker disagree with
        // the others' and it earns less trust.
        let looping = || EvalOptions {
            robots: 4,
            ticks: 300,
            episodes: 2,
            ..options(fixture(), Faults { looping: 1, ..Faults::none() })
        };
        let mut unchecked = looping();
        unchecked.tick.stale_after_frames = 0;
        let unchecked = run(&unchecked).unwrap();
        let trust: Vec<f64> = unchecked.per_robot.iter().map(|p| p.trust.expect("every robot voted")).collect();
        assert!(trust[0] < 0.9 && trust[1..].iter().all(|&t| t > trust[0]), "{trust:?}");
        let checked = run(&looping()).unwrap();
        assert!(
            checked.samples < unchecked.samples,
            "robot 0's replayed frames are not scored as seeing the worker: {} vs {}",
            checked.samples,
            unchecked.samples
        );
    }

    #[test]
    fn a_confident_liar_loses_the_others_trust_and_its_decisions_are_not_scored() {
        // 4 robots, 30 s: robot 0 votes a station the worker is not heading to, every
        // tick, sure of it and claiming the best view.
        let o = EvalOptions {
            robots: 4,
            ticks: 300,
            episodes: 2,
            ..options(fixture(), Faults { liars: 1, ..Faults::none() })
        };
        let r = run(&o).unwrap();
        let trust: Vec<f64> = r.per_robot.iter().map(|p| p.trust.expect("every robot voted")).collect();
        // The mean over its votes of the trust the others held of it: from 1 at the
        // start down; with the fixture models the honest robots often disagree among
        // themselves, so not every tick judges it.
        assert!(trust[1..].iter().all(|&t| t > trust[0] + 0.1), "{trust:?}");
    }

    #[test]
    fn training_episodes_are_refused() {
        let mut m = fixture().manifest.clone();
        m.fixture = false;
        m.extra.insert("dataset".into(), serde_json::json!({"exports": [{"seed": 13, "episodes": 300}]}));
        let e = check_held_out(&m, 13, 10).unwrap_err().to_string();
        assert!(e.contains("was used to train"), "{e}");
        check_held_out(&m, DEFAULT_SEED, 1000).unwrap();
        m.extra.insert(
            "dataset".into(),
            serde_json::json!({"exports": [{"seed": 13, "episodes": 3, "layouts": "heldout:0..9"}]}),
        );
        let e = check_held_out(&m, DEFAULT_SEED, 10).unwrap_err().to_string();
        assert!(e.contains("trained on held-out floors"), "{e}");
        m.extra.remove("dataset");
        assert!(check_held_out(&m, DEFAULT_SEED, 10).unwrap_err().to_string().contains("cannot check"));
    }

    #[test]
    fn consensus_figures_match_a_hand_computed_case() {
        use spwi_core::consensus::{decide, Ballot, Rule, Weights};
        use spwi_proto::{RobotId, Station::*, StepVote};
        // Robot a sees 3 detections and says 2 (confidence 0.9); b sees 1 and says 1 (0.6);
        // c sees 4 and says 1 (0.3). α = β = 0.5:
        //   ṽ = 3/8, 1/8, 4/8;  c̃ = 0.9/1.8, 0.6/1.8, 0.3/1.8
        //   score(2) = 0.5·3/8 + 0.5·0.5 = 0.4375; score(1) = 0.5·5/8 + 0.5·0.5 = 0.5625
        let ids: Vec<RobotId> = ["a", "b", "c"].iter().map(|s| RobotId::new(*s).unwrap()).collect();
        let votes = [
            [StepVote { class: Assembly, confidence: 0.9 }],
            [StepVote { class: Workstation, confidence: 0.6 }],
            [StepVote { class: Workstation, confidence: 0.3 }],
        ];
        let mut ballots: Vec<Ballot<'_>> = [3, 1, 4]
            .iter()
            .zip(&ids)
            .zip(&votes)
            .map(|((&visibility, robot), steps)| Ballot { robot, visibility, trust: 1.0, quality: 1.0, steps })
            .collect();
        let d = decide(&mut ballots, Rule::Paper(Weights { alpha: 0.5, beta: 0.5 }));
        assert_eq!(d[0].class, Workstation);
        assert!((d[0].score - 0.5625).abs() < 1e-6);
        let mut t = score::Tally::default();
        t.add(&[d[0].class], &[Workstation]);
        t.add(&[Assembly], &[Workstation]);
        assert_eq!(estimate(&[t]).t, 0.5);
    }
}
