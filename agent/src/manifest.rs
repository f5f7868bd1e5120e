//! The model-set manifest (`models/<set>/manifest.json`) and its check against the
//! ONNX files.
//!
//! The manifest is the contract between training and serving: window W, horizon H,
//! node count, edge-weight kind, temperatures, and every input/output name and shape.
//! At start-up each ONNX file is opened and its declared inputs and outputs are
//! compared with the manifest; any difference refuses the set with an error naming the
//! file, the tensor and both shapes, rather than failing (or silently mispredicting)
//! at the first tick.

use crate::graph::{EdgeWeight, NODE_FEATURE_DIM};
use crate::temporal::{RowLayout, TemporalModel, CNN1D_DIM};
use serde::{Deserialize, Serialize};
use spwi_proto::{EMBEDDING_DIM, NUM_CLASSES};
use std::path::{Path, PathBuf};
use tract_onnx::prelude::*;

#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct TensorSpec {
    pub name: String,
    pub shape: Vec<usize>,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ModelSpec {
    pub file: String,
    pub inputs: Vec<TensorSpec>,
    pub outputs: Vec<TensorSpec>,
    /// Softmax temperature fitted on the validation split (GRUs only).
    #[serde(default)]
    pub temperature: Option<f32>,
}

impl ModelSpec {
    /// The GCN interface the daemon feeds for graphs of `max_nodes` nodes.
    pub fn gcn(max_nodes: usize) -> ModelSpec {
        let t = |name: &str, shape: &[usize]| TensorSpec { name: name.into(), shape: shape.to_vec() };
        ModelSpec {
            file: "gcn.onnx".into(),
            inputs: vec![t("x", &[1, max_nodes, NODE_FEATURE_DIM]), t("adj", &[1, max_nodes, max_nodes])],
            outputs: vec![t("embedding", &[1, EMBEDDING_DIM]), t("logits", &[1, NUM_CLASSES])],
            temperature: None,
        }
    }
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ConsensusDefaults {
    pub alpha: f32,
    pub beta: f32,
}

/// The models a set can hold.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum ModelKind {
    Gcn,
    EgoGru,
    CollectiveGru,
    /// The paper's 1D-CNN baseline (evaluation only).
    Cnn1d,
}

impl ModelKind {
    pub const ALL: [ModelKind; 4] = [ModelKind::Gcn, ModelKind::EgoGru, ModelKind::CollectiveGru, ModelKind::Cnn1d];

    /// Its key under `models` in the manifest (and in `reference.json`).
    pub fn name(self) -> &'static str {
        match self {
            ModelKind::Gcn => "gcn",
            ModelKind::EgoGru => "ego_gru",
            ModelKind::CollectiveGru => "collective_gru",
            ModelKind::Cnn1d => "cnn1d",
        }
    }

    /// The GRU that reads `temporal`'s rows.
    pub fn gru(temporal: TemporalModel) -> ModelKind {
        match temporal {
            TemporalModel::Ego => ModelKind::EgoGru,
            TemporalModel::Collective => ModelKind::CollectiveGru,
        }
    }
}

impl std::fmt::Display for ModelKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Models {
    pub gcn: ModelSpec,
    pub ego_gru: ModelSpec,
    pub collective_gru: ModelSpec,
    /// The paper's 1D-CNN baseline (human node feature ‖ keypoints per frame → logits),
    /// shipped for the evaluation only: the daemon never runs it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cnn1d: Option<ModelSpec>,
}

impl Models {
    /// A model's spec; `None` for a baseline the set does not ship.
    pub fn get(&self, kind: ModelKind) -> Option<&ModelSpec> {
        match kind {
            ModelKind::Gcn => Some(&self.gcn),
            ModelKind::EgoGru => Some(&self.ego_gru),
            ModelKind::CollectiveGru => Some(&self.collective_gru),
            ModelKind::Cnn1d => self.cnn1d.as_ref(),
        }
    }

