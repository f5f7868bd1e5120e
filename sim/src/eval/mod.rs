//! `spwi-sim eval`: the paper's tables from held-out simulated episodes, computed by the
//! agent's own pipeline code (graph, models, window, vote, consensus — called as a
//! library, not re-implemented), plus the two baselines and the fault studies.
//!
//! - `robot.rs`: one robot's pipeline and the baselines; `cvm.rs`: the constant-velocity model;
//! - `fleet.rs`: N robots in lock step over one episode, message loss, dropouts, stuck cameras;
//! - `score.rs`: tallies and accuracies; `studies.rs`: `--all` and docs/RESULTS.md;
//!   `plots.rs`: the PNG figures of `--plots`.
//!
//! Held-out honesty: the episode seeds evaluated are checked against the training
//! episodes recorded in the model set's manifest, and refused if any is shared.

pub mod cvm;
pub mod fleet;
pub mod plots;
pub mod robot;
pub mod score;
pub mod studies;

use crate::dataset::episode_seed;
use crate::layout::Layout;
use crate::world::Scenario;
use anyhow::{bail, Context, Result};
use score::{Accuracy, Confusion};
use serde::Serialize;
use spwi_agent::manifest::Manifest;
use spwi_agent::model::ModelSet;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

/// Default evaluation seed: far from the training seeds (10 N + scenario).
pub const DEFAULT_SEED: u64 = 1000;

/// What goes wrong in the fleet during an evaluation.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Faults {
    /// Robots (the highest slots) that leave half-way through every episode.
    pub dropouts: usize,
    /// Probability that any one message between two robots is lost.
    pub loss: f64,
    /// Robots (the lowest slots) whose camera is stuck on an old frame that shows the
    /// worker: confident, plausible, wrong.
    pub faulty: usize,
}

impl Faults {
    /// A fleet where nothing goes wrong.
    pub fn none() -> Faults {
        Faults::default()
    }
}

pub struct EvalOptions {
    pub scenario: Scenario,
    pub robots: usize,
    pub models: Arc<ModelSet>,
    pub layout: Layout,
    pub layout_name: String,
    pub episodes: u32,
    pub seed: u64,
    /// Ticks per episode (10 per second).
    pub ticks: u32,
    pub faults: Faults,
}

#[derive(Debug, Clone, Serialize)]
pub struct PerRobot {
    pub robot: String,
    pub gnn: f64,
    pub ego: Accuracy,
    pub collective: Accuracy,
}

/// Every figure of one evaluation; `--json` writes it as is.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    pub scenario: u8,
    pub robots: usize,
    pub window: usize,
    pub frames: usize,
    pub horizon: usize,
    pub episodes: u32,
    pub ticks_per_episode: u32,
    pub seed: u64,
    pub model_set: String,
    pub layout: String,
    pub faults: Faults,
    /// gnn (t only), ego, collective, consensus (collective votes + consensus, on the
    /// ticks some robot decided), team_all_ticks (the same decision over every tick, no
    /// decision counting as wrong), cvm, cnn1d. Each model is scored on the ticks where
    /// it predicts: a robot's models when it sees the worker.
    pub models: BTreeMap<&'static str, Accuracy>,
    pub per_robot: Vec<PerRobot>,
    /// Share of decided ticks on which every live robot decided the same class for t.
    pub agreement: f64,
    /// Share of ticks on which the team had a decision (some robot saw the worker).
    pub coverage: f64,
    /// Rows: true class; columns: predicted class (at t).
    pub confusion: BTreeMap<&'static str, Confusion>,
    /// Predictions at t scored for the collective GRU (robot-ticks seeing the worker).
    pub samples: u64,
    pub seconds: f64,
    /// Wall time per robot frame (world, all models, consensus), microseconds.
    pub per_frame_us: f64,
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
    let started = Instant::now();
    let mut all = fleet::Tallies::default();
    for e in 0..o.episodes {
        all.merge(&fleet::episode(o, episode_seed(o.seed, e))?);
    }
    let seconds = started.elapsed().as_secs_f64();
    let m = &o.models.manifest;
    let mut models = BTreeMap::new();
    models.insert("gnn", Accuracy { t: all.gnn.accuracy().t, future: None });
    models.insert("ego", all.ego.accuracy());
    models.insert("collective", all.collective.accuracy());
    models.insert("consensus", all.consensus.accuracy());
    models.insert("team_all_ticks", all.team_all_ticks.accuracy());
    models.insert("cvm", all.cvm.accuracy());
    if m.models.cnn1d.is_some() {
        models.insert("cnn1d", all.cnn1d.accuracy());
    }
    let per_robot = all
        .per_robot
        .iter()
        .enumerate()
        .map(|(slot, [g, e, c])| PerRobot {
            robot: format!("r{slot}"),
            gnn: g.accuracy().t,
            ego: e.accuracy(),
            collective: c.accuracy(),
        })
        .collect();
    Ok(Report {
        scenario: o.scenario as u8,
        robots: o.robots,
        window: m.window,
        frames: m.frames(),
        horizon: m.horizon,
        episodes: o.episodes,
        ticks_per_episode: o.ticks,
        seed: o.seed,
        model_set: m.name.clone(),
        layout: o.layout_name.clone(),
        faults: o.faults.clone(),
        models,
        per_robot,
        agreement: if all.decided_ticks == 0 { 0.0 } else { all.agreed_ticks as f64 / all.decided_ticks as f64 },
        coverage: all.decided_ticks as f64 / all.ticks.max(1) as f64,
        confusion: BTreeMap::from([("ego", all.confusion_ego), ("collective", all.confusion_collective)]),
        samples: all.collective.samples(),
        seconds,
        per_frame_us: seconds * 1e6 / all.frames.max(1) as f64,
    })
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

