//! The `spwi-sim` command line: `world`, `demo`, `dataset`, `eval`, `bench`, `render`,
//! `stats`, `layout`. Every tool that runs a world takes the same [`WorldArgs`].

use crate::world_args::{check_robots, run_layout, LayoutArgs, WorldArgs};
use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use spwi_agent::cli::{init_tracing, spawn_signal_handler};
use spwi_agent::config::LogFormat;
use spwi_proto::FleetId;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

#[derive(Parser)]
#[command(name = "spwi-sim", version, about = "The simulated factory that stands in for Isaac Sim")]
struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Publish every live agent's detections and the truth over Zenoh at 10 Hz.
    World {
        #[arg(long, default_value = "default")]
        fleet: FleetId,
        #[command(flatten)]
        world: WorldArgs,
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Zenoh's own config file (json5).
        #[arg(long, env = "ZENOH_CONFIG")]
        zenoh_config: Option<PathBuf>,
        /// Zenoh setting override KEY:VALUE (VALUE in json5), repeatable.
        #[arg(long = "cfg", value_name = "KEY:VALUE")]
        cfg: Vec<String>,
        /// Tick period in milliseconds.
        #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u64).range(1..=10_000))]
        tick_ms: u64,
    },
    /// Watch a fleet decide: the world and N agents in this process, a live view each
    /// second, a summary at the end (or on Ctrl-C).
    Demo {
        #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u64).range(1..=8))]
        robots: u64,
        #[command(flatten)]
        world: WorldArgs,
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// How long to run (e.g. 60s, 2m).
        #[arg(long, default_value = "60s", value_parser = crate::demo::parse_duration)]
        duration: Duration,
        /// Stop one agent after this long, to watch the fleet shrink.
        #[arg(long, value_parser = crate::demo::parse_duration)]
        kill_after: Option<Duration>,
        /// Start one more agent after this long, to watch it join.
        #[arg(long, value_parser = crate::demo::parse_duration)]
        join_after: Option<Duration>,
        /// Model set folder (default: the agent's default).
        #[arg(long)]
        models: Option<PathBuf>,
        /// Write the summary as JSON to this file.
        #[arg(long)]
        json: Option<PathBuf>,
        /// No live view, only the summary.
        #[arg(long)]
        quiet: bool,
        /// Serve a live page (floor map, votes, decision, accuracy) on this address.
        #[arg(long, value_name = "ADDR")]
        http: Option<std::net::SocketAddr>,
    },
    /// Export training data (.npy arrays + dataset.json) for the models.
    Dataset {
        #[command(flatten)]
        world: WorldArgs,
        #[arg(long, default_value_t = 100)]
        episodes: u32,
        #[arg(long, default_value_t = 4)]
        robots: usize,
        /// Ticks per episode (10 per second).
        #[arg(long, default_value_t = 300)]
        ticks: u32,
        #[arg(long, default_value_t = 1)]
        seed: u64,
        #[arg(long)]
        out: PathBuf,
        /// Keep the graph of every Nth tick per robot for the spatial part.
        #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u32).range(1..))]
        spatial_every: u32,
        /// The GCN that computes the temporal part's embeddings (via the agent's code):
        /// a model set folder, or a lone gcn .onnx file.
        #[arg(long, value_name = "MODEL_SET_OR_ONNX")]
        gcn: Option<PathBuf>,
        /// Graph size, unless --gcn names a model set (then: its manifest's).
        #[arg(long, default_value_t = 16)]
        max_nodes: usize,
        /// Edge weights, unless --gcn names a model set (then: its manifest's).
        #[arg(long, default_value = "proximity", value_parser = parse_edge_weight)]
        edge_weight: spwi_agent::graph::EdgeWeight,
        /// Also write the worker node's 1024-d feature per row (the 1D-CNN baseline's input).
        #[arg(long)]
        human_features: bool,
    },
    /// Reproduce the paper's tables on held-out episodes with the agent's own pipeline.
    Eval {
        #[command(flatten)]
        world: WorldArgs,
        #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u64).range(1..=8))]
        robots: u64,
        /// Ticks of history (selects the model set, with --horizon and --frames).
        #[arg(long, default_value_t = 20)]
        window: usize,
        #[arg(long, default_value_t = 20)]
        horizon: usize,
        /// Frames of the window fed to the models (default: all).
        #[arg(long)]
        frames: Option<usize>,
        /// A model set folder (instead of choosing by --window/--horizon/--frames).
        #[arg(long)]
        models: Option<PathBuf>,
        #[arg(long, default_value_t = crate::eval::DEFAULT_EPISODES, value_parser = clap::value_parser!(u32).range(1..))]
        episodes: u32,
        /// Evaluation seed; episodes the models were trained on are refused.
        #[arg(long, default_value_t = crate::eval::DEFAULT_SEED)]
        seed: u64,
        /// Ticks per episode (10 per second).
        #[arg(long, default_value_t = 300, value_parser = clap::value_parser!(u32).range(1..))]
        ticks: u32,
        /// Robots (highest slots) that leave half-way through each episode.
        #[arg(long, default_value_t = 0)]
        dropouts: usize,
        /// Probability that a message between robots is lost (0-1).
        #[arg(long, default_value_t = 0.0)]
        loss: f64,
        /// Robots (lowest slots) whose camera is stuck on a frame showing the worker.
        #[arg(long, default_value_t = 0)]
        faulty: usize,
        /// Mean delay of a message between robots, ms (default: loopback-like, 0.5 ms).
        #[arg(long, default_value_t = 0.0)]
        delay: f64,
        /// Write every figure as JSON to this file.
        #[arg(long)]
        json: Option<PathBuf>,
        /// Every study (tables II-IV, robots, horizons, resolution, faults, an unseen
        /// layout); with --markdown FILE also writes the results page.
        #[arg(long)]
        all: bool,
        #[arg(long, requires = "all")]
        markdown: Option<PathBuf>,
        /// Write PNG figures into this folder (with --all: robots, horizons, resolution
        /// and confusion matrices; alone: the confusion matrices).
        #[arg(long, value_name = "DIR")]
        plots: Option<PathBuf>,
    },
    /// Measure a fleet: the world here, N spwi-agent processes over Zenoh on loopback.
    Bench {
        #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u64).range(1..=64))]
        robots: u64,
        /// How long to measure, after 2 s of warm-up (e.g. 20s).
        #[arg(long, default_value = "20s", value_parser = crate::demo::parse_duration)]
        duration: Duration,
        /// Publish the next tick as soon as every robot decided (the maximum rate).
        #[arg(long)]
        free: bool,
        #[arg(long, default_value = "3", value_parser = crate::world_args::parse_scenario)]
        scenario: spwi_world::world::Scenario,
        /// The spwi-agent binary (default: next to this one).
        #[arg(long)]
        agent: Option<PathBuf>,
        /// Model set folder for the agents (default: theirs).
        #[arg(long)]
        models: Option<PathBuf>,
        #[arg(long)]
        json: Option<PathBuf>,
    },
    /// Draw the floor and every robot's detections at one tick into a PNG.
    Render {
        #[command(flatten)]
        world: WorldArgs,
        #[arg(long, default_value_t = 1)]
        seed: u64,
        #[arg(long, default_value_t = 100)]
        tick: u64,
        #[arg(long, default_value_t = 4)]
        robots: usize,
        #[arg(long, default_value = "scene.png")]
        out: PathBuf,
    },
    /// Measure how hard a scenario is (who sees the worker, detections, phases, goal changes).
    Stats {
        #[command(flatten)]
        world: WorldArgs,
        #[arg(long, default_value_t = 4)]
        robots: usize,
        #[arg(long, default_value_t = 20)]
        episodes: u32,
        /// Ticks per episode (10 per second).
        #[arg(long, default_value_t = 600)]
        ticks: u32,
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Print JSON instead of a table.
        #[arg(long)]
        json: bool,
        /// Instead: coverage (ticks on which some robot sees the worker) for fleets of
        /// 1-8 robots under `fixed` and `track` cameras.
        #[arg(long)]
        coverage: bool,
    },
    /// Write a floor to a TOML file: generated from a seed, or a mirrored copy.
    Layout(LayoutArgs),
}