    /// Every model the set holds.
    pub fn all(&self) -> impl Iterator<Item = (ModelKind, &ModelSpec)> {
        ModelKind::ALL.into_iter().filter_map(|k| self.get(k).map(|s| (k, s)))
    }
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Manifest {
    pub name: String,
    /// True for the random-weight fixture set: plumbing only, predictions meaningless.
    #[serde(default)]
    pub fixture: bool,
    pub classes: Vec<String>,
    pub max_nodes: usize,
    /// Ticks of history the temporal models look at.
    pub window: usize,
    /// Rows of that history fed to them, picked at uniform intervals (the paper's
    /// temporal-resolution study); absent means every tick of the window.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frames: Option<usize>,
    pub horizon: usize,
    pub edge_weight: EdgeWeight,
    /// What the temporal rows hold: the paper's parts only (absent), or also the
    /// worker's relations to the mapped stations.
    #[serde(default, skip_serializing_if = "is_paper")]
    pub row: RowLayout,
    pub consensus: ConsensusDefaults,
    pub models: Models,
    /// Everything else (dataset, evaluation figures, code version) is kept as is.
    #[serde(flatten)]
    pub extra: serde_json::Map<String, serde_json::Value>,
}

fn is_paper(r: &RowLayout) -> bool {
    *r == RowLayout::Paper
}

/// A model set that does not fit the daemon or its own ONNX files.
#[derive(Debug, thiserror::Error)]
pub enum ManifestError {
    #[error("cannot read model manifest {path}: {source}")]
    Read { path: PathBuf, source: std::io::Error },
    #[error("model manifest {path} is not valid: {source}")]
    Parse { path: PathBuf, source: serde_json::Error },
    #[error("model manifest {path}: {problem}")]
    Invalid { path: PathBuf, problem: String },
    #[error("{file}: cannot load ONNX model: {reason}")]
    Onnx { file: PathBuf, reason: String },
    #[error("{file}: {side} {index} is named {actual:?}, the manifest says {expected:?}")]
    Name { file: PathBuf, side: &'static str, index: usize, expected: String, actual: String },
    #[error("{file}: tensor {tensor:?} has shape {actual:?}, the manifest says {expected:?}")]
    Shape { file: PathBuf, tensor: String, expected: Vec<usize>, actual: String },
    #[error("{file}: has {actual} {side}s, the manifest lists {expected}")]
    Count { file: PathBuf, side: &'static str, expected: usize, actual: usize },
}

impl Manifest {
    /// Reads `<dir>/manifest.json`, checks it against what the daemon feeds the models,
    /// and checks every ONNX file against it.
    pub fn load(dir: &Path) -> Result<Manifest, ManifestError> {
        let path = dir.join("manifest.json");
        let text =
            std::fs::read_to_string(&path).map_err(|source| ManifestError::Read { path: path.clone(), source })?;
        let m: Manifest =
            serde_json::from_str(&text).map_err(|source| ManifestError::Parse { path: path.clone(), source })?;
        m.check_interface(&path)?;
        for (_, spec) in m.models.all() {
            check_onnx(&dir.join(&spec.file), spec)?;
        }
        Ok(m)
    }

    /// Rows fed to the temporal models per window.
    pub fn frames(&self) -> usize {
        self.frames.unwrap_or(self.window)
    }

    /// The shapes the daemon will feed and read, derived from W, H and the node count.
    fn check_interface(&self, path: &Path) -> Result<(), ManifestError> {
        let bad = |problem: String| Err(ManifestError::Invalid { path: path.to_owned(), problem });
        if self.classes.len() != NUM_CLASSES {
            return bad(format!("{} classes, the daemon predicts {NUM_CLASSES}", self.classes.len()));
        }
        if !(1..=256).contains(&self.max_nodes)
            || !(1..=600).contains(&self.window)
            || self.horizon >= spwi_proto::MAX_STEPS
        {
            return bad(format!(
                "max_nodes {} (1..=256), window {} (1..=600) or horizon {} (0..{}) out of range",
                self.max_nodes,
                self.window,
                self.horizon,
                spwi_proto::MAX_STEPS
            ));
        }
        if !(1..=self.window).contains(&self.frames()) {
            return bad(format!("frames {} must be within 1..=window ({})", self.frames(), self.window));
        }
        let (n, w, steps) = (self.max_nodes, self.frames(), self.horizon + 1);
        let expect = |spec: &ModelSpec, what: ModelKind, inputs: &[&[usize]], outputs: &[&[usize]]| {
            let ins: Vec<&[usize]> = spec.inputs.iter().map(|t| t.shape.as_slice()).collect();
            let outs: Vec<&[usize]> = spec.outputs.iter().map(|t| t.shape.as_slice()).collect();
            if ins != inputs || outs != outputs {
                return bad(format!(
                    "{what} ({}) declares inputs {ins:?} and outputs {outs:?}; with max_nodes {n}, window {} ({w} frames), horizon {} and {:?} rows the daemon feeds {inputs:?} and reads {outputs:?}",
                    spec.file, self.window, self.horizon, self.row
                ));
            }
            Ok(())
        };
        expect(
            &self.models.gcn,
            ModelKind::Gcn,
            &[&[1, n, NODE_FEATURE_DIM], &[1, n, n]],
            &[&[1, EMBEDDING_DIM], &[1, NUM_CLASSES]],
        )?;
        for temporal in [TemporalModel::Ego, TemporalModel::Collective] {
            let kind = ModelKind::gru(temporal);
            let spec = self.models.get(kind).expect("every set has both GRUs");
            expect(spec, kind, &[&[1, w, temporal.row_dim(self.row)]], &[&[1, steps, NUM_CLASSES]])?;
            match spec.temperature {
                Some(t) if t.is_finite() && t > 0.0 => {}
                other => return bad(format!("{kind}.temperature is {other:?}; it must be a positive number")),
            }
        }
        if let Some(cnn) = &self.models.cnn1d {
            expect(cnn, ModelKind::Cnn1d, &[&[1, w, CNN1D_DIM]], &[&[1, steps, NUM_CLASSES]])?;
        }
        Ok(())
    }
}

/// Compares an ONNX file's inputs (as declared) and outputs (as tract infers them
/// from the declared inputs) with the manifest.
pub fn check_onnx(file: &Path, spec: &ModelSpec) -> Result<(), ManifestError> {
    let onnx_err = |e: TractError| ManifestError::Onnx { file: file.to_owned(), reason: format!("{e:#}") };
    let model = tract_onnx::onnx().model_for_path(file).map_err(onnx_err)?;
    let inputs: Vec<(String, Option<TVec<usize>>, String)> = model
        .input_outlets()
        .map_err(onnx_err)?
        .iter()
        .map(|&o| {
            let fact = model.outlet_fact(o).map_err(onnx_err)?;
            let name = model.node(o.node).name.clone();
            Ok((name, fact.shape.as_concrete_finite().ok().flatten(), format!("{:?}", fact.shape)))
        })
        .collect::<Result<_, ManifestError>>()?;
    compare(file, "input", &inputs, &spec.inputs)?;
    let typed = model.into_typed().map_err(onnx_err)?;
    let outputs: Vec<(String, Option<TVec<usize>>, String)> = typed
        .output_outlets()
        .map_err(onnx_err)?
        .iter()
        .map(|&o| {
            let fact = typed.outlet_fact(o).map_err(onnx_err)?;
            let name = typed.outlet_label(o).unwrap_or(&typed.node(o.node).name).to_owned();
            Ok((name, fact.shape.as_concrete().map(|s| s.iter().copied().collect()), format!("{:?}", fact.shape)))
        })
        .collect::<Result<_, ManifestError>>()?;
    compare(file, "output", &outputs, &spec.outputs)
}

fn compare(
    file: &Path,
    side: &'static str,
    actual: &[(String, Option<TVec<usize>>, String)],
    specs: &[TensorSpec],
) -> Result<(), ManifestError> {
    if actual.len() != specs.len() {
        return Err(ManifestError::Count { file: file.to_owned(), side, expected: specs.len(), actual: actual.len() });
    }
    for (index, ((name, shape, shown), want)) in actual.iter().zip(specs).enumerate() {
        if *name != want.name {
            return Err(ManifestError::Name {
                file: file.to_owned(),
                side,
                index,
                expected: want.name.clone(),
                actual: name.clone(),
            });
        }
        if shape.as_deref() != Some(want.shape.as_slice()) {
            return Err(ManifestError::Shape {
                file: file.to_owned(),
                tensor: want.name.clone(),
                expected: want.shape.clone(),
                actual: match shape {
                    Some(s) => format!("{:?}", s.as_slice()),
                    None => format!("{shown} (not fixed)"),
                },
            });
        }
    }
    Ok(())
}