/// The human-readable summary of one report.
pub fn print(r: &Report) {
    let pct = |v: f64| format!("{:5.1}", 100.0 * v);
    println!(
        "scenario {} · {} robots · {} ticks ({} frames) → {} ahead · model set {} · layout {} · {} episodes × {} ticks, seed {}",
        r.scenario,
        r.robots,
        r.window,
        r.frames,
        r.horizon,
        r.model_set,
        r.layout,
        r.episodes,
        r.ticks_per_episode,
        r.seed
    );
    if r.faults != Faults::default() {
        println!(
            "faults: {} dropping out half-way, {:.0}% messages lost, {} stuck cameras",
            r.faults.dropouts,
            100.0 * r.faults.loss,
            r.faults.faulty
        );
    }
    println!("  {:<12} {:>7} {:>10}", "model", "at t %", "t+1..H %");
    for name in ["gnn", "ego", "collective", "consensus", "team_all_ticks", "cvm", "cnn1d"] {
        if let Some(a) = r.models.get(name) {
            println!("  {:<12} {:>7} {:>10}", name, pct(a.t), a.future.map(pct).unwrap_or_else(|| "–".into()));
        }
    }
    for p in &r.per_robot {
        println!(
            "  robot {:<4} gnn {} · ego {} / {} · collective {} / {}",
            p.robot,
            pct(p.gnn),
            pct(p.ego.t),
            pct(p.ego.future.unwrap_or(0.0)),
            pct(p.collective.t),
            pct(p.collective.future.unwrap_or(0.0))
        );
    }
    println!(
        "  agreement {:.1}% · coverage {:.1}% · {} scored predictions · {:.1} s ({:.0} µs per robot frame)",
        100.0 * r.agreement,
        100.0 * r.coverage,
        r.samples,
        r.seconds,
        r.per_frame_us
    );
}

#[cfg(test)]
mod tests {
    use super::*;
    use spwi_agent::model::Backend;

    fn fixture() -> Arc<ModelSet> {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/fixture");
        ModelSet::load(&dir, Backend::Tract, None).unwrap()
    }

    fn options(models: Arc<ModelSet>, faults: Faults) -> EvalOptions {
        EvalOptions {
            scenario: Scenario::Dynamic,
            robots: 3,
            models,
            layout: Layout::default_layout(),
            layout_name: "test".into(),
            episodes: 2,
            seed: 5,
            ticks: 60,
            faults,
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
        let faults = Faults { loss: 0.2, dropouts: 1, faulty: 1 };
        let a = run(&options(m.clone(), faults.clone())).unwrap();
        let b = run(&options(m, faults)).unwrap();
        assert_eq!(without_timings(&a), without_timings(&b));
        assert!(a.samples > 0, "some robot saw the worker");
        for key in ["gnn", "ego", "collective", "consensus", "cvm"] {
            let acc = a.models[key];
            assert!((0.0..=1.0).contains(&acc.t), "{key}: {acc:?}");
        }
        assert_eq!(a.per_robot.len(), 3);
    }

    #[test]
    fn without_faults_every_robot_reaches_the_same_decision() {
        let r = run(&options(fixture(), Faults::none())).unwrap();
        assert_eq!(r.agreement, 1.0, "same votes, same deterministic consensus");
        let lossy = run(&options(fixture(), Faults { loss: 0.3, ..Faults::none() })).unwrap();
        assert!(lossy.agreement < 1.0, "robots holding different votes disagree sometimes");
    }

    #[test]
    fn training_episodes_are_refused() {
        let mut m = fixture().manifest.clone();
        m.fixture = false;
        m.extra.insert("dataset".into(), serde_json::json!({"exports": [{"seed": 13, "episodes": 300}]}));
        let e = check_held_out(&m, 13, 10).unwrap_err().to_string();
        assert!(e.contains("was used to train"), "{e}");
        check_held_out(&m, DEFAULT_SEED, 1000).unwrap();
        m.extra.remove("dataset");
        assert!(check_held_out(&m, DEFAULT_SEED, 10).unwrap_err().to_string().contains("cannot check"));
    }

    #[test]
    fn consensus_figures_match_a_hand_computed_case() {
        use spwi_agent::consensus::{decide, Ballot, Weights};
        use spwi_proto::{RobotId, StepVote};
        // Robot a sees 3 detections and says 2 (confidence 0.9); b sees 1 and says 1 (0.6);
        // c sees 4 and says 1 (0.3). α = β = 0.5:
        //   ṽ = 3/8, 1/8, 4/8;  c̃ = 0.9/1.8, 0.6/1.8, 0.3/1.8
        //   score(2) = 0.5·3/8 + 0.5·0.5 = 0.4375; score(1) = 0.5·5/8 + 0.5·0.5 = 0.5625
        let ids: Vec<RobotId> = ["a", "b", "c"].iter().map(|s| RobotId::new(*s).unwrap()).collect();
        let votes = [
            [StepVote { class: 2, confidence: 0.9 }],
            [StepVote { class: 1, confidence: 0.6 }],
            [StepVote { class: 1, confidence: 0.3 }],
        ];
        let mut ballots: Vec<Ballot<'_>> = [3, 1, 4]
            .iter()
            .zip(&ids)
            .zip(&votes)
            .map(|((&visibility, robot), steps)| Ballot { robot, visibility, steps })
            .collect();
        let d = decide(&mut ballots, Weights { alpha: 0.5, beta: 0.5 });
        assert_eq!(d[0].class, 1);
        assert!((d[0].score - 0.5625).abs() < 1e-6);
        let mut t = score::Tally::default();
        t.add(&[d[0].class], &[1]);
        t.add(&[2], &[1]);
        assert_eq!(t.accuracy().t, 0.5);
    }
}
