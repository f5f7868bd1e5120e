//! `spwi-sim eval --all`: every study of the paper's section IV and the fault studies
//! beyond it, as one JSON document and as `docs/RESULTS.md` (tables beside the paper's).

use super::{find_model_set, run, EvalOptions, Faults, Report};
use crate::world_args::BUILT_IN;
use anyhow::Result;
use serde::Serialize;
use spwi_core::model::{Backend, ModelSet};
use spwi_core::settings::{ConsensusRule, TickConfig};
use spwi_world::generate::{self, LayoutSource, NamedLayout};
use spwi_world::layout::{CameraPolicy, Layout};
use spwi_world::world::Scenario;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Settings shared by every study.
pub struct Settings {
    pub models_root: PathBuf,
    /// The floors of every study but the generalisation one.
    pub floors: Vec<NamedLayout>,
    pub floors_name: String,
    /// A camera policy forced on every floor, if any.
    pub camera: Option<CameraPolicy>,
    pub episodes: u32,
    pub seed: u64,
    pub ticks: u32,
}

#[derive(Debug, Clone, Serialize)]
pub struct Studies {
    /// Table II: the three scenarios, 3 robots, default set.
    pub scenarios: Vec<Report>,
    /// Robots 1, 2, 3, 4, 6, 8 (scenario 3).
    pub robots: Vec<Report>,
    /// 1 s → 1 s, 2 s → 2 s, 3 s → 3 s with 1 and 3 robots.
    pub horizons: Vec<Report>,
    /// 1 s of history at 10, 5 and 3 frames, 3 robots.
    pub resolution: Vec<Report>,
    /// Scenario 3, 4 robots: dropouts, message loss, a stuck camera.
    pub faults: Vec<Report>,
    /// Scenario 3, 3 robots, default set: the study floors (held-out episodes), held-out
    /// generated floors, the default floor with two stations swapped, and mirrored.
    pub generalisation: Vec<Report>,
    /// Scenario 3 on the held-out generated floors: the paper's design (`models/paper`),
    /// relation rows without the facing block (`models/relations`) and our peer set
    /// (`models/peer-set`) against ours (`models/default`), trained on the same data,
    /// with fixed cameras and with cameras that track the worker; ours with 1 to 4
    /// robots under tracking.
    pub designs: Vec<Report>,
    /// The default set with station maps warm ([`WARM_MAP_S`]): held-out floors with
    /// fixed cameras and with tracking cameras (1 to 4 robots), the built-in floor,
    /// moved and mirrored. Their cold twins are in `designs` and `generalisation`.
    pub warm_maps: Vec<Report>,
    /// The default set, 3 robots, on [`FRESH_FLOORS`] with episodes of another seed:
    /// fixed and tracking cameras, maps empty and warm. Their twins on the held-out
    /// floors are in `designs` and `warm_maps`.
    pub fresh: Vec<Report>,
}

/// How long the fleet of the warm-map study has worked on a floor before an episode:
/// a minute, two episodes' length.
pub const WARM_MAP_S: u32 = 60;

/// The other designs shipped beside `models/default`, trained on the same data,
/// compared with it on the held-out floors when present.
pub const OTHER_DESIGNS: [&str; 3] = ["paper", "relations", "peer-set"];

/// The design of the window study sets (`w10-h10`, `w30-h30`: models/train.sh). The
/// horizon study reads it at 2 s → 2 s too, when shipped, so that only the window varies.
pub const WINDOW_STUDY_DESIGN: &str = "relations";

/// Held-out generated floors of the generalisation study.
pub const HELDOUT_FLOORS: &str = "heldout:0..50";

/// Floors of the fresh sample: the held-out family's next fifty. Every design choice
/// was measured on [`HELDOUT_FLOORS`] at the study seed, which can flatter them; the
/// fresh sample (these floors, episodes of another seed) says whether the figures hold
/// elsewhere. Never choose a design by it, or it stops saying that.
pub const FRESH_FLOORS: &str = "heldout:50..100";
/// The fresh sample's evaluation seed is the study seed plus this.
pub const FRESH_SEED_OFFSET: u64 = 1000;

/// "heldout:0..50, Track cameras": the name of floors whose camera policy a study forces.
pub fn with_cameras(floors: &str, policy: CameraPolicy) -> String {
    format!("{floors}, {policy:?} cameras")
}

