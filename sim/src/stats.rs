//! `spwi-sim stats`: figures that show the task is not trivial — how often each robot
//! sees the worker, how many detections a frame holds, how the worker's time splits
//! between moving, transitions and working, how often it changes its mind, how often
//! it is near both stations of a close pair — and, with `--coverage`, how often some
//! robot of a fleet of 1 to 8 sees the worker under each camera policy.

use crate::world_args::{check_robots, WorldArgs};
use anyhow::Result;
use serde::Serialize;
use spwi_proto::{RobotId, WorkerPhase};
use spwi_world::generate::NamedLayout;
use spwi_world::geometry::dist;
use spwi_world::layout::CameraPolicy;
use spwi_world::world::{Scenario, World};

#[derive(Debug, Clone, Serialize)]
pub struct Difficulty {
    pub scenario: u8,
    pub episodes: u32,
    pub ticks_per_episode: u32,
    /// Per robot slot: share of ticks in which it detects the worker.
    pub worker_seen: Vec<f64>,
    /// Share of ticks in which no robot detects the worker.
    pub nobody_sees_worker: f64,
    pub mean_detections_per_frame: f64,
    pub phase_moving: f64,
    pub phase_transition: f64,
    pub phase_stationary: f64,
    /// Goal changes mid-way per trip started.
    pub goal_changes_per_trip: f64,
    /// Share of ticks the worker is within 3 m of both work spots of a close pair.
    pub near_close_stations: f64,
}

/// Episode `e` runs on floor `e mod floors`.
pub fn measure(
    floors: &[NamedLayout],
    scenario: Scenario,
    workers: usize,
    robots: usize,
    episodes: u32,
    ticks: u32,
    seed: u64,
) -> Difficulty {
    let ids: Vec<RobotId> = (0..robots).map(|i| RobotId::new(format!("r{i}")).expect("valid id")).collect();
    let mut seen = vec![0u64; robots];
    let (mut nobody, mut detections, mut frames) = (0u64, 0u64, 0u64);
    let (mut moving, mut transition, mut stationary, mut near) = (0u64, 0u64, 0u64, 0u64);
    let (mut changes, mut trips) = (0u64, 0u64);
    for e in 0..episodes {
        let layout = &floors[e as usize % floors.len()].layout;
        let pairs: Vec<_> = layout
            .close_pairs()
            .iter()
            .map(|&(a, b)| (layout.station(a).work_spot, layout.station(b).work_spot))
            .collect();
        let mut w = World::with_workers(layout.clone(), scenario, seed.wrapping_add(e as u64), robots, workers);
        for _ in 0..ticks {
            w.step();
            let mut any = false;
            for (slot, id) in ids.iter().enumerate() {
                let f = w.observe(slot, id);
                if f.worker().is_some() {
                    seen[slot] += 1;
                    any = true;
                }
                detections += f.visibility() as u64;
                frames += 1;
            }
            nobody += u64::from(!any);
            match w.worker().phase {
                WorkerPhase::Moving => moving += 1,
                WorkerPhase::Transition => transition += 1,
                WorkerPhase::Stationary => stationary += 1,
            }
            let p = w.worker().position;
            near += u64::from(pairs.iter().any(|&(a, b)| dist(p, a) < 3.0 && dist(p, b) < 3.0));
        }
        changes += w.worker().goal_changes as u64;
        trips += w.worker().arrivals as u64 + 1;
    }
    let n = (episodes as u64 * ticks as u64).max(1) as f64;
    Difficulty {
        scenario: scenario as u8,
        episodes,
        ticks_per_episode: ticks,
        worker_seen: seen.iter().map(|&s| s as f64 / n).collect(),
        nobody_sees_worker: nobody as f64 / n,
        mean_detections_per_frame: detections as f64 / frames.max(1) as f64,
        phase_moving: moving as f64 / n,
        phase_transition: transition as f64 / n,
        phase_stationary: stationary as f64 / n,
        goal_changes_per_trip: changes as f64 / trips.max(1) as f64,
        near_close_stations: near as f64 / n,
    }
}

