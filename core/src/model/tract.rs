//! The tract runtime: each model is optimised once into a runnable plan shared by all
//! robots, and each runner keeps one state of it, reused run after run (it holds
//! tract's scratch buffers and the GRUs' packed weights, so nothing is set up per tick).
//!
//! tract turns an ONNX GRU into a recurrent op (`GruSeq`, or a `Scan` in general) that
//! by default keeps its hidden state in that state and starts the next run from where
//! the last one ended: a window would be read as the sequel of the previous one instead
//! of from zero, as the models were trained. Every recurrent op of the optimised model
//! is therefore told to restart from its initial state on every run (ONNX's contract);
//! `tests/golden.rs` runs every model twice and requires the same output.

use super::{Input, LoadedModel, Runner};
use anyhow::{Context, Result};
use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tract_onnx::prelude::*;
use tract_onnx::tract_core::ops::{gru_seq::GruSeq, scan::OptScan};

pub struct TractModel {
    plan: Arc<TypedRunnableModel>,
}

impl TractModel {
    pub fn load(path: &Path) -> Result<Self> {
        Ok(TractModel { plan: plan(path)? })
    }
}

fn plan(path: &Path) -> Result<Arc<TypedRunnableModel>> {
    tract_onnx::onnx()
        .model_for_path(path)
        .and_then(|m| m.into_optimized())
        .map(restart_recurrences_every_run)
        .and_then(|m| m.into_runnable())
        .with_context(|| format!("{}: tract cannot load and optimise this model", path.display()))
}

/// One node of a model's optimised tract plan and its mean time per run.
#[derive(Debug, Clone)]
pub struct NodeTime {
    pub node: String,
    pub op: String,
    pub mean: Duration,
}

/// Where a model's run time goes in tract: every node of its optimised plan with its
/// mean time over `runs` runs on `inputs` (after `runs / 10` unmeasured ones), slowest
/// first. For `benches/ops.rs`: the daemon never calls it.
pub fn profile_nodes(path: &Path, inputs: &[Input<'_>], runs: usize) -> Result<Vec<NodeTime>> {
    let plan = plan(path)?;
    let mut state = TypedSimpleState::new(&plan)?;
    let inputs = tensors(inputs)?;
    let mut total = vec![Duration::ZERO; plan.model().nodes.len()];
    let warm_up = runs / 10;
    for run in 0..warm_up + runs {
        state.run_plan_with_eval(inputs.clone(), |ctx, op_state, node, input| {
            let start = Instant::now();
            let out = tract_onnx::tract_core::plan::eval(ctx, op_state, node, input);
            if run >= warm_up {
                total[node.id] += start.elapsed();
            }
            out
        })?;
    }
    let mut nodes: Vec<NodeTime> = plan
        .model()
        .nodes
        .iter()
        .map(|n| NodeTime { node: n.name.clone(), op: n.op.name().into_owned(), mean: total[n.id] / runs as u32 })
        .collect();
    nodes.sort_by_key(|n| std::cmp::Reverse(n.mean));
    Ok(nodes)
}

fn tensors(inputs: &[Input<'_>]) -> TractResult<TVec<TValue>> {
    inputs.iter().map(|i| Tensor::from_shape(i.shape, i.data).map(TValue::from)).collect()
}

/// Makes every recurrent op of an optimised model start from its initial state on
/// every run instead of carrying the last run's final state into the next.
fn restart_recurrences_every_run(mut model: TypedModel) -> TypedModel {
    for node in &mut model.nodes {
        if let Some(gru) = node.op_as_mut::<GruSeq>() {
            gru.reset_every_turn = true;
        } else if let Some(scan) = node.op_as::<OptScan>() {
            let mut params = (**scan).clone();
            params.reset_every_turn = true;
            node.op = Box::new(OptScan::new(Arc::new(params)));
        }
    }
    model
}

impl LoadedModel for TractModel {
    fn runner(&self) -> Result<Box<dyn Runner>> {
        Ok(Box::new(TractRunner { state: TypedSimpleState::new(&self.plan)? }))
    }
}

struct TractRunner {
    state: TypedSimpleState,
}

impl Runner for TractRunner {
    fn run(&mut self, inputs: &[Input<'_>]) -> Result<Vec<Vec<f32>>> {
        let outputs = self.state.run(tensors(inputs)?)?;
        outputs.iter().map(|o| Ok(o.to_plain_array_view::<f32>()?.iter().copied().collect())).collect()
    }
}