/// The floors of the generalisation study, beside the study floors (`study`, left out
/// here when it is one of them), each with `camera` forced and named if given.
pub fn unseen_floors(study: &str, camera: Option<CameraPolicy>) -> Result<Vec<(String, Vec<NamedLayout>)>> {
    let moved = Layout::parse(include_str!("../../../world/layouts/factory-moved.toml"), "factory-moved.toml")?;
    let heldout: LayoutSource = HELDOUT_FLOORS.parse().map_err(anyhow::Error::msg)?;
    let built_in = NamedLayout { name: BUILT_IN.into(), layout: Layout::default_layout() };
    let mut sets = vec![
        (HELDOUT_FLOORS.to_owned(), generate::resolve(&[heldout])?),
        (BUILT_IN.to_owned(), vec![built_in]),
        (
            "factory-moved.toml (two stations swapped)".to_owned(),
            vec![NamedLayout { name: "factory-moved".into(), layout: moved }],
        ),
        (
            "factory.toml mirrored".to_owned(),
            vec![NamedLayout { name: "factory-mirrored".into(), layout: Layout::default_layout().mirrored() }],
        ),
    ];
    sets.retain(|(name, _)| name != study);
    if let Some(p) = camera {
        for (name, floors) in &mut sets {
            *name = with_cameras(name, p);
            floors.iter_mut().for_each(|f| f.layout.camera.policy = p);
        }
    }
    Ok(sets)
}

/// The `[tick]` settings of the paper's protocol: votes go out once, nobody relays
/// them, a feed that repeats itself is believed, and the paper's rule weighs the votes.
pub fn paper_protocol() -> TickConfig {
    TickConfig { relay_ms: 0, stale_after_frames: 0, consensus: ConsensusRule::Paper, ..TickConfig::default() }
}

/// The mean trust the others held of the untrue robots (lying cameras, liars, a pose
/// off) / of the rest.
fn trust_split(r: &Report) -> String {
    let lying = r.faults.untrue();
    let mean = |ps: &[super::PerRobot]| {
        let ts: Vec<f64> = ps.iter().filter_map(|p| p.trust).collect();
        if ts.is_empty() {
            "–".to_owned()
        } else {
            format!("{:.2}", ts.iter().sum::<f64>() / ts.len() as f64)
        }
    };
    let split = lying.min(r.per_robot.len());
    let faulty = if lying == 0 { "–".to_owned() } else { mean(&r.per_robot[..split]) };
    format!("{faulty} / {}", mean(&r.per_robot[split..]))
}

fn load(root: &Path, window: usize, horizon: usize, frames: Option<usize>) -> Result<std::sync::Arc<ModelSet>> {
    ModelSet::load(&find_model_set(root, window, horizon, frames)?, Backend::Tract, None)
}

/// The model sets of `reports`, each once, in order, as `a`, `b`.
fn set_names(reports: &[Report]) -> String {
    let mut names: Vec<&str> = Vec::new();
    for r in reports {
        if !names.contains(&r.model_set.as_str()) {
            names.push(&r.model_set);
        }
    }
    names.iter().map(|n| format!("`{n}`")).collect::<Vec<_>>().join(", ")
}

