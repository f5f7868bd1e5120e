//! `spwi-sim eval`'s command line: one configuration (a table on stdout, `--json`,
//! `--plots`) or, with `--all`, every study and the results page.

use crate::world_args::{check_robots, WorldArgs};
use anyhow::{Context, Result};
use std::path::PathBuf;

/// The arguments of `spwi-sim eval`.
#[derive(clap::Args, Debug)]
pub struct EvalArgs {
    #[command(flatten)]
    pub world: WorldArgs,
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u64).range(1..=8))]
    pub robots: u64,
    /// Ticks of history (selects the model set, with --horizon and --frames).
    #[arg(long, default_value_t = 20)]
    pub window: usize,
    #[arg(long, default_value_t = 20)]
    pub horizon: usize,
    /// Frames of the window fed to the models (default: all).
    #[arg(long)]
    pub frames: Option<usize>,
    /// A model set folder (instead of choosing by --window/--horizon/--frames).
    #[arg(long)]
    pub models: Option<PathBuf>,
    #[arg(long, default_value_t = crate::eval::DEFAULT_EPISODES, value_parser = clap::value_parser!(u32).range(1..))]
    pub episodes: u32,
    /// Evaluation seed; episodes the models were trained on are refused.
    #[arg(long, default_value_t = crate::eval::DEFAULT_SEED)]
    pub seed: u64,
    /// Ticks per episode (10 per second).
    #[arg(long, default_value_t = 300, value_parser = clap::value_parser!(u32).range(1..))]
    pub ticks: u32,
    /// Robots (highest slots) that leave half-way through each episode.
    #[arg(long, default_value_t = 0)]
    pub dropouts: usize,
    /// Probability that a message between robots is lost (0-1).
    #[arg(long, default_value_t = 0.0)]
    pub loss: f64,
    /// Robots (lowest slots) whose camera is stuck on a frame showing the worker.
    #[arg(long, default_value_t = 0)]
    pub faulty: usize,
    /// Robots (the slots after the stuck ones) whose camera loops a 5 s clip of the
    /// worker it recorded once.
    #[arg(long, default_value_t = 0)]
    pub looping: usize,
    /// Robots (the slots after the lying cameras) that vote a wrong station every tick
    /// at confidence 1, claiming the best view: members whose word is false.
    #[arg(long, default_value_t = 0)]
    pub liars: usize,
    /// How far off one robot's floor pose is (metres; the slot after the liars).
    #[arg(long, value_name = "METRES", default_value_t = 0.0)]
    pub pose_error: f64,
    /// How far one robot's clock (the highest slot) runs ahead of the others' (ms;
    /// negative: behind).
    #[arg(long, value_name = "MS", default_value_t = 0, allow_negative_numbers = true)]
    pub clock_offset: i64,
    /// Seconds the fleet has already worked on the floor when an episode starts: its
    /// station maps are what its robots built watching another worker that long (0:
    /// every episode starts with empty maps, a fleet's first seconds on a new floor).
    #[arg(long, value_name = "SECONDS", default_value_t = 0, value_parser = clap::value_parser!(u32).range(0..=3600))]
    pub warm_map: u32,
    /// Give every robot a floor plan: `truth`, the floor's own stations (the only one
    /// the generated floors have).
    #[arg(long, value_name = "truth", value_parser = ["truth"])]
    pub floor_plan: Option<String>,
    /// With --floor-plan: each station of the plan displaced by up to this many metres.
    #[arg(long, value_name = "METRES", default_value_t = 0.0, requires = "floor_plan")]
    pub plan_error: f32,
    /// Mean delay of a message between robots, ms (default: loopback-like, 0.5 ms).
    #[arg(long, default_value_t = 0.0)]
    pub delay: f64,
    /// The robots' settings: the `[tick]` section of this agent config (relays, stale
    /// feeds, deadlines, consensus weights) instead of the daemon's defaults.
    #[arg(long, value_name = "FILE", conflicts_with = "all")]
    pub agent_config: Option<PathBuf>,
    /// Write every figure as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Every study (tables II-IV, robots, horizons, resolution, faults, floors the
    /// models never saw); with --markdown FILE also writes the results page.
    #[arg(long)]
    pub all: bool,
    #[arg(long, requires = "all")]
    pub markdown: Option<PathBuf>,
    /// Write PNG figures into this folder (with --all: robots, horizons, resolution
    /// and confusion matrices; alone: the confusion matrices).
    #[arg(long, value_name = "DIR")]
    pub plots: Option<PathBuf>,
}