fn run(args: Args) -> Result<()> {
    match args.command {
        Command::World { fleet, world, seed, zenoh_config, cfg, tick_ms } => {
            init_tracing(LogFormat::Human);
            let opts = crate::service::WorldOptions {
                fleet,
                scenario: world.scenario,
                seed,
                layout: world.floor()?.layout,
                zenoh: spwi_agent::zenoh_config::build(zenoh_config.as_deref(), &cfg)?,
                tick: Duration::from_millis(tick_ms),
            };
            let rt = tokio::runtime::Builder::new_multi_thread().enable_all().build()?;
            rt.block_on(async {
                let (tx, rx) = tokio::sync::watch::channel(false);
                spawn_signal_handler(tx);
                crate::service::run(opts, rx).await
            })
        }
        Command::Demo { robots, world, seed, duration, kill_after, join_after, models, json, quiet, http } => {
            init_tracing(LogFormat::Human);
            let mut agent = spwi_agent::config::AgentConfig::load(None)?;
            if let Some(m) = models {
                agent.models.dir = m;
            }
            let set = spwi_agent::daemon::load_models(&agent)?;
            let opts = crate::demo::DemoOptions {
                robots: robots as usize,
                scenario: world.scenario,
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
        Command::Dataset {
            world,
            episodes,
            robots,
            ticks,
            seed,
            out,
            spatial_every,
            gcn,
            max_nodes,
            edge_weight,
            human_features,
        } => {
            let floors = world.floors()?;
            check_robots(robots, &floors)?;
            if episodes == 0 || ticks == 0 {
                anyhow::bail!("--episodes and --ticks must be at least 1");
            }
            let (gcn, max_nodes, edge_weight) = match gcn {
                Some(dir) if dir.is_dir() => {
                    let m = spwi_agent::manifest::Manifest::load(&dir)?;
                    (Some(dir.join(&m.models.gcn.file)), m.max_nodes, m.edge_weight)
                }
                file => (file, max_nodes, edge_weight),
            };
            if !(1..=256).contains(&max_nodes) {
                anyhow::bail!("--max-nodes {max_nodes}: must be within 1..=256");
            }
            let started = std::time::Instant::now();
            let (samples, rows) = crate::dataset::export(&crate::dataset::DatasetOptions {
                scenario: world.scenario,
                episodes,
                robots,
                ticks,
                seed,
                out: out.clone(),
                spatial_every,
                floors,
                max_nodes,
                edge_weight,
                gcn,
                human_features,
            })?;
            println!(
                "wrote {} ({samples} graph samples, {rows} temporal rows) in {:.1} s",
                out.display(),
                started.elapsed().as_secs_f64()
            );
            Ok(())
        }
        Command::Eval {
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
            delay,
            json,
            all,
            markdown,
            plots,
        } => {
            let floors = world.floors()?;
            let robots = robots as usize;
            check_robots(robots, &floors)?;
            if !(0.0..=1.0).contains(&loss) {
                anyhow::bail!("--loss {loss}: a probability, 0 to 1");
            }
            if !(0.0..=10_000.0).contains(&delay) {
                anyhow::bail!("--delay {delay}: milliseconds, 0 to 10000");
            }
            if dropouts >= robots || faulty > robots {
                anyhow::bail!(
                    "--dropouts {dropouts} / --faulty {faulty}: must leave at least one of the {robots} robots working"
                );
            }
            let root = std::path::Path::new("models");
            if all {
                let settings = crate::eval::studies::Settings {
                    models_root: root.to_owned(),
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
                    let mut command = format!(
                        "spwi-sim eval --all --episodes {episodes} --seed {seed} --markdown {}",
                        path.display()
                    );
                    // Figures are linked relative to the page when they sit beside it.
                    let page_dir = path.parent().unwrap_or(std::path::Path::new(""));
                    let figures = plots.as_ref().map(|d| {
                        command += &format!(" --plots {}", d.display());
                        d.strip_prefix(page_dir).map(|p| p.to_owned()).unwrap_or_else(|_| d.clone())
                    });
                    let page = crate::eval::studies::markdown(&studies, &command, &settings, figures.as_deref());
                    std::fs::write(&path, page)?;
                    println!("wrote {}", path.display());
                }
                return Ok(());
            }
            let dir = match models {
                Some(d) => d,
                None => crate::eval::find_model_set(root, window, horizon, frames)?,
            };
            let models = spwi_agent::model::ModelSet::load(&dir, spwi_agent::model::Backend::Tract, None)?;
            let report = crate::eval::run(&crate::eval::EvalOptions {
                scenario: world.scenario,
                robots,
                models,
                floors,
                floors_name: world.describe(),
                episodes,
                seed,
                ticks,
                faults: crate::eval::Faults { dropouts, loss, faulty, delay_ms: delay },
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
        Command::Bench { robots, duration, free, scenario, agent, models, json } => {
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
            };
            let rt = tokio::runtime::Builder::new_multi_thread().enable_all().build()?;
            let report = rt.block_on(crate::bench::run(&opts))?;
            crate::bench::print(&report);
            if let Some(path) = json {
                std::fs::write(&path, serde_json::to_string_pretty(&report)?)?;
            }
            Ok(())
        }
        Command::Render { world: w, seed, tick, robots, out } => {
            let floor = w.floor()?;
            check_robots(robots, std::slice::from_ref(&floor))?;
            let world = spwi_world::world::World::new(floor.layout, w.scenario, seed, robots);
            crate::render::render_tick(world, robots, tick, &out)?;
            println!("wrote {}", out.display());
            Ok(())
        }
        Command::Stats { world, robots, episodes, ticks, seed, json, coverage } => {
            let floors = world.floors()?;
            if coverage {
                let c = crate::stats::coverage(&floors, world.scenario, episodes, ticks, seed);
                if json {
                    println!("{}", serde_json::to_string_pretty(&c)?);
                } else {
                    crate::stats::print_coverage(&c);
                }
                return Ok(());
            }
            check_robots(robots, &floors)?;
            let d = crate::stats::measure(&floors, world.scenario, robots, episodes, ticks, seed);
            if json {
                println!("{}", serde_json::to_string_pretty(&d)?);
            } else {
                println!(
                    "scenario {} — {} episodes × {} ticks, {} robots, seed {seed}",
                    d.scenario, episodes, ticks, robots
                );
                let seen: Vec<String> = d.worker_seen.iter().map(|s| format!("{:.0}%", s * 100.0)).collect();
                println!("  worker seen, per robot        {}", seen.join("  "));
                println!("  no robot sees the worker      {:.1}%", d.nobody_sees_worker * 100.0);
                println!("  detections per frame          {:.2}", d.mean_detections_per_frame);
                println!(
                    "  phases: moving / transition / stationary   {:.0}% / {:.0}% / {:.0}%",
                    d.phase_moving * 100.0,
                    d.phase_transition * 100.0,
                    d.phase_stationary * 100.0
                );
                println!("  goal changes per trip         {:.2}", d.goal_changes_per_trip);
                println!("  near both stations of a close pair  {:.1}%", d.near_close_stations * 100.0);
            }
            Ok(())
        }
        Command::Layout(a) => run_layout(&a),
    }
}

/// `main` of `spwi-sim`.
pub fn main() -> ExitCode {
    match run(Args::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("spwi-sim: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn parse_edge_weight(s: &str) -> Result<spwi_agent::graph::EdgeWeight, String> {
    serde_json::from_value(serde_json::Value::String(s.to_owned()))
        .map_err(|_| format!("unknown edge weight {s:?}; use \"proximity\" or \"distance\""))
}