pub fn run_all(s: &Settings) -> Result<Studies> {
    let default = load(&s.models_root, 20, 20, None)?;
    // The 1D-CNN baseline runs only where a table shows it (Table IV, the unseen floors).
    let one_with = |scenario: u8,
                    robots: usize,
                    models: &std::sync::Arc<ModelSet>,
                    seed: u64,
                    faults: Faults,
                    tick: TickConfig,
                    cnn1d: bool|
     -> Result<Report> {
        let r = run(&EvalOptions {
            scenario: Scenario::from_number(scenario)?,
            robots,
            models: models.clone(),
            floors: s.floors.clone(),
            floors_name: s.floors_name.clone(),
            episodes: s.episodes,
            seed,
            ticks: s.ticks,
            faults,
            tick,
            warm_map_ticks: 0,
            cnn1d,
        })?;
        super::print(&r);
        println!();
        Ok(r)
    };
    let one = |scenario: u8, robots: usize, models: &std::sync::Arc<ModelSet>, seed: u64, faults: Faults| {
        one_with(scenario, robots, models, seed, faults, TickConfig::default(), false)
    };
    let mut st = Studies {
        scenarios: Vec::new(),
        robots: Vec::new(),
        horizons: Vec::new(),
        resolution: Vec::new(),
        faults: Vec::new(),
        generalisation: Vec::new(),
        designs: Vec::new(),
        warm_maps: Vec::new(),
        fresh: Vec::new(),
    };
    for scenario in 1..=3 {
        st.scenarios.push(one_with(scenario, 3, &default, s.seed, Faults::none(), TickConfig::default(), true)?);
    }
    for robots in [1, 2, 3, 4, 6, 8] {
        st.robots.push(one(3, robots, &default, s.seed, Faults::none())?);
    }
    for (w, h) in [(10, 10), (20, 20), (30, 30)] {
        let same_design = s.models_root.join(WINDOW_STUDY_DESIGN);
        let set = match w {
            20 if same_design.join("manifest.json").is_file() => ModelSet::load(&same_design, Backend::Tract, None)?,
            20 => default.clone(),
            _ => load(&s.models_root, w, h, None)?,
        };
        for robots in [1, 3] {
            st.horizons.push(one(3, robots, &set, s.seed, Faults::none())?);
        }
    }
    for frames in [10, 5, 3] {
        let set = load(&s.models_root, 10, 10, Some(frames))?;
        st.resolution.push(one(3, 3, &set, s.seed, Faults::none())?);
    }
    for faults in [
        Faults::none(),
        Faults { dropouts: 1, ..Faults::none() },
        Faults { dropouts: 2, ..Faults::none() },
        Faults { loss: 0.1, ..Faults::none() },
        Faults { loss: 0.3, ..Faults::none() },
        Faults { faulty: 1, ..Faults::none() },
        Faults { looping: 1, ..Faults::none() },
        Faults { liars: 1, ..Faults::none() },
        Faults { pose_error_m: 2.0, ..Faults::none() },
    ] {
        // The paper's protocol (no relays, no check for frozen feeds, the paper's rule)
        // beside ours with each consensus rule.
        st.faults.push(one_with(3, 4, &default, s.seed, faults.clone(), paper_protocol(), false)?);
        for consensus in [ConsensusRule::Paper, ConsensusRule::Trust] {
            let ours = TickConfig { consensus, ..TickConfig::default() };
            st.faults.push(one_with(3, 4, &default, s.seed, faults.clone(), ours, false)?);
        }
    }
    if let Some(r) = st.scenarios.iter().find(|r| r.scenario == 3) {
        st.generalisation.push(r.clone());
    }
    let others = OTHER_DESIGNS
        .iter()
        .map(|name| s.models_root.join(name))
        .filter(|dir| dir.join("manifest.json").is_file())
        .map(|dir| ModelSet::load(&dir, Backend::Tract, None))
        .collect::<Result<Vec<_>>>()?;
    let heldout = generate::resolve(&[HELDOUT_FLOORS.parse().map_err(anyhow::Error::msg)?])?;
    let mut configs: Vec<(&std::sync::Arc<ModelSet>, CameraPolicy, usize)> = Vec::new();
    for policy in [CameraPolicy::Fixed, CameraPolicy::Track] {
        configs.extend(others.iter().map(|p| (p, policy, 3)));
        configs.push((&default, policy, 3));
    }
    configs.extend([1, 2, 4].map(|n| (&default, CameraPolicy::Track, n)));
    let fresh = generate::resolve(&[FRESH_FLOORS.parse().map_err(anyhow::Error::msg)?])?;
    let under = |(name, floors): (&str, &[NamedLayout]), policy: CameraPolicy| {
        let mut floors = floors.to_vec();
        floors.iter_mut().for_each(|f| f.layout.camera.policy = policy);
        (with_cameras(name, policy), floors)
    };
    let on_heldout = |policy: CameraPolicy| under((HELDOUT_FLOORS, &heldout), policy);
    let scenario_3 = |models: &std::sync::Arc<ModelSet>,
                      (name, floors): (String, Vec<NamedLayout>),
                      robots: usize,
                      warm_s: u32,
                      cnn1d: bool,
                      seed: u64| {
        let r = run(&EvalOptions {
            scenario: Scenario::Dynamic,
            robots,
            models: models.clone(),
            floors,
            floors_name: name,
            episodes: s.episodes,
            seed,
            ticks: s.ticks,
            faults: Faults::none(),
            tick: TickConfig::default(),
            warm_map_ticks: warm_s * 10,
            cnn1d,
        })?;
        super::print(&r);
        anyhow::Ok(r)
    };
    let mut unseen = unseen_floors(&s.floors_name, s.camera)?;
    for floors in &unseen {
        st.generalisation.push(scenario_3(&default, floors.clone(), 3, 0, true, s.seed)?);
    }
    // The built-in floors again under tracking cameras, to set beside the held-out
    // floors under the same cameras (the design study's run).
    if s.camera != Some(CameraPolicy::Track) {
        let tracked = unseen_floors(&s.floors_name, Some(CameraPolicy::Track))?;
        for floors in tracked.into_iter().filter(|(name, _)| !name.starts_with(HELDOUT_FLOORS)) {
            st.generalisation.push(scenario_3(&default, floors.clone(), 3, 0, false, s.seed)?);
            unseen.push(floors);
        }
    }
    for (models, policy, robots) in configs {
        st.designs.push(scenario_3(models, on_heldout(policy), robots, 0, false, s.seed)?);
    }
    let mut warm: Vec<((String, Vec<NamedLayout>), usize)> = vec![(on_heldout(CameraPolicy::Fixed), 3)];
    warm.extend([1, 2, 3, 4].map(|n| (on_heldout(CameraPolicy::Track), n)));
    warm.extend(unseen.into_iter().filter(|(name, _)| !name.starts_with(HELDOUT_FLOORS)).map(|f| (f, 3)));
    for (floors, robots) in warm {
        st.warm_maps.push(scenario_3(&default, floors, robots, WARM_MAP_S, false, s.seed)?);
    }
    for policy in [CameraPolicy::Fixed, CameraPolicy::Track] {
        for warm_s in [0, WARM_MAP_S] {
            let floors = under((FRESH_FLOORS, &fresh), policy);
            st.fresh.push(scenario_3(&default, floors, 3, warm_s, false, s.seed + FRESH_SEED_OFFSET)?);
        }
    }
    Ok(st)
}