/// `spwi-sim eval`: parses nothing more, runs the tool.
pub fn main(a: EvalArgs) -> Result<()> {
    let EvalArgs {
        world,
        robots,
        window,
        horizon,
        frames,
        models,
        episodes,
        seed,
        ticks,
        dropouts,
        loss,
        faulty,
        looping,
        liars,
        pose_error,
        clock_offset,
        warm_map,
        floor_plan,
        plan_error,
        delay,
        agent_config,
        json,
        all,
        markdown,
        plots,
    } = a;
    let floors = world.floors()?;
    let robots = robots as usize;
    check_robots(robots, &floors)?;
    if !(0.0..=1.0).contains(&loss) {
        anyhow::bail!("--loss {loss}: a probability, 0 to 1");
    }
    if !(0.0..=10_000.0).contains(&delay) {
        anyhow::bail!("--delay {delay}: milliseconds, 0 to 10000");
    }
    if !(0.0..=100.0).contains(&pose_error) {
        anyhow::bail!("--pose-error {pose_error}: metres, 0 to 100");
    }
    if !(0.0..=20.0).contains(&plan_error) {
        anyhow::bail!("--plan-error {plan_error}: metres, 0 to 20");
    }
    if all && floor_plan.is_some() {
        anyhow::bail!("--all --floor-plan: the results page's studies map the floors from detections alone");
    }
    if clock_offset.unsigned_abs() > 400 {
        anyhow::bail!("--clock-offset {clock_offset}: ms, within ±400 (the robots take ticks 5 back, 2 ahead)");
    }
    if dropouts >= robots || faulty + looping + liars + usize::from(pose_error > 0.0) >= robots {
        anyhow::bail!(
            "--dropouts {dropouts} / --faulty {faulty} + --looping {looping} + --liars {liars}: must leave at least one of the {robots} robots working"
        );
    }
    let tick = match &agent_config {
        Some(path) => {
            let c = spwi_agent::config::AgentConfig::from_file(path)?;
            c.validate().with_context(|| format!("config {}", path.display()))?;
            c.tick
        }
        None => Default::default(),
    };
    let root = spwi_core::model::locate::sets_folder(spwi_core::model::locate::DEFAULT_SET)?;
    if all && world.workers != 1 {
        anyhow::bail!("--all --workers {}: the results page's studies are of one worker", world.workers);
    }
    if all {
        let settings = crate::eval::studies::Settings {
            models_root: root.clone(),
            floors,
            floors_name: world.describe(),
            camera: world.camera,
            episodes,
            seed,
            ticks,
        };
        let studies = crate::eval::studies::run_all(&settings)?;
        if let Some(path) = json {
            std::fs::write(&path, serde_json::to_string_pretty(&studies)?)?;
        }
        if let Some(dir) = &plots {
            for f in crate::eval::plots::write_all(&studies, dir)? {
                println!("wrote {}", f.display());
            }
        }
        if let Some(path) = markdown {
            let mut command = format!("spwi-sim eval --all --episodes {episodes} --seed {seed}");
            for l in &world.layouts {
                command += &format!(" --layouts {l}");
            }
            if let Some(c) = world.camera {
                command += &format!(" --camera {}", format!("{c:?}").to_lowercase());
            }
            command += &format!(" --markdown {}", path.display());
            // Figures are linked relative to the page when they sit beside it.
            let page_dir = path.parent().unwrap_or(std::path::Path::new(""));
            let figures = plots.as_ref().map(|d| {
                command += &format!(" --plots {}", d.display());
                d.strip_prefix(page_dir).map(|p| p.to_owned()).unwrap_or_else(|_| d.clone())
            });
            let page = crate::eval::page::markdown(&studies, &command, &settings, figures.as_deref());
            std::fs::write(&path, page)?;
            println!("wrote {}", path.display());
        }
        return Ok(());
    }
    let dir = match models {
        Some(d) => d,
        None => crate::eval::find_model_set(&root, window, horizon, frames)?,
    };
    let models = spwi_core::model::ModelSet::load(&dir, spwi_core::model::Backend::Tract, None)?;
    let report = crate::eval::run(&crate::eval::EvalOptions {
        scenario: world.scenario,
        workers: usize::from(world.workers),
        robots,
        models,
        floors,
        floors_name: world.describe(),
        episodes,
        seed,
        ticks,
        faults: crate::eval::Faults {
            dropouts,
            loss,
            faulty,
            looping,
            liars,
            pose_error_m: pose_error,
            clock_offset_ms: clock_offset,
            delay_ms: delay,
        },
        tick,
        warm_map_ticks: warm_map * spwi_proto::TICKS_PER_SECOND,
        plan_error_m: floor_plan.map(|_| plan_error),
        cnn1d: true,
    })?;
    crate::eval::print(&report);
    if let Some(path) = json {
        std::fs::write(&path, serde_json::to_string_pretty(&report)?)?;
    }
    if let Some(dir) = plots {
        std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
        for (name, c) in &report.confusion {
            let path = dir.join(format!("confusion_{name}.png"));
            crate::eval::plots::confusion(&path, &format!("{name}: share of each true station"), c)?;
            println!("wrote {}", path.display());
        }
    }
    Ok(())
}
