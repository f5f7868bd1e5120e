//! ONNX models: loaded, checked and optimised once per process, shared read-only
//! ([`ModelSet`] behind an `Arc`), and run through a per-robot [`Inference`] that
//! owns the mutable run state. Two runtimes sit behind one small trait:
//!
//! - `tract` (pure Rust, always built, the default);
//! - `ort`: ONNX Runtime, loaded at run time from the `onnxruntime` wheel's shared
//!   library (cargo feature `ort`), so nothing is downloaded at build time.

pub mod locate;
#[cfg(feature = "ort")]
mod ort;
mod tract;

pub use tract::{profile_nodes, NodeTime};

use crate::floor::RELATION_DIM;
use crate::graph::{NodeFeatures, StarGraph};
use crate::manifest::{Dim, GcnNodes, Manifest, ModelKind, ModelSpec};
use crate::temporal::TemporalModel;
use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use spwi_proto::{EMBEDDING_DIM, NUM_CLASSES};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Which ONNX runtime runs the models.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Backend {
    #[default]
    Tract,
    Ort,
}

impl std::str::FromStr for Backend {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "tract" => Ok(Backend::Tract),
            "ort" => Ok(Backend::Ort),
            _ => Err(format!("unknown backend {s:?}; use \"tract\" or \"ort\"")),
        }
    }
}

/// One input tensor: shape and row-major data.
pub struct Input<'a> {
    pub shape: &'a [usize],
    pub data: &'a [f32],
}

/// A model loaded once and shared by every robot of the process.
trait LoadedModel: Send + Sync {
    /// A fresh run state for one robot.
    fn runner(&self) -> Result<Box<dyn Runner>>;
}

/// Runs one model; holds whatever mutable state the runtime needs.
pub trait Runner: Send {
    /// Runs the model, returning each output flattened, in manifest order.
    fn run(&mut self, inputs: &[Input<'_>]) -> Result<Vec<Vec<f32>>>;
}

/// The models of a model set, checked against its manifest.
pub struct ModelSet {
    pub manifest: Manifest,
    pub dir: PathBuf,
    pub backend: Backend,
    gcn: Box<dyn LoadedModel>,
    ego_gru: Box<dyn LoadedModel>,
    collective_gru: Box<dyn LoadedModel>,
    cnn1d: Option<Box<dyn LoadedModel>>,
}

fn load_file(path: &Path, backend: Backend, ort_library: Option<&Path>) -> Result<Box<dyn LoadedModel>> {
    match backend {
        Backend::Tract => Ok(Box::new(tract::TractModel::load(path)?)),
        #[cfg(feature = "ort")]
        Backend::Ort => Ok(Box::new(ort::OrtModel::load(path, ort_library)?)),
        #[cfg(not(feature = "ort"))]
        Backend::Ort => {
            let _ = ort_library;
            bail!("backend \"ort\" was asked for, but this build has no ONNX Runtime support (rebuild with `--features ort`)")
        }
    }
}

impl std::fmt::Debug for ModelSet {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ModelSet").field("dir", &self.dir).field("backend", &self.backend).finish_non_exhaustive()
    }
}

impl ModelSet {
    /// Loads and checks the model set in `dir` with `backend`. `ort_library` is the
    /// path of `libonnxruntime.so` (ort backend only).
    pub fn load(dir: &Path, backend: Backend, ort_library: Option<&Path>) -> Result<Arc<ModelSet>> {
        let manifest = Manifest::load(dir)?;
        let load = |spec: &ModelSpec| load_file(&dir.join(&spec.file), backend, ort_library);
        let set = ModelSet {
            gcn: load(&manifest.models.gcn)?,
            ego_gru: load(&manifest.models.ego_gru)?,
            collective_gru: load(&manifest.models.collective_gru)?,
            cnn1d: manifest.models.cnn1d.as_ref().map(load).transpose()?,
            manifest,
            dir: dir.to_owned(),
            backend,
        };
        Ok(Arc::new(set))
    }

    /// Run state for one robot using `temporal` as its GRU.
    pub fn inference(self: &Arc<Self>, temporal: TemporalModel) -> Result<Inference> {
        let gru = self.runner(ModelKind::gru(temporal))?;
        let gcn = Gcn::new(self.gcn.runner()?, self.manifest.gcn_nodes(), self.manifest.node_features);
        Ok(Inference { set: Arc::clone(self), gcn, gru, temporal })
    }

    /// The GRU's softmax temperature T for `temporal`.
    pub fn temperature(&self, temporal: TemporalModel) -> f32 {
        let spec = self.manifest.models.get(ModelKind::gru(temporal)).expect("every set has both GRUs");
        spec.temperature.unwrap_or(1.0) // validated present by Manifest::load
    }

