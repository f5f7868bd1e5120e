//! The model-set manifest (`models/<set>/manifest.json`) and its check against the
//! ONNX files.
//!
//! The manifest is the contract between training and serving: window W, horizon H,
//! node count, edge-weight kind, temperatures, and every input/output name and shape.
//! At start-up each ONNX file is opened and its declared inputs and outputs are
//! compared with the manifest; any difference refuses the set with an error naming the
//! file, the tensor and both shapes, rather than failing (or silently mispredicting)
//! at the first tick.

use crate::floor::RELATION_DIM;
use crate::graph::{EdgeWeight, NodeFeatures};
use crate::temporal::{RowLayout, TemporalModel, CNN1D_DIM};
use serde::{Deserialize, Serialize};
use spwi_proto::{EMBEDDING_DIM, NUM_CLASSES};
use std::path::{Path, PathBuf};
use tract_onnx::prelude::*;
use tract_onnx::tract_hir::infer::Factoid;

#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct TensorSpec {
    pub name: String,
    pub shape: Vec<Dim>,
}

impl TensorSpec {
    /// The shape, when every dimension is a size.
    pub fn fixed_shape(&self) -> Option<Vec<usize>> {
        self.shape.iter().map(|d| if let Dim::Fixed(n) = d { Some(*n) } else { None }).collect()
    }
}

/// One dimension of a tensor: a size, or a name where the file leaves the size to
/// each run (only the GCN's node count may be left so: see [`GcnNodes`]).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Dim {
    Fixed(usize),
    Named(String),
}

impl Dim {
    /// Fixed dimensions, from sizes.
    pub fn fixed(sizes: &[usize]) -> Vec<Dim> {
        sizes.iter().map(|&n| Dim::Fixed(n)).collect()
    }
}

/// A shape as people write it: `[1, nodes, 1024]`.
fn shown(shape: &[Dim]) -> String {
    let dims: Vec<String> = shape
        .iter()
        .map(|d| match d {
            Dim::Fixed(n) => n.to_string(),
            Dim::Named(s) => s.clone(),
        })
        .collect();
    format!("[{}]", dims.join(", "))
}

/// How the GCN is fed a graph.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GcnNodes {
    /// Every graph padded to this many nodes (the file fixes its node count).
    Padded(usize),
    /// Only the graph's real nodes (the file names its node count): the products of
    /// both layers shrink with the graph, and the worker node's output is the same,
    /// since padding nodes have no edge to it.
    Real,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ModelSpec {
    pub file: String,
    /// The file's SHA-256 (hex): a file changed on disk, even one that still parses
    /// and fits the interface, is refused at start. Absent only where no manifest
    /// names the file (a lone GCN given on the command line).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sha256: Option<String>,
    pub inputs: Vec<TensorSpec>,
    pub outputs: Vec<TensorSpec>,
    /// Softmax temperature fitted on the validation split (GRUs only).
    #[serde(default)]
    pub temperature: Option<f32>,
}

