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

/// Which run of `--all` a table or the reading looks up.
#[derive(Debug, Clone, Copy)]
pub struct RunKey<'a> {
    pub model_set: &'a str,
    /// The floors as the command line names them (`heldout:0..50`); a run whose
    /// cameras a study forced carries them in its name ([`with_cameras`]).
    pub floors: &'a str,
    pub robots: usize,
    pub cameras: CameraPolicy,
    /// Whether the fleet worked on the floor before each episode (warm station maps).
    pub warm: bool,
}

impl RunKey<'_> {
    pub fn matches(&self, r: &Report) -> bool {
        r.model_set == self.model_set
            && r.robots == self.robots
            && r.cameras == Some(self.cameras)
            && (r.warm_map_s > 0.0) == self.warm
            && (r.floors == self.floors || r.floors == with_cameras(self.floors, self.cameras))
    }

    /// The first of `runs` it names.
    pub fn find<'r>(&self, runs: &[&'r Report]) -> Option<&'r Report> {
        runs.iter().copied().find(|r| self.matches(r))
    }
}

/// The built-in floor with two stations swapped.
pub const MOVED_FLOORS: &str = "factory-moved.toml (two stations swapped)";
/// The built-in floor mirrored: every relation kept, every place moved.
pub const MIRRORED_FLOORS: &str = "factory.toml mirrored";

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
        (MOVED_FLOORS.to_owned(), vec![NamedLayout { name: "factory-moved".into(), layout: moved }]),
        (
            MIRRORED_FLOORS.to_owned(),
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

fn load(root: &Path, window: usize, horizon: usize, frames: Option<usize>) -> Result<std::sync::Arc<ModelSet>> {
    ModelSet::load(&find_model_set(root, window, horizon, frames)?, Backend::Tract, None)
}

/// The model sets of `reports`, each once, in order, as `a`, `b`.
pub(super) fn set_names(reports: &[Report]) -> String {
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
    let one_with = |scenario: Scenario,
                    robots: usize,
                    models: &std::sync::Arc<ModelSet>,
                    seed: u64,
                    faults: Faults,
                    tick: TickConfig,
                    cnn1d: bool|
     -> Result<Report> {
        let r = run(&EvalOptions {
            scenario,
            workers: 1,
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
            plan_error_m: None,
            cnn1d,
        })?;
        super::print(&r);
        println!();
        Ok(r)
    };
    let one = |scenario: Scenario, robots: usize, models: &std::sync::Arc<ModelSet>, seed: u64, faults: Faults| {
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
    for scenario in Scenario::ALL {
        st.scenarios.push(one_with(scenario, 3, &default, s.seed, Faults::none(), TickConfig::default(), true)?);
    }
    for robots in [1, 2, 3, 4, 6, 8] {
        st.robots.push(one(Scenario::Dynamic, robots, &default, s.seed, Faults::none())?);
    }
    for (w, h) in [(10, 10), (20, 20), (30, 30)] {
        let same_design = s.models_root.join(WINDOW_STUDY_DESIGN);
        let set = match w {
            20 if same_design.join("manifest.json").is_file() => ModelSet::load(&same_design, Backend::Tract, None)?,
            20 => default.clone(),
            _ => load(&s.models_root, w, h, None)?,
        };
        for robots in [1, 3] {
            st.horizons.push(one(Scenario::Dynamic, robots, &set, s.seed, Faults::none())?);
        }
    }
    for frames in [10, 5, 3] {
        let set = load(&s.models_root, 10, 10, Some(frames))?;
        st.resolution.push(one(Scenario::Dynamic, 3, &set, s.seed, Faults::none())?);
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
        st.faults.push(one_with(Scenario::Dynamic, 4, &default, s.seed, faults.clone(), paper_protocol(), false)?);
        for consensus in [ConsensusRule::Paper, ConsensusRule::Trust] {
            let ours = TickConfig { consensus, ..TickConfig::default() };
            st.faults.push(one_with(Scenario::Dynamic, 4, &default, s.seed, faults.clone(), ours, false)?);
        }
    }
    if let Some(r) = st.scenarios.iter().find(|r| r.scenario == Scenario::Dynamic) {
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
            workers: 1,
            robots,
            models: models.clone(),
            floors,
            floors_name: name,
            episodes: s.episodes,
            seed,
            ticks: s.ticks,
            faults: Faults::none(),
            tick: TickConfig::default(),
            warm_map_ticks: warm_s * spwi_proto::TICKS_PER_SECOND,
            plan_error_m: None,
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
