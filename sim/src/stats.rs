//! `spwi-sim stats`: figures that show the task is not trivial — how often each robot
//! sees the worker, how many detections a frame holds, how the worker's time splits
//! between moving, transitions and working, how often it changes its mind, and how
//! often it is near the two close stations.

use crate::geometry::dist;
use crate::layout::Layout;
use crate::world::{Scenario, World};
use serde::Serialize;
use spwi_proto::{RobotId, WorkerPhase};

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
    /// Share of ticks the worker is within 3 m of both the assembly and manufacturing spots.
    pub near_close_stations: f64,
}

pub fn measure(layout: &Layout, scenario: Scenario, robots: usize, episodes: u32, ticks: u32, seed: u64) -> Difficulty {
    let ids: Vec<RobotId> = (0..robots).map(|i| RobotId::new(format!("r{i}")).expect("valid id")).collect();
    let mut seen = vec![0u64; robots];
    let (mut nobody, mut detections, mut frames) = (0u64, 0u64, 0u64);
    let (mut moving, mut transition, mut stationary, mut near) = (0u64, 0u64, 0u64, 0u64);
    let (mut changes, mut trips) = (0u64, 0u64);
    let (s2, s3) = (layout.station(2).work_spot, layout.station(3).work_spot);
    for e in 0..episodes {
        let mut w = World::new(layout.clone(), scenario, seed.wrapping_add(e as u64), robots);
        for _ in 0..ticks {
            w.step();
            let mut any = false;
            for (slot, id) in ids.iter().enumerate() {
                let f = w.observe(slot, id);
                if f.human.is_some() {
                    seen[slot] += 1;
                    any = true;
                }
                detections += f.visibility() as u64;
                frames += 1;
            }
            nobody += u64::from(!any);
            match w.worker.phase {
                WorkerPhase::Moving => moving += 1,
                WorkerPhase::Transition => transition += 1,
                WorkerPhase::Stationary => stationary += 1,
            }
            let p = w.worker.position;
            near += u64::from(dist(p, s2) < 3.0 && dist(p, s3) < 3.0);
        }
        changes += w.worker.goal_changes as u64;
        trips += w.worker.arrivals as u64 + 1;
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
