//! The `spwi-sim` command line: `world`, `demo`, `dataset`, `eval`, `bench`, `render`,
//! `stats`, `layout`. Every tool that runs a world takes the same
//! [`crate::world_args::WorldArgs`].

//! Each tool owns its arguments and its `main` in its own module; this file only
//! dispatches.

use anyhow::Result;
use clap::{Parser, Subcommand};
use std::process::ExitCode;

#[derive(Parser)]
#[command(name = "spwi-sim", version, about = "The simulated factory that stands in for Isaac Sim")]
struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Publish every live agent's detections and the truth over Zenoh at 10 Hz.
    World(crate::service::WorldServiceArgs),
    /// Watch a fleet decide: the world and N agents in this process, a live view each
    /// second, a summary at the end (or on Ctrl-C).
    Demo(crate::demo::DemoArgs),
    /// Export training data (.npy arrays + dataset.json) for the models.
    Dataset(crate::dataset::DatasetArgs),
    /// Reproduce the paper's tables on held-out episodes: the daemon's own engines on an
    /// in-memory bus, every figure with its 95 % confidence interval.
    Eval(crate::eval::command::EvalArgs),
    /// Measure a fleet: the world here, N spwi-agent processes over Zenoh on loopback.
    Bench(crate::bench::BenchArgs),
    /// Draw the floor and every robot's detections at one tick into a PNG.
    Render(crate::render::RenderArgs),
    /// Measure how hard a scenario is (who sees the worker, detections, phases, goal changes).
    Stats(crate::stats::StatsArgs),
    /// Write a floor to a TOML file: generated from a seed, or a mirrored copy.
    Layout(crate::layout::LayoutArgs),
}

fn run(args: Args) -> Result<()> {
    match args.command {
        Command::World(a) => crate::service::main(a),
        Command::Demo(a) => crate::demo::main(a),
        Command::Dataset(a) => crate::dataset::main(a),
        Command::Eval(a) => crate::eval::command::main(a),
        Command::Bench(a) => crate::bench::main(a),
        Command::Render(a) => crate::render::main(a),
        Command::Stats(a) => crate::stats::main(a),
        Command::Layout(a) => crate::layout::main(a),
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