/// "+9.0": `model`'s accuracy at t less `other`'s, in points ("–" if either is absent).
fn points(r: &Report, model: &str, other: &str) -> String {
    lead(r, model, other).map_or("–".into(), |g| format!("{:+.1}", 100.0 * g))
}

/// "empty" or "warm, 60 s": how a run's station maps started.
pub(super) fn maps(r: &Report) -> String {
    if r.warm_map_s > 0.0 {
        format!("warm, {} s", r.warm_map_s)
    } else {
        "empty".into()
    }
}

pub(super) fn pct(v: f64) -> String {
    format!("{:.1}", 100.0 * v)
}

/// "81.0 (79.2–82.7)": a figure with its 95 % interval.
pub(super) fn with_ci(v: f64, ci: [f64; 2]) -> String {
    format!("{} ({}–{})", pct(v), pct(ci[0]), pct(ci[1]))
}

/// A model's accuracy at t and over t+1…H, each with its interval ("–" if absent).
fn acc(r: &Report, model: &str) -> (String, String) {
    acc_in(&r.models, model)
}

fn acc_in(m: &std::collections::BTreeMap<&'static str, super::score::Accuracy>, model: &str) -> (String, String) {
    m.get(model).map_or(("–".into(), "–".into()), |a| {
        let future = match (a.future, a.future_ci95) {
            (Some(f), Some(ci)) => with_ci(f, ci),
            _ => "–".into(),
        };
        (with_ci(a.t, a.t_ci95), future)
    })
}

