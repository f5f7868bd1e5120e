//! Where each model's run time goes in tract: every node of its optimised plan with its
//! mean time per run, batch 1, single-threaded; the GCN on a star graph of the worker
//! and three objects (what the simulated floors show), the GRUs on one window.
//!
//! Run: `cargo bench -p spwi-core --bench ops` (`SPWI_BENCH_MODELS=DIR` picks a model
//! set, default models/default; `SPWI_BENCH_OPS_TOP=N` rows per model, default 12).

use spwi_core::manifest::{Dim, Manifest};
use spwi_core::model::{profile_nodes, Input};
use std::path::PathBuf;
use std::time::Duration;

/// Nodes of the GCN's star graph: the worker and three objects.
const GCN_NODES: usize = 4;
const RUNS: usize = 2_000;

fn main() -> anyhow::Result<()> {
    let dir = std::env::var_os("SPWI_BENCH_MODELS")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../models/default"));
    let top: usize = std::env::var("SPWI_BENCH_OPS_TOP").ok().and_then(|v| v.parse().ok()).unwrap_or(12);
    let manifest = Manifest::load(&dir)?;
    for (kind, spec) in manifest.models.all() {
        let shapes: Vec<Vec<usize>> = spec
            .inputs
            .iter()
            .map(|i| i.shape.iter().map(|d| if let Dim::Fixed(n) = *d { n } else { GCN_NODES }).collect())
            .collect();
        let data: Vec<Vec<f32>> = shapes.iter().map(|s| vec![0.1; s.iter().product()]).collect();
        let inputs: Vec<Input> = shapes.iter().zip(&data).map(|(shape, data)| Input { shape, data }).collect();
        let nodes = profile_nodes(&dir.join(&spec.file), &inputs, RUNS)?;
        let us = |d: Duration| d.as_secs_f64() * 1e6;
        let total: Duration = nodes.iter().map(|n| n.mean).sum();
        println!(
            "\n== {} ({}): {} nodes, {:.1} µs per run in its nodes",
            kind.name(),
            spec.file,
            nodes.len(),
            us(total)
        );
        for n in nodes.iter().take(top) {
            println!("{:>9.2} µs  {:<24} {}", us(n.mean), n.op, n.node);
        }
        let rest = &nodes[top.min(nodes.len())..];
        let rest_total: Duration = rest.iter().map(|n| n.mean).sum();
        println!("{:>9.2} µs  the other {} nodes", us(rest_total), rest.len());
    }
    Ok(())
}