impl ModelSpec {
    /// The GCN interface the daemon feeds for graphs of `nodes` nodes (a size, or the
    /// name of a node count left to each run) whose nodes carry `features`.
    pub fn gcn(nodes: Dim, features: NodeFeatures) -> ModelSpec {
        let t = |name: &str, shape: Vec<Dim>| TensorSpec { name: name.into(), shape };
        let (f, n) = (Dim::Fixed(features.dim()), nodes);
        ModelSpec {
            file: "gcn.onnx".into(),
            sha256: None,
            inputs: vec![t("x", vec![Dim::Fixed(1), n.clone(), f]), t("adj", vec![Dim::Fixed(1), n.clone(), n])],
            outputs: vec![t("embedding", Dim::fixed(&[1, EMBEDDING_DIM])), t("logits", Dim::fixed(&[1, NUM_CLASSES]))],
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
    /// What the GCN's graph is made of: image distances and appearance (absent, the
    /// paper's), or floor distances and each node's floor relations
    /// (`floor_relations`; `graph.rs`).
    #[serde(default, skip_serializing_if = "is_appearance")]
    pub node_features: NodeFeatures,
    /// What the temporal rows hold: the paper's parts only (absent), or the worker's
    /// relations to the mapped stations (`relations`), also where it faces
    /// (`relations_facing`).
    #[serde(default, skip_serializing_if = "is_paper")]
    pub row: RowLayout,
    /// Relation rows (with or without facing) only: the collective GRU fuses its peers
    /// with a set model and takes a second input, `peers` `[1, frames, peer_slots,
    /// RELATION_DIM]`, one relation block per peer heard (`floor::peer_set`). Absent:
    /// rows only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub peer_slots: Option<usize>,
    pub consensus: ConsensusDefaults,
    pub models: Models,
    /// Everything else (dataset, evaluation figures, code version) is kept as is.
    #[serde(flatten)]
    pub extra: serde_json::Map<String, serde_json::Value>,
}

fn is_appearance(f: &NodeFeatures) -> bool {
    *f == NodeFeatures::Appearance
}

fn is_paper(r: &RowLayout) -> bool {
    *r == RowLayout::Paper
}

/// A model set that does not fit the daemon or its own ONNX files.
#[derive(Debug, thiserror::Error)]
pub enum ManifestError {
    // The cause is in the message, so it is not also the error's `source`: a chain
    // printed with `{:#}` would name it twice.
    #[error("cannot read model manifest {path}: {cause}")]
    Read { path: PathBuf, cause: std::io::Error },
    #[error("model manifest {path} is not valid: {cause}")]
    Parse { path: PathBuf, cause: serde_json::Error },
    #[error("model manifest {path}: {problem}")]
    Invalid { path: PathBuf, problem: String },
    #[error("{file}: cannot load ONNX model: {reason}")]
    Onnx { file: PathBuf, reason: String },
    #[error("{file}: {side} {index} is named {actual:?}, the manifest says {expected:?}")]
    Name { file: PathBuf, side: &'static str, index: usize, expected: String, actual: String },
    #[error("{file}: tensor {tensor:?} has shape {actual}, the manifest says {expected}")]
    Shape { file: PathBuf, tensor: String, expected: String, actual: String },
    #[error("{file}: has {actual} {side}s, the manifest lists {expected}")]
    Count { file: PathBuf, side: &'static str, expected: usize, actual: usize },
    #[error("{file}: its SHA-256 is {actual}, the manifest names {expected}: the file was changed after the set was made; refusing it")]
    Digest { file: PathBuf, expected: String, actual: String },
    #[error("{file}: the manifest names no sha256 for it (every model file's digest is checked at start; models/train/export.py writes it)")]
    NoDigest { file: PathBuf },
}

/// The SHA-256 of `file`, in lower-case hex.
pub fn sha256_hex(file: &Path) -> std::io::Result<String> {
    let bytes = std::fs::read(file)?;
    let d = ring::digest::digest(&ring::digest::SHA256, &bytes);
    Ok(d.as_ref().iter().map(|b| format!("{b:02x}")).collect())
}

/// Refuses `file` unless its SHA-256 is the one `spec` names.
fn check_digest(file: &Path, spec: &ModelSpec) -> Result<(), ManifestError> {
    let expected = spec.sha256.clone().ok_or_else(|| ManifestError::NoDigest { file: file.to_owned() })?;
    let actual = sha256_hex(file).map_err(|e| ManifestError::Onnx { file: file.to_owned(), reason: e.to_string() })?;
    if !actual.eq_ignore_ascii_case(&expected) {
        return Err(ManifestError::Digest { file: file.to_owned(), expected, actual });
    }
    Ok(())
}

impl Manifest {
    /// Reads `<dir>/manifest.json`, checks it against what the daemon feeds the models,
    /// and checks every ONNX file against it.
    pub fn load(dir: &Path) -> Result<Manifest, ManifestError> {
        let path = dir.join("manifest.json");
        let text = std::fs::read_to_string(&path).map_err(|cause| ManifestError::Read { path: path.clone(), cause })?;
        let m: Manifest =
            serde_json::from_str(&text).map_err(|cause| ManifestError::Parse { path: path.clone(), cause })?;
        m.check_interface(&path)?;
        for (_, spec) in m.models.all() {
            check_onnx(&dir.join(&spec.file), spec)?;
            check_digest(&dir.join(&spec.file), spec)?;
        }
        Ok(m)
    }

    /// How the GCN is fed: padded to `max_nodes`, or only the real nodes when its file
    /// names the node count (checked consistent with the file at load).
    pub fn gcn_nodes(&self) -> GcnNodes {
        match self.gcn_node_dim() {
            Dim::Named(_) => GcnNodes::Real,
            Dim::Fixed(n) => GcnNodes::Padded(n),
        }
    }

    /// The GCN's node dimension: the name its first input gives it, else max_nodes.
    fn gcn_node_dim(&self) -> Dim {
        match self.models.gcn.inputs.first().and_then(|x| x.shape.get(1)) {
            Some(Dim::Named(name)) => Dim::Named(name.clone()),
            _ => Dim::Fixed(self.max_nodes),
        }
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
        match (self.peer_slots, self.row) {
            (None, _) => {}
            (Some(s), row) if row.reads_relations() && (1..=64).contains(&s) => {}
            (Some(s), row) if row.reads_relations() => return bad(format!("peer_slots {s} out of range (1..=64)")),
            (Some(_), row) => {
                return bad(format!("peer_slots needs relation rows (\"row\": \"relations\"), not {row:?}"))
            }
        }
        let (n, w, steps) = (self.max_nodes, self.frames(), self.horizon + 1);
        let expect = |spec: &ModelSpec, what: ModelKind, want: &ModelSpec| {
            let shapes = |ts: &[TensorSpec]| {
                ts.iter().map(|t| format!("{} {}", t.name, shown(&t.shape))).collect::<Vec<_>>().join(", ")
            };
            let same = |a: &[TensorSpec], b: &[TensorSpec]| a.iter().map(|t| &t.shape).eq(b.iter().map(|t| &t.shape));
            if !same(&spec.inputs, &want.inputs) || !same(&spec.outputs, &want.outputs) {
                return bad(format!(
                    "{what} ({}) declares inputs {} and outputs {}; with max_nodes {n}, {:?} node features, window {} ({w} frames), horizon {} and {:?} rows the daemon feeds {} and reads {}",
                    spec.file,
                    shapes(&spec.inputs),
                    shapes(&spec.outputs),
                    self.node_features,
                    self.window,
                    self.horizon,
                    self.row,
                    shapes(&want.inputs),
                    shapes(&want.outputs),
                ));
            }
            Ok(())
        };
        let inputs = |tensors: &[(&str, Vec<usize>)], steps: usize| ModelSpec {
            file: String::new(),
            sha256: None,
            inputs: tensors
                .iter()
                .map(|(name, shape)| TensorSpec { name: (*name).into(), shape: Dim::fixed(shape) })
                .collect(),
            outputs: vec![TensorSpec { name: "logits".into(), shape: Dim::fixed(&[1, steps, NUM_CLASSES]) }],
            temperature: None,
        };
        expect(&self.models.gcn, ModelKind::Gcn, &ModelSpec::gcn(self.gcn_node_dim(), self.node_features))?;
        for temporal in [TemporalModel::Ego, TemporalModel::Collective] {
            let kind = ModelKind::gru(temporal);
            let spec = self.models.get(kind).expect("every set has both GRUs");
            let mut fed = vec![("window", vec![1, w, temporal.row_dim(self.row)])];
            if let (TemporalModel::Collective, Some(slots)) = (temporal, self.peer_slots) {
                fed.push(("peers", vec![1, w, slots, RELATION_DIM]));
            }
            expect(spec, kind, &inputs(&fed, steps))?;
            match spec.temperature {
                Some(t) if t.is_finite() && t > 0.0 => {}
                other => return bad(format!("{kind}.temperature is {other:?}; it must be a positive number")),
            }
        }
        if let Some(cnn) = &self.models.cnn1d {
            expect(cnn, ModelKind::Cnn1d, &inputs(&[("window", vec![1, w, CNN1D_DIM])], steps))?;
        }
        Ok(())
    }
}

/// Compares an ONNX file's inputs (as declared) and outputs (as tract infers them
/// from the declared inputs) with the manifest.
pub fn check_onnx(file: &Path, spec: &ModelSpec) -> Result<(), ManifestError> {
    let onnx_err = |e: TractError| ManifestError::Onnx { file: file.to_owned(), reason: format!("{e:#}") };
    let model = tract_onnx::onnx().model_for_path(file).map_err(onnx_err)?;
    let inputs: Vec<(String, Option<Vec<Dim>>, String)> = model
        .input_outlets()
        .map_err(onnx_err)?
        .iter()
        .map(|&o| {
            let fact = model.outlet_fact(o).map_err(onnx_err)?;
            let name = model.node(o.node).name.clone();
            let dims = (!fact.shape.is_open())
                .then(|| {
                    fact.shape.dims().map(|d| d.concretize().and_then(|d| declared(&d))).collect::<Option<Vec<_>>>()
                })
                .flatten();
            Ok((name, dims, format!("{:?}", fact.shape)))
        })
        .collect::<Result<_, ManifestError>>()?;
    compare(file, "input", &inputs, &spec.inputs)?;
    let typed = model.into_typed().map_err(onnx_err)?;
    let outputs: Vec<(String, Option<Vec<Dim>>, String)> = typed
        .output_outlets()
        .map_err(onnx_err)?
        .iter()
        .map(|&o| {
            let fact = typed.outlet_fact(o).map_err(onnx_err)?;
            let name = typed.outlet_label(o).unwrap_or(&typed.node(o.node).name).to_owned();
            Ok((name, fact.shape.as_concrete().map(Dim::fixed), format!("{:?}", fact.shape)))
        })
        .collect::<Result<_, ManifestError>>()?;
    compare(file, "output", &outputs, &spec.outputs)
}

/// The name a GCN file gives its node count (dimension 1 of its first input), or
/// `None` when it fixes it.
pub fn declared_node_dim(file: &Path) -> Result<Option<String>, ManifestError> {
    let onnx_err = |e: TractError| ManifestError::Onnx { file: file.to_owned(), reason: format!("{e:#}") };
    let model = tract_onnx::onnx().model_for_path(file).map_err(onnx_err)?;
    let input = model.input_outlets().map_err(onnx_err)?.first().copied();
    let dim = match input {
        Some(o) => model.outlet_fact(o).map_err(onnx_err)?.shape.dim(1).and_then(|d| d.concretize()),
        None => None,
    };
    Ok(match dim.as_ref().and_then(declared) {
        Some(Dim::Named(name)) => Some(name),
        _ => None,
    })
}

/// A dimension as an ONNX file declares it: a size or a plain name, nothing computed.
fn declared(d: &TDim) -> Option<Dim> {
    match d {
        TDim::Val(n) => usize::try_from(*n).ok().map(Dim::Fixed),
        TDim::Sym(s) => Some(Dim::Named(s.to_string())),
        _ => None,
    }
}

fn compare(
    file: &Path,
    side: &'static str,
    actual: &[(String, Option<Vec<Dim>>, String)],
    specs: &[TensorSpec],
) -> Result<(), ManifestError> {
    if actual.len() != specs.len() {
        return Err(ManifestError::Count { file: file.to_owned(), side, expected: specs.len(), actual: actual.len() });
    }
    for (index, ((name, shape, as_tract_sees_it), want)) in actual.iter().zip(specs).enumerate() {
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
                expected: shown(&want.shape),
                actual: match shape {
                    Some(s) => shown(s),
                    None => format!("{as_tract_sees_it} (not fixed)"),
                },
            });
        }
    }
    Ok(())
}