/// docs/RESULTS.md: our tables next to the paper's.
/// `figures`: the folder of `--plots`, relative to the page, to show the figures.
pub fn markdown(st: &Studies, command: &str, s: &Settings, figures: Option<&Path>) -> String {
    let figure =
        |name: &str, alt: &str| figures.map_or(String::new(), |d| format!("\n![{alt}]({})\n", d.join(name).display()));
    let mut m = String::new();
    let w = &mut m;
    let _ = writeln!(w, "# Results: the paper's tables, reproduced on the simulated factory\n");
    let _ = writeln!(
        w,
        "Generated by `{command}` — do not edit by hand. {} held-out episodes of {} ticks (10 Hz) per configuration on {}, evaluation seed {} (training used seeds 11–13; `spwi-sim eval` refuses overlapping episodes). Models: the shipped sets under `models/` (see models/README.md). Accuracies in %, at t and averaged over t+1…H, each followed by its 95 % bootstrap confidence interval (whole episodes resampled). Paper figures from Isaac Sim, ours from `world/`: the worlds differ, so compare orderings and gaps, not digits.\n",
        s.episodes, s.ticks, s.floors_name, s.seed
    );
    let _ = writeln!(
        w,
        "**Headline: the team's accuracy over all ticks** (`team, all ticks`): every robot's decision on every tick, a tick without a decision counted as wrong — what the fleet gets right. Per-model figures are over the ticks where that model predicts (a robot's models when it sees the worker; the consensus when some robot does).\n"
    );
    let _ = writeln!(w, "## Table II — scenarios (3 robots, 2 s → 2 s)\n");
    let _ = writeln!(w, "| scenario | team, all ticks | GNN | ego t | collective t | collective t+1…H | consensus t | paper: GNN / ego t / collective t / consensus |");
    let _ = writeln!(w, "|---|---|---|---|---|---|---|---|");
    let paper2 = ["71.2 / 84.2 / 92.8 / 90.3", "73.4 / 82.5 / 91.8 / 89.3", "70.7 / 77.7 / 88.9 / 88.5"];
    for (r, p) in st.scenarios.iter().zip(paper2) {
        let (c, cf) = acc(r, "collective");
        let _ = writeln!(
            w,
            "| {} | {} | {} | {} | {c} | {cf} | {} | {p} |",
            r.scenario,
            acc(r, "team_all_ticks").0,
            acc(r, "gnn").0,
            acc(r, "ego").0,
            acc(r, "consensus").0
        );
    }
    if let Some(r) = st.scenarios.iter().find(|r| r.scenario == 3) {
        let _ = writeln!(w, "\n## Table III — per robot (scenario 3, 3 robots, 2 s → 2 s)\n");
        let _ = writeln!(w, "| robot | GNN | ego t | collective t | collective t+1…H |");
        let _ = writeln!(w, "|---|---|---|---|---|");
        for p in &r.per_robot {
            let f = |a: &super::score::Accuracy| with_ci(a.t, a.t_ci95);
            let future = match (p.collective.future, p.collective.future_ci95) {
                (Some(v), Some(ci)) => with_ci(v, ci),
                _ => "–".into(),
            };
            let _ = writeln!(w, "| {} | {} | {} | {} | {future} |", p.robot, pct(p.gnn), f(&p.ego), f(&p.collective));
        }
        let _ = writeln!(
            w,
            "\nPaper: robots 69.2–72.9 (GNN), 76.1–79.2 (ego t), 86.3–91.8 (collective t), consensus 88.5.\n"
        );
        let _ = writeln!(w, "## Table IV — models on the current frame (scenario 3, 3 robots)\n");
        let _ = writeln!(w, "| model | ours, t | ours, t+1…H | paper, t |");
        let _ = writeln!(w, "|---|---|---|---|");
        for (name, label, paper) in [
            ("gnn", "GNN", "70.73"),
            ("ego", "Ego-GRU", "77.7"),
            ("collective", "Collective-GRU", "88.87"),
            ("cvm", "CVM (constant velocity, Kalman), true work spots", "66.1"),
            ("cvm_mapped", "CVM on the stations the team mapped", "–"),
            ("cnn1d", "1D-CNN + GRU", "63.31"),
            ("consensus", "Collective-GRU + consensus", "88.5"),
            ("team_all_ticks", "Team, all ticks", "–"),
        ] {
            let (t, f) = acc(r, name);
            let _ = writeln!(w, "| {label} | {t} | {f} | {paper} |");
        }
        if !r.close_pair.is_empty() {
            let _ = writeln!(
                w,
                "\nTicks where the worker heads to a station of the close pair (work spots within 3.5 m):\n"
            );
            let _ = writeln!(w, "| model | t | t+1…H |\n|---|---|---|");
            for name in ["team_all_ticks", "ego", "collective", "consensus", "cvm", "collective_farther", "cvm_farther"]
            {
                let (t, f) = acc_in(&r.close_pair, name);
                let _ = writeln!(w, "| {name} | {t} | {f} |");
            }
            let _ = writeln!(
                w,
                "\n`*_farther`: the ticks where the goal is the station of the pair farther from the worker (its walk passes the nearer one first), i.e. the recall of the farther station."
            );
        }
        if !r.by_phase.is_empty() {
            let _ = writeln!(
                w,
                "\nBy where the tick falls in the worker's cycle: at work, or walking so long after it committed to its goal (the label changes in that very tick; the motion shows it only as it builds up):\n"
            );
            let _ = writeln!(w, "| phase | share of ticks | collective t | ego t | CVM t |\n|---|---|---|---|---|");
            for p in &r.by_phase {
                let c = |a: &super::score::Accuracy| with_ci(a.t, a.t_ci95);
                let share = format!("{:.1}", 100.0 * p.share);
                let _ = writeln!(w, "| {} | {share} | {} | {} | {} |", p.phase, c(&p.collective), c(&p.ego), c(&p.cvm));
            }
        }
        let _ = writeln!(w, "\nConfusion at t (rows: true station 0–3, columns: predicted):\n");
        for (name, c) in &r.confusion {
            let _ = writeln!(w, "- {name}: {}", c.iter().map(|row| format!("{row:?}")).collect::<Vec<_>>().join(" "));
        }
        let _ = write!(w, "{}", figure("confusion_ego.png", "ego confusion"));
        let _ = write!(w, "{}", figure("confusion_collective.png", "collective confusion"));
    }
    let _ = writeln!(w, "\n## Number of robots (scenario 3, 2 s → 2 s) — paper Fig. 5: accuracy grows from 1 to 3 robots, less from 3 to 4\n");
    let _ = writeln!(
        w,
        "| robots | team, all ticks: t | team t+1…H | coverage | ego t | collective t | consensus t | agreement |"
    );
    let _ = writeln!(w, "|---|---|---|---|---|---|---|---|");
    for r in &st.robots {
        let _ = writeln!(
            w,
            "| {} | {} | {} | {} | {} | {} | {} | {} |",
            r.robots,
            acc(r, "team_all_ticks").0,
            acc(r, "team_all_ticks").1,
            pct(r.coverage),
            acc(r, "ego").0,
            acc(r, "collective").0,
            acc(r, "consensus").0,
            pct(r.agreement)
        );
    }
    let _ = writeln!(
        w,
        "\n*Coverage*: ticks on which the team decides (some robot sees the worker or, with a relation set, still tracks it). Robots 4–8 take layout slots with poorer views, so per-model averages mix in harder samples; coverage and the team's accuracy over all ticks show what a larger fleet buys."
    );
    let _ = write!(w, "{}", figure("robots.png", "accuracy against the number of robots"));
    let _ = writeln!(w, "\n## Time horizons (scenario 3) — paper Fig. 4: more past helps\n");
    let _ = writeln!(
        w,
        "Model sets: {} (models/README.md: the same design and data, other windows).\n",
        set_names(&st.horizons)
    );
    let _ = writeln!(w, "| past → future | robots | collective t | collective t+1…H | ego t | team, all ticks |");
    let _ = writeln!(w, "|---|---|---|---|---|---|");
    for r in &st.horizons {
        let (c, cf) = acc(r, "collective");
        let _ = writeln!(
            w,
            "| {:.0} s → {:.0} s | {} | {c} | {cf} | {} | {} |",
            r.window as f64 * spwi_proto::TICK_PERIOD.as_secs_f64(),
            r.horizon as f64 * spwi_proto::TICK_PERIOD.as_secs_f64(),
            r.robots,
            acc(r, "ego").0,
            acc(r, "team_all_ticks").0
        );
    }
    let _ = write!(w, "{}", figure("horizons.png", "time horizons"));
    let _ = writeln!(w, "\n## Temporal resolution (scenario 3, 3 robots, 1 s → 1 s) — paper Fig. 6\n");
    let _ = writeln!(w, "Model sets: {}.\n", set_names(&st.resolution));
    let _ = writeln!(w, "| frames of the last second | ego t | collective t | collective t+1…H | consensus t |");
    let _ = writeln!(w, "|---|---|---|---|---|");
    for r in &st.resolution {
        let (c, cf) = acc(r, "collective");
        let _ = writeln!(w, "| {} | {} | {c} | {cf} | {} |", r.frames, acc(r, "ego").0, acc(r, "consensus").0);
    }
    let _ = write!(w, "{}", figure("resolution.png", "temporal resolution"));
    let _ = writeln!(w, "\n## Beyond the paper: faults (scenario 3, 4 robots, 2 s → 2 s)\n");
    let _ = writeln!(
        w,
        "Each fault three times: with the paper's protocol (each vote sent once, every feed believed, the paper's consensus rule) and with ours (`[tick]` defaults: the ballots each robot holds relayed {} ms into the tick and sent up to {} times from then to the deadline by a robot still missing a vote, a camera repeating the same worker detection {} times set aside, peers trusted below {} left out of the fusion; `core/src/engine/`) under each consensus rule: *paper* (normalised shares of visibility and confidence) and *trust* (each vote's log-likelihood ratio weighted by the voter's agreement with the others over the last {} decided ticks and by its view of the worker; `core/src/consensus.rs`, `core/src/trust.rs`). The daemon's default rule is `{}`. *Healthy collective*: the collective GRU of the robots whose camera works. Messages and bytes: what each robot publishes per tick.\n",
        TickConfig::default().relay_ms,
        TickConfig::default().ask_rounds,
        TickConfig::default().stale_after_frames,
        TickConfig::default().fuse_min_trust,
        TickConfig::default().trust_window_ticks,
        TickConfig::default().consensus.name(),
    );
    let _ = writeln!(w, "| fault | protocol | team, all ticks | healthy collective t | consensus t | consensus t+1…H | agreement | trust: faulty robot / others | messages / bytes per robot tick |");
    let _ = writeln!(w, "|---|---|---|---|---|---|---|---|---|");
    for r in &st.faults {
        let f = &r.faults;
        let what = if f.dropouts > 0 {
            format!("{} of 4 leave half-way", f.dropouts)
        } else if f.loss > 0.0 {
            format!("{:.0}% of messages lost", 100.0 * f.loss)
        } else if f.faulty > 0 {
            format!("{} stuck camera (confident, wrong)", f.faulty)
        } else if f.looping > 0 {
            format!("{} camera looping an old 5 s clip", f.looping)
        } else if f.liars > 0 {
            format!("{} member voting a wrong station every tick, sure of it", f.liars)
        } else if f.pose_error_m > 0.0 {
            format!("1 robot's pose {} m off", f.pose_error_m)
        } else {
            "none".into()
        };
        let protocol = if r.tick == paper_protocol() {
            "paper".to_owned()
        } else {
            format!("ours, {} rule", r.tick.consensus.name())
        };
        let (c, cf) = acc(r, "consensus");
        let _ = writeln!(
            w,
            "| {what} | {protocol} | {} | {} | {c} | {cf} | {} | {} | {:.2} / {:.0} |",
            acc(r, "team_all_ticks").0,
            acc(r, "healthy_collective").0,
            pct(r.agreement),
            trust_split(r),
            r.messages_per_robot_tick,
            r.bytes_per_robot_tick
        );
    }
    if !st.generalisation.is_empty() {
        let _ =
            writeln!(w, "\n## Generalisation: floors the models never saw (scenario 3, 3 robots, default set, at t)\n");
        let _ = writeln!(
            w,
            "First column: the study floors above (held-out episodes). Then floors the models never saw: held-out generated floors ({HELDOUT_FLOORS}, one episode after another on each), the built-in floor (unless it is the study floor), the built-in floor with two stations swapped, and mirrored (every relation kept, every place moved); then the last three again under cameras that track the worker and look round while it works (*Track cameras*; the held-out floors under them are in the next table). A model that learned the worker's relations to objects keeps its accuracy across the columns; one that learned places does not. The training floors of the default set are in its manifest (`dataset.exports`).\n"
        );
        let _ = write!(w, "| model |");
        for r in &st.generalisation {
            let _ = write!(w, " {} |", r.floors);
        }
        let _ = writeln!(w, "\n|---|{}", "---|".repeat(st.generalisation.len()));
        for name in ["team_all_ticks", "gnn", "ego", "collective", "consensus", "cvm", "cvm_mapped", "cnn1d"] {
            let _ = write!(w, "| {name} |");
            for r in &st.generalisation {
                let _ = write!(w, " {} |", acc(r, name).0);
            }
            let _ = writeln!(w);
        }
        let _ = write!(w, "| coverage |");
        for r in &st.generalisation {
            let _ = write!(w, " {} |", pct(r.coverage));
        }
        let _ = writeln!(w);
        let _ = write!(w, "| goal unmapped |");
        for r in &st.generalisation {
            let _ = write!(w, " {} |", pct(r.goal_unmapped_share));
        }
        let _ = writeln!(w);
        let _ = write!(w, "| on the team map: storage / workstation / assembly / manufacturing |");
        for r in &st.generalisation {
            let shares: Vec<String> = r.map.iter().map(|p| format!("{:.0}", 100.0 * p.mapped)).collect();
            let _ = write!(w, " {} |", shares.join(" / "));
        }
        let _ = writeln!(w);
        let _ = writeln!(
            w,
            "\n*Goal unmapped*: share of the collective's ticks on which the station the worker heads to is missing from the robot's team map. *On the team map*: share of the scored robot-ticks on which each station is on it (built from the robots' own detections: a station no camera looks at stays off the map)."
        );
    }
    if !st.designs.is_empty() {
        let _ = writeln!(
            w,
            "\n## The paper's design against ours (scenario 3, held-out generated floors {HELDOUT_FLOORS}, 2 s → 2 s)\n"
        );
        let _ = writeln!(
            w,
            "`paper`: the paper's rows (GCN embedding ‖ mean of the peers' ‖ keypoints). `relations`: the same GCN and data, rows ending with the worker's relations to the stations the team mapped from its own detections (floor-frame track shared and fused; `core/src/floor/`), and votes from the track while it is fresh. `peer-set`: the relations rows, and a collective GRU that also pools one relation block per peer it heard (each peer's own estimate of the worker against the team map; DeepSets over 0–7 peers, `models/README.md`). `default`: the relations rows, each followed by where the worker's body faces against every station (the ego GRU's from the robot's own keypoints, the collective's fused over the robots whose estimates make the team's track, each sharing its own in its embedding message). CVM is given the true work spots; our models map the stations themselves, and *CVM, mapped* is the same CVM given only those. *Goal unmapped*: share of the collective's ticks on which the station the worker heads to is missing from the robot's team map (no relation row describes it). *Close pair*: ticks heading to a station of a close pair.\n"
        );
        let _ = writeln!(
            w,
            "| set | cameras | robots | team, all ticks | coverage | ego t | collective t | collective − ego | consensus t | CVM t | CVM, mapped t | goal unmapped | close pair, collective t | agreement |"
        );
        let _ = writeln!(w, "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
        for r in &st.designs {
            let gap = points(r, "collective", "ego");
            let cameras = r.cameras.map_or("mixed cameras".to_owned(), |p| format!("{p:?} cameras"));
            let _ = writeln!(
                w,
                "| {} | {cameras} | {} | {} | {} | {} | {} | {gap} | {} | {} | {} | {} | {} | {} |",
                r.model_set,
                r.robots,
                acc(r, "team_all_ticks").0,
                pct(r.coverage),
                acc(r, "ego").0,
                acc(r, "collective").0,
                acc(r, "consensus").0,
                acc(r, "cvm").0,
                acc(r, "cvm_mapped").0,
                pct(r.goal_unmapped_share),
                acc_in(&r.close_pair, "collective").0,
                pct(r.agreement)
            );
        }
    }
    if !st.warm_maps.is_empty() {
        let _ =
            writeln!(w, "\n## A fleet that knows the floor: station maps warm (scenario 3, default set, 2 s → 2 s)\n");
        let _ = writeln!(
            w,
            "A daemon keeps its station map for as long as it runs, so a fleet that has worked on a floor for a while has mapped every station its cameras have seen; every table above starts each 30 s episode with empty maps instead, a fleet's first seconds on a floor. Here the robots first work {WARM_MAP_S} s on the floor (unscored, another worker, the same robots; `spwi-sim eval --warm-map {WARM_MAP_S}`, `sim/src/team_floor.rs`), then the episode is scored as above. The maps still come from the robots' own detections only; the models never saw these floors. Each warm row follows its cold twin from the tables above. *Farther station*: recall of the station of a close pair the worker's walk reaches second.\n"
        );
        let _ = writeln!(
            w,
            "| floors | robots | maps | team, all ticks | coverage | ego t | collective t | collective − ego | consensus t | CVM t | goal unmapped | farther station, collective t | agreement |"
        );
        let _ = writeln!(w, "|---|---|---|---|---|---|---|---|---|---|---|---|---|");
        for warm in &st.warm_maps {
            for r in twin(st, &warm.floors, warm, 0.0).into_iter().chain([warm]) {
                let maps = maps(r);
                let _ = writeln!(
                    w,
                    "| {} | {} | {maps} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
                    r.floors,
                    r.robots,
                    acc(r, "team_all_ticks").0,
                    pct(r.coverage),
                    acc(r, "ego").0,
                    acc(r, "collective").0,
                    points(r, "collective", "ego"),
                    acc(r, "consensus").0,
                    acc(r, "cvm").0,
                    pct(r.goal_unmapped_share),
                    acc_in(&r.close_pair, "collective_farther").0,
                    pct(r.agreement)
                );
            }
        }
    }
    fresh_sample(st, s.seed, w);
    super::reading::targets(st, s.seed, w);
    // The first generalisation column is the scenario-3 run of Table II again.
    let total: f64 =
        [&st.scenarios, &st.robots, &st.horizons, &st.resolution, &st.faults, &st.designs, &st.warm_maps, &st.fresh]
            .iter()
            .flat_map(|v| v.iter())
            .chain(st.generalisation.iter().skip(1))
            .map(|r| r.seconds)
            .sum();
    let _ = writeln!(w, "\nWhole run: {total:.0} s of evaluation on this machine (both cores).");
    m
}

/// The run of `r`'s set and fleet on `floors` whose maps were warmed for `warm_map_s`:
/// the run a table sets `r` beside.
fn twin<'a>(st: &'a Studies, floors: &str, r: &Report, warm_map_s: f64) -> Option<&'a Report> {
    st.designs.iter().chain(&st.generalisation).chain(&st.warm_maps).find(|t| {
        t.floors == floors && t.robots == r.robots && t.model_set == r.model_set && t.warm_map_s == warm_map_s
    })
}