/// Coverage of fleets of 1..=8 robots under one camera policy.
#[derive(Debug, Clone, Serialize)]
pub struct Coverage {
    pub camera: CameraPolicy,
    /// Index k: share of ticks on which some robot of a fleet of k + 1 sees the worker.
    pub by_robots: Vec<f64>,
}

/// Coverage for fleets of 1-8 robots under `fixed` and `track` cameras (episode e on
/// floor e mod floors; the same worker walks whatever the fleet).
pub fn coverage(
    floors: &[NamedLayout],
    scenario: Scenario,
    workers: usize,
    episodes: u32,
    ticks: u32,
    seed: u64,
) -> Vec<Coverage> {
    let ids: Vec<spwi_proto::RobotId> =
        (0..8).map(|i| spwi_proto::RobotId::new(format!("r{i}")).expect("valid id")).collect();
    [CameraPolicy::Fixed, CameraPolicy::Track]
        .into_iter()
        .map(|camera| {
            let by_robots = (1..=8usize)
                .map(|n| {
                    let mut seen = 0u64;
                    for e in 0..episodes {
                        let mut layout = floors[e as usize % floors.len()].layout.clone();
                        layout.camera.policy = camera;
                        let n = n.min(layout.robots.len());
                        let mut w = World::with_workers(layout, scenario, seed.wrapping_add(e as u64), n, workers);
                        for _ in 0..ticks {
                            w.step();
                            let mut any = false;
                            for (slot, id) in ids.iter().enumerate().take(n) {
                                any |= w.observe(slot, id).worker().is_some();
                            }
                            seen += u64::from(any);
                        }
                    }
                    seen as f64 / (episodes as u64 * ticks as u64).max(1) as f64
                })
                .collect();
            Coverage { camera, by_robots }
        })
        .collect()
}

pub fn print_coverage(c: &[Coverage]) {
    println!("coverage: share of ticks on which some robot sees the worker");
    println!("  {:<8} {}", "robots", (1..=8).map(|n| format!("{n:>6}")).collect::<String>());
    for row in c {
        let name = format!("{:?}", row.camera).to_lowercase();
        println!("  {:<8} {}", name, row.by_robots.iter().map(|v| format!("{:>5.1}%", 100.0 * v)).collect::<String>());
    }
}

/// The arguments of `spwi-sim stats`.
#[derive(clap::Args, Debug)]
pub struct StatsArgs {
    #[command(flatten)]
    pub world: WorldArgs,
    #[arg(long, default_value_t = 4)]
    pub robots: usize,
    #[arg(long, default_value_t = 20)]
    pub episodes: u32,
    /// Ticks per episode (10 per second).
    #[arg(long, default_value_t = 600)]
    pub ticks: u32,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Instead: coverage (ticks on which some robot sees the worker) for fleets of
    /// 1-8 robots under `fixed` and `track` cameras.
    #[arg(long)]
    pub coverage: bool,
}

/// `spwi-sim stats`: parses nothing more, runs the tool.
pub fn main(a: StatsArgs) -> Result<()> {
    let StatsArgs { world, robots, episodes, ticks, seed, json, coverage } = a;
    let floors = world.floors()?;
    if coverage {
        let c = crate::stats::coverage(&floors, world.scenario, usize::from(world.workers), episodes, ticks, seed);
        if json {
            println!("{}", serde_json::to_string_pretty(&c)?);
        } else {
            crate::stats::print_coverage(&c);
        }
        return Ok(());
    }
    check_robots(robots, &floors)?;
    let d = crate::stats::measure(&floors, world.scenario, usize::from(world.workers), robots, episodes, ticks, seed);
    if json {
        println!("{}", serde_json::to_string_pretty(&d)?);
    } else {
        println!("scenario {} — {} episodes × {} ticks, {} robots, seed {seed}", d.scenario, episodes, ticks, robots);
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
