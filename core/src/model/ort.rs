//! The ONNX Runtime backend (cargo feature `ort`). The runtime library is loaded at
//! run time with `ort::init_from`, from the path given in config or `ORT_DYLIB_PATH`:
//! the `libonnxruntime.so.*` inside the `onnxruntime` PyPI wheel, whose version must
//! match the `ort` crate (1.31 for 2.0.0-rc.15). A wrong path is an error at start-up,
//! not a panic at the first tick. Each robot gets its own session (ort runs need
//! `&mut Session`), with one intra-op thread.

use super::{Input, LoadedModel, Runner};
use anyhow::{anyhow, bail, Context, Result};
use ort::session::Session;
use ort::value::TensorRef;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, OnceLock};

static ENVIRONMENT: OnceLock<ort::environment::Environment> = OnceLock::new();
static INIT: Mutex<()> = Mutex::new(());

fn environment(library: Option<&Path>) -> Result<&'static ort::environment::Environment> {
    let _guard = INIT.lock().map_err(|_| anyhow!("ort initialisation lock poisoned"))?;
    if let Some(env) = ENVIRONMENT.get() {
        return Ok(env);
    }
    let path: PathBuf = match library {
        Some(p) => p.to_owned(),
        None => std::env::var_os("ORT_DYLIB_PATH").map(PathBuf::from).context(
            "the ort backend needs the ONNX Runtime library: set models.ort_library in the config or ORT_DYLIB_PATH",
        )?,
    };
    if !path.is_file() {
        bail!("ONNX Runtime library {} does not exist", path.display());
    }
    let env = ort::init_from(&path)
        .map_err(|e| anyhow!("cannot load ONNX Runtime from {}: {e}", path.display()))?
        .with_name("spwi")
        .build()
        .map_err(|e| anyhow!("cannot start ONNX Runtime from {}: {e}", path.display()))?;
    Ok(ENVIRONMENT.get_or_init(|| env))
}

pub struct OrtModel {
    path: PathBuf,
    env: &'static ort::environment::Environment,
}

impl OrtModel {
    pub fn load(path: &Path, library: Option<&Path>) -> Result<Self> {
        let model = OrtModel { path: path.to_owned(), env: environment(library)? };
        model.session()?; // fail at start-up, not at the first tick
        Ok(model)
    }

    fn session(&self) -> Result<Session> {
        // Builder errors carry the builder and are not Send + Sync: map them to text.
        let err = |e: ort::Error<_>| anyhow!("{}: ONNX Runtime refused the model: {e}", self.path.display());
        Session::builder(self.env)
            .map_err(|e| anyhow!("{}: {e}", self.path.display()))?
            .with_intra_threads(1)
            .map_err(err)?
            .commit_from_file(&self.path)
            .map_err(|e| anyhow!("{}: ONNX Runtime refused the model: {e}", self.path.display()))
    }
}

impl LoadedModel for OrtModel {
    fn runner(&self) -> Result<Box<dyn Runner>> {
        Ok(Box::new(OrtRunner { session: self.session()? }))
    }
}

struct OrtRunner {
    session: Session,
}

impl Runner for OrtRunner {
    fn run(&mut self, inputs: &[Input<'_>]) -> Result<Vec<Vec<f32>>> {
        let values = inputs
            .iter()
            .map(|i| {
                let shape: Vec<i64> = i.shape.iter().map(|&d| d as i64).collect();
                TensorRef::from_array_view((shape, i.data)).map(ort::session::SessionInputValue::from)
            })
            .collect::<ort::Result<Vec<_>>>()?;
        let outputs = self.session.run(values.as_slice())?;
        outputs.iter().map(|(_, v)| Ok(v.try_extract_tensor::<f32>()?.1.to_vec())).collect()
    }
}