/// The fresh sample beside its twins on the held-out floors (same cameras and maps).
fn fresh_sample(st: &Studies, seed: u64, w: &mut String) {
    if st.fresh.is_empty() {
        return;
    }
    let _ = writeln!(
        w,
        "\n## A fresh sample: floors and episodes no design was chosen on (scenario 3, 3 robots, default set, 2 s → 2 s)\n"
    );
    let _ = writeln!(
        w,
        "Every design on this page was chosen, and every target of the reading below is read, on the held-out floors {HELDOUT_FLOORS} with episodes of seed {seed}: a choice made by looking at one sample can flatter it. Here the same fleet on the next fifty held-out floors ({FRESH_FLOORS}) with episodes of seed {}, on which no choice was measured; each run follows its twin on {HELDOUT_FLOORS}.\n",
        seed + FRESH_SEED_OFFSET
    );
    let _ = writeln!(
        w,
        "| floors | seed | maps | team, all ticks | coverage | ego t | collective t | CVM t | collective − CVM | collective − ego | goal unmapped | farther station, collective t |"
    );
    let _ = writeln!(w, "|---|---|---|---|---|---|---|---|---|---|---|---|");
    for f in &st.fresh {
        let Some(cameras) = f.cameras else { continue };
        let twin = twin(st, &with_cameras(HELDOUT_FLOORS, cameras), f, f.warm_map_s);
        for r in twin.into_iter().chain([f]) {
            let maps = maps(r);
            let _ = writeln!(
                w,
                "| {} | {} | {maps} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
                r.floors,
                r.seed,
                acc(r, "team_all_ticks").0,
                pct(r.coverage),
                acc(r, "ego").0,
                acc(r, "collective").0,
                acc(r, "cvm").0,
                points(r, "collective", "cvm"),
                points(r, "collective", "ego"),
                pct(r.goal_unmapped_share),
                acc_in(&r.close_pair, "collective_farther").0,
            );
        }
    }
}

/// A model's accuracy at t and its interval.
pub(super) fn at(r: &Report, model: &str) -> Option<(f64, [f64; 2])> {
    r.models.get(model).map(|a| (a.t, a.t_ci95))
}

/// How far `model`'s accuracy at t leads `other`'s, as a fraction.
pub(super) fn lead(r: &Report, model: &str, other: &str) -> Option<f64> {
    Some(at(r, model)?.0 - at(r, other)?.0)
}