    /// One model's own runner (the golden tests, the benchmarks, the evaluation's baselines).
    pub fn runner(&self, kind: ModelKind) -> Result<Box<dyn Runner>> {
        match kind {
            ModelKind::Gcn => self.gcn.runner(),
            ModelKind::EgoGru => self.ego_gru.runner(),
            ModelKind::CollectiveGru => self.collective_gru.runner(),
            ModelKind::Cnn1d => match &self.cnn1d {
                Some(m) => m.runner(),
                None => bail!("model set {:?} ships no cnn1d baseline", self.manifest.name),
            },
        }
    }
}

/// The GCN's output for the worker node.
#[derive(Debug, Clone, PartialEq)]
pub struct GcnOutput {
    pub embedding: Vec<f32>,
    pub logits: [f32; NUM_CLASSES],
}

/// The GCN with how it is fed; on its own, it is what the dataset export needs before
/// any GRU is trained.
pub struct Gcn {
    runner: Box<dyn Runner>,
    nodes: GcnNodes,
    features: NodeFeatures,
    /// The real nodes' block of the adjacency ([`GcnNodes::Real`]).
    adj: Vec<f32>,
}

impl Gcn {
    fn new(runner: Box<dyn Runner>, nodes: GcnNodes, features: NodeFeatures) -> Gcn {
        Gcn { runner, nodes, features, adj: Vec::new() }
    }

    /// Loads a lone GCN file, checked against the interface the daemon feeds for
    /// graphs of at most `max_nodes` nodes carrying `features`: padded to that many
    /// when the file fixes its node count, only the real ones when it names it.
    pub fn load(
        file: &Path,
        max_nodes: usize,
        features: NodeFeatures,
        backend: Backend,
        ort_library: Option<&Path>,
    ) -> Result<Gcn> {
        let (spec, nodes) = match crate::manifest::declared_node_dim(file)? {
            Some(name) => (ModelSpec::gcn(Dim::Named(name), features), GcnNodes::Real),
            None => (ModelSpec::gcn(Dim::Fixed(max_nodes), features), GcnNodes::Padded(max_nodes)),
        };
        crate::manifest::check_onnx(file, &spec)?;
        Ok(Gcn::new(load_file(file, backend, ort_library)?.runner()?, nodes, features))
    }

    /// The worker node's embedding and the spatial-only logits.
    pub fn run(&mut self, g: &StarGraph) -> Result<GcnOutput> {
        let f = self.features.dim();
        if g.dim != f {
            bail!("the GCN takes nodes of {f} features ({:?}), this graph's have {}", self.features, g.dim);
        }
        let out = match self.nodes {
            GcnNodes::Padded(n) => {
                if n != g.max_nodes {
                    bail!("the GCN takes graphs of {n} nodes, this one has room for {}", g.max_nodes);
                }
                self.runner
                    .run(&[Input { shape: &[1, n, f], data: &g.x }, Input { shape: &[1, n, n], data: &g.adj }])?
            }
            GcnNodes::Real => {
                let (n, stride) = (g.nodes, g.max_nodes);
                self.adj.clear();
                self.adj.extend((0..n).flat_map(|i| &g.adj[i * stride..i * stride + n]));
                self.runner.run(&[
                    Input { shape: &[1, n, f], data: &g.x[..n * f] },
                    Input { shape: &[1, n, n], data: &self.adj },
                ])?
            }
        };
        let [embedding, logits] =
            <[Vec<f32>; 2]>::try_from(out).map_err(|o| anyhow::anyhow!("gcn gave {} outputs", o.len()))?;
        if embedding.len() != EMBEDDING_DIM || logits.len() != NUM_CLASSES {
            bail!("gcn gave an embedding of {} and {} logits", embedding.len(), logits.len());
        }
        if embedding.iter().chain(&logits).any(|v| !v.is_finite()) {
            bail!("gcn produced a non-finite value");
        }
        Ok(GcnOutput { embedding, logits: logits.try_into().expect("length checked") })
    }
}

/// One robot's model runners.
pub struct Inference {
    set: Arc<ModelSet>,
    gcn: Gcn,
    gru: Box<dyn Runner>,
    pub temporal: TemporalModel,
}

impl Inference {
    pub fn set(&self) -> &Arc<ModelSet> {
        &self.set
    }

    pub fn gcn(&mut self, g: &StarGraph) -> Result<GcnOutput> {
        self.gcn.run(g)
    }

    /// Peer blocks per row this robot's GRU reads (0: no peer input).
    pub fn peer_slots(&self) -> usize {
        match self.temporal {
            TemporalModel::Collective => self.set.manifest.peer_slots.unwrap_or(0),
            TemporalModel::Ego => 0,
        }
    }

    /// Logits for t and each forecast step, from a `[frames, row_dim]` window and, for
    /// a model with a peer set, its `[frames, slots, RELATION_DIM]` peer input (else
    /// empty: `temporal::Window::peer_input` gives the right one).
    pub fn gru(&mut self, window: &[f32], peers: &[f32]) -> Result<Vec<[f32; NUM_CLASSES]>> {
        let m = &self.set.manifest;
        let (frames, slots) = (m.frames(), self.peer_slots());
        let fed = [
            Input { shape: &[1, frames, self.temporal.row_dim(m.row)], data: window },
            Input { shape: &[1, frames, slots, RELATION_DIM], data: peers },
        ];
        let out = self.gru.run(&fed[..if slots > 0 { 2 } else { 1 }])?;
        let logits = out.into_iter().next().context("gru gave no output")?;
        if logits.len() != (m.horizon + 1) * NUM_CLASSES || logits.iter().any(|v| !v.is_finite()) {
            bail!("gru gave {} values (want {}) or a non-finite one", logits.len(), (m.horizon + 1) * NUM_CLASSES);
        }
        Ok(logits.chunks_exact(NUM_CLASSES).map(|c| c.try_into().expect("chunk of 4")).collect())
    }
}
