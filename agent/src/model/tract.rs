//! The tract runtime: each model is optimised once into a runnable plan shared by all
//! robots, and every run starts from a fresh state of it. A state must not be reused:
//! tract's recurrent ops (the GRUs become a `Scan`) keep their hidden state in it and
//! start the next run from where the last one ended, so a window would be read after
//! the previous one instead of from zero, as the models were trained.

use super::{Input, LoadedModel, Runner};
use anyhow::{Context, Result};
use std::path::Path;
use std::sync::Arc;
use tract_onnx::prelude::*;

pub struct TractModel {
    plan: Arc<TypedRunnableModel>,
}

impl TractModel {
    pub fn load(path: &Path) -> Result<Self> {
        let plan = tract_onnx::onnx()
            .model_for_path(path)
            .and_then(|m| m.into_optimized())
            .and_then(|m| m.into_runnable())
            .with_context(|| format!("{}: tract cannot load and optimise this model", path.display()))?;
        Ok(TractModel { plan })
    }
}

impl LoadedModel for TractModel {
    fn runner(&self) -> Result<Box<dyn Runner>> {
        Ok(Box::new(TractRunner { plan: Arc::clone(&self.plan) }))
    }
}

struct TractRunner {
    plan: Arc<TypedRunnableModel>,
}

impl Runner for TractRunner {
    fn run(&mut self, inputs: &[Input<'_>]) -> Result<Vec<Vec<f32>>> {
        let inputs = inputs
            .iter()
            .map(|i| Tensor::from_shape(i.shape, i.data).map(TValue::from))
            .collect::<TractResult<TVec<_>>>()?;
        let outputs = self.plan.run(inputs)?; // a fresh state: see the module's doc
        outputs.iter().map(|o| Ok(o.to_plain_array_view::<f32>()?.iter().copied().collect())).collect()
    }
}
