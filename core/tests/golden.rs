//! Golden tests: every runtime reproduces the outputs onnxruntime-Python gave for the
//! reference inputs shipped beside the models (`reference.json`), within 1e-4, run after
//! run (no state carried from one run to the next); a GCN that names its node count
//! gives the same outputs fed only a graph's real nodes as fed the padded graph; and a
//! model set that does not match its manifest is refused with an error naming the
//! file, the tensor and both shapes.
//!
//! The ort runtime is checked when built with `--features ort`; it then needs
//! `ORT_DYLIB_PATH` (`.ci/run` sets it to the onnxruntime wheel's library).

use spwi_core::manifest::{GcnNodes, ModelKind};
use spwi_core::model::{Backend, Input, ModelSet};
use std::path::{Path, PathBuf};

mod synthetic;

const TOLERANCE: f32 = 1e-4;

fn model_sets() -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models");
    let mut sets: Vec<PathBuf> = std::fs::read_dir(&root)
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.join("manifest.json").is_file() && p.join("reference.json").is_file())
        .collect();
    sets.sort();
    assert!(!sets.is_empty(), "no model set with reference.json under {}", root.display());
    sets
}

fn check_backend(backend: Backend) {
    for dir in model_sets() {
        let set = ModelSet::load(&dir, backend, None).unwrap_or_else(|e| panic!("{}: {e:#}", dir.display()));
        let reference: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("reference.json")).unwrap()).unwrap();
        for (name, spec) in set.manifest.models.all() {
            let inputs: Vec<(Vec<usize>, Vec<f32>)> = spec
                .inputs
                .iter()
                .map(|t| {
                    let r = &reference[name.name()]["inputs"][&t.name];
                    (shape(r), floats(r))
                })
                .collect();
            let feed: Vec<Input<'_>> = inputs.iter().map(|(s, d)| Input { shape: s, data: d }).collect();
            let mut runner = set.runner(name).unwrap();
            let got = runner.run(&feed).unwrap();
            // A run must not depend on the runs before it (a recurrent state carried
            // over would make the second window read as the first one's sequel).
            assert_eq!(runner.run(&feed).unwrap(), got, "{} {backend:?} {name}: a second run differs", dir.display());
            for (out, spec_out) in got.iter().zip(&spec.outputs) {
                let want = floats(&reference[name.name()]["outputs"][&spec_out.name]);
                assert_eq!(out.len(), want.len(), "{name}.{}", spec_out.name);
                let worst = out.iter().zip(&want).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
                assert!(
                    worst <= TOLERANCE,
                    "{} {backend:?} {name}.{}: max deviation {worst} > {TOLERANCE}",
                    dir.display(),
                    spec_out.name
                );
            }
        }
    }
}

fn floats(v: &serde_json::Value) -> Vec<f32> {
    v["data"].as_array().unwrap().iter().map(|x| x.as_f64().unwrap() as f32).collect()
}

fn shape(v: &serde_json::Value) -> Vec<usize> {
    v["shape"].as_array().unwrap().iter().map(|x| x.as_u64().unwrap() as usize).collect()
}

/// Every set whose GCN names its node count: the reference graph (padded, its real
/// nodes are those with a self-loop) fed with only its real nodes gives the padded
/// run's outputs within 1e-5.
fn check_real_nodes(backend: Backend) {
    let mut checked = 0;
    for dir in model_sets() {
        let set = ModelSet::load(&dir, backend, None).unwrap();
        if set.manifest.gcn_nodes() != GcnNodes::Real {
            continue;
        }
        let reference: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("reference.json")).unwrap()).unwrap();
        let (x, adj) = (&reference["gcn"]["inputs"]["x"], &reference["gcn"]["inputs"]["adj"]);
        let (x_shape, x, adj) = (shape(x), floats(x), floats(adj));
        let (max, features) = (x_shape[1], x_shape[2]);
        let real = (0..max).take_while(|&i| adj[i * max + i] > 0.0).count();
        assert!((1..max).contains(&real), "{}: the reference graph should be padded", dir.display());
        let block: Vec<f32> = (0..real).flat_map(|i| adj[i * max..i * max + real].to_vec()).collect();
        let mut runner = set.runner(ModelKind::Gcn).unwrap();
        let padded = runner
            .run(&[Input { shape: &[1, max, features], data: &x }, Input { shape: &[1, max, max], data: &adj }])
            .unwrap();
        let compact = runner
            .run(&[
                Input { shape: &[1, real, features], data: &x[..real * features] },
                Input { shape: &[1, real, real], data: &block },
            ])
            .unwrap();
        for (p, c) in padded.iter().zip(&compact) {
            let worst = p.iter().zip(c).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
            assert!(
                worst <= 1e-5,
                "{} {backend:?}: {real} real nodes differ from {max} padded by {worst}",
                dir.display()
            );
        }
        checked += 1;
    }
    assert!(checked >= 2, "the fixture and default sets name their node count");
}

#[test]
fn tract_matches_onnxruntime_python() {
    check_backend(Backend::Tract);
    check_real_nodes(Backend::Tract);
}

#[cfg(feature = "ort")]
#[test]
fn ort_matches_onnxruntime_python() {
    assert!(
        std::env::var_os("ORT_DYLIB_PATH").is_some(),
        "built with the ort feature but ORT_DYLIB_PATH is not set: point it at the onnxruntime wheel's libonnxruntime.so"
    );
    check_backend(Backend::Ort);
    check_real_nodes(Backend::Ort);
}

#[cfg(not(feature = "ort"))]
#[test]
fn ort_backend_without_the_feature_is_a_clear_error() {
    let dir = &model_sets()[0];
    let e = ModelSet::load(dir, Backend::Ort, None).unwrap_err().to_string();
    assert!(e.contains("--features ort"), "{e}");
}

/// A copy of the fixture set in a fresh temporary folder, for tampering.
fn fixture_copy(tag: &str) -> PathBuf {
    copy_of("fixture", tag)
}

/// A copy of the shipped set `set` (its manifest and GCN and GRUs) in a fresh
/// temporary folder.
fn copy_of(set: &str, tag: &str) -> PathBuf {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models").join(set);
    let dst = std::env::temp_dir().join(format!("spwi-golden-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dst);
    std::fs::create_dir_all(&dst).unwrap();
    for f in ["manifest.json", "gcn.onnx", "ego_gru.onnx", "collective_gru.onnx"] {
        std::fs::copy(src.join(f), dst.join(f)).unwrap();
    }
    dst
}

#[test]
fn a_set_whose_collective_cannot_take_the_peer_input_is_refused_naming_it() {
    // A relation set whose manifest claims a peer set its collective GRU does not read.
    let dir = copy_of("relations", "peers");
    let edit = |f: &dyn Fn(&mut serde_json::Value)| {
        let mut m: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("manifest.json")).unwrap()).unwrap();
        f(&mut m);
        std::fs::write(dir.join("manifest.json"), m.to_string()).unwrap();
    };
    edit(&|m| m["peer_slots"] = 7.into());
    let e = ModelSet::load(&dir, Backend::Tract, None).unwrap_err().to_string();
    assert!(e.contains("collective_gru.onnx") && e.contains("peers [1, 20, 7, 27]"), "{e}");
    // Peer blocks are relation blocks: a set of the paper's rows cannot have them.
    edit(&|m| {
        m.as_object_mut().unwrap().remove("row");
    });
    let e = ModelSet::load(&dir, Backend::Tract, None).unwrap_err().to_string();
    assert!(e.contains("peer_slots needs relation rows"), "{e}");
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn a_manifest_that_lies_about_a_shape_is_refused_naming_file_tensor_and_shapes() {
    let dir = fixture_copy("shape");
    let text = std::fs::read_to_string(dir.join("manifest.json")).unwrap();
    let mut m: serde_json::Value = serde_json::from_str(&text).unwrap();
    // The ONNX GCN names its node count; claim a fixed 12 everywhere so the interface
    // is self-consistent and only the file disagrees.
    m["max_nodes"] = 12.into();
    m["models"]["gcn"]["inputs"][0]["shape"] = serde_json::json!([1, 12, 1024]);
    m["models"]["gcn"]["inputs"][1]["shape"] = serde_json::json!([1, 12, 12]);
    std::fs::write(dir.join("manifest.json"), m.to_string()).unwrap();
    let e = ModelSet::load(&dir, Backend::Tract, None).unwrap_err().to_string();
    assert!(
        e.contains("gcn.onnx") && e.contains("\"x\"") && e.contains("[1, nodes, 1024]") && e.contains("[1, 12, 1024]"),
        "{e}"
    );
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn a_wrong_model_file_is_refused() {
    let dir = fixture_copy("swap");
    std::fs::copy(dir.join("ego_gru.onnx"), dir.join("collective_gru.onnx")).unwrap();
    let e = ModelSet::load(&dir, Backend::Tract, None).unwrap_err().to_string();
    assert!(e.contains("collective_gru.onnx") && e.contains("[1, 20, 290]") && e.contains("[1, 20, 162]"), "{e}");
    std::fs::write(dir.join("gcn.onnx"), b"not an onnx file").unwrap();
    let e = ModelSet::load(&dir, Backend::Tract, None).unwrap_err().to_string();
    assert!(e.contains("gcn.onnx"), "{e}");
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn a_model_file_changed_after_the_set_was_made_is_refused_naming_it() {
    let dir = fixture_copy("tampered");
    // One weight changed: the file still parses and fits the interface.
    let path = dir.join("ego_gru.onnx");
    let mut bytes = std::fs::read(&path).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0x40;
    std::fs::write(&path, &bytes).unwrap();
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/fixture");
    let spec = spwi_core::manifest::Manifest::load(&shipped).unwrap().models.ego_gru;
    spwi_core::manifest::check_onnx(&path, &spec).expect("the tampered file still parses and fits");
    let e = ModelSet::load(&dir, Backend::Tract, None).unwrap_err().to_string();
    assert!(e.contains("ego_gru.onnx") && e.contains("SHA-256") && e.contains("changed"), "{e}");
    // A manifest that names no digest is refused too.
    std::fs::write(&path, &{
        bytes[mid] ^= 0x40;
        bytes
    })
    .unwrap();
    let mut m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("manifest.json")).unwrap()).unwrap();
    m["models"]["gcn"].as_object_mut().unwrap().remove("sha256");
    std::fs::write(dir.join("manifest.json"), m.to_string()).unwrap();
    let e = ModelSet::load(&dir, Backend::Tract, None).unwrap_err().to_string();
    assert!(e.contains("gcn.onnx") && e.contains("names no sha256"), "{e}");
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn a_set_without_a_manifest_is_refused_naming_the_file_and_the_cause_once() {
    let dir = fixture_copy("no-manifest");
    std::fs::remove_file(dir.join("manifest.json")).unwrap();
    // `{:#}` is how the daemon prints a failed start: the whole chain.
    let e = format!("{:#}", ModelSet::load(&dir, Backend::Tract, None).unwrap_err());
    let not_found = std::fs::read_to_string(dir.join("manifest.json")).unwrap_err().to_string();
    assert!(e.contains("manifest.json") && e.contains(&not_found), "{e}");
    assert_eq!(e.matches(&not_found).count(), 1, "the cause is said once: {e}");
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn a_manifest_inconsistent_with_the_daemon_is_refused() {
    let dir = fixture_copy("window");
    let text = std::fs::read_to_string(dir.join("manifest.json")).unwrap();
    std::fs::write(dir.join("manifest.json"), text.replace("\"window\": 20", "\"window\": 30")).unwrap();
    let e = ModelSet::load(&dir, Backend::Tract, None).unwrap_err().to_string();
    assert!(e.contains("ego_gru") && e.contains("window 30"), "{e}");
    std::fs::remove_dir_all(dir).unwrap();
}

/// How loading a copy of the fixture fails once its manifest's `key` says `value`
/// (`{:#}`, as the daemon prints a failed start).
fn refusal_of_fixture_with(key: &str, value: &str) -> String {
    let dir = fixture_copy(&format!("{key}-{value}"));
    let text = std::fs::read_to_string(dir.join("manifest.json")).unwrap();
    let mut m: serde_json::Value = serde_json::from_str(&text).unwrap();
    m[key] = value.into();
    std::fs::write(dir.join("manifest.json"), m.to_string()).unwrap();
    let e = format!("{:#}", ModelSet::load(&dir, Backend::Tract, None).unwrap_err());
    std::fs::remove_dir_all(dir).unwrap();
    e
}

#[test]
fn a_set_whose_rows_the_daemon_cannot_build_is_refused_naming_the_tensor() {
    // The fixture GRUs read the paper's rows; a manifest claiming relation rows must not
    // load (the daemon would feed 61 values per row to a model that reads 162).
    let e = refusal_of_fixture_with("row", "relations");
    assert!(e.contains("ego_gru") && e.contains("Relations") && e.contains("[1, 20, 61]"), "{e}");
    let e = refusal_of_fixture_with("row", "holograms");
    assert!(e.contains("manifest.json") && e.contains("holograms"), "{e}");
}

#[test]
fn a_set_whose_graphs_the_daemon_cannot_build_is_refused_naming_the_tensor() {
    // The fixture's GCN reads appearance only (1024 values a node); a manifest claiming
    // floor relations must not load (the daemon would feed 1033).
    let e = refusal_of_fixture_with("node_features", "floor_relations");
    assert!(e.contains("gcn") && e.contains("FloorRelations") && e.contains("1033]") && e.contains("1024]"), "{e}");
    let e = refusal_of_fixture_with("node_features", "x-ray");
    assert!(e.contains("manifest.json") && e.contains("x-ray"), "{e}");
}

#[test]
fn the_daemons_gcn_gives_the_padded_graphs_outputs_from_its_real_nodes_alone() {
    use spwi_core::graph::GraphBuilder;
    use spwi_core::temporal::TemporalModel;
    for set in ["fixture", "default"] {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models").join(set);
        let set = ModelSet::load(&dir, Backend::Tract, None).unwrap();
        let m = &set.manifest;
        assert_eq!(m.gcn_nodes(), GcnNodes::Real, "{}", dir.display());
        let mut inference = set.inference(TemporalModel::Ego).unwrap();
        let mut padded = set.runner(ModelKind::Gcn).unwrap();
        let mut builder = GraphBuilder::new(m.max_nodes, m.edge_weight, m.node_features);
        let camera = spwi_core::floor::CameraCalibration::default();
        for objects in [0, 3, m.max_nodes - 1] {
            let g = builder.build(&synthetic::frame(1, objects), Some(synthetic::on_floor(&camera))).unwrap().clone();
            let (n, f) = (m.max_nodes, g.x.len() / m.max_nodes);
            let want = padded
                .run(&[Input { shape: &[1, n, f], data: &g.x }, Input { shape: &[1, n, n], data: &g.adj }])
                .unwrap();
            let got = inference.gcn(&g).unwrap();
            for (name, w, have) in [("embedding", &want[0], &got.embedding[..]), ("logits", &want[1], &got.logits[..])]
            {
                let worst = w.iter().zip(have).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
                assert!(worst <= 1e-5, "{} {objects} objects: {name} differs by {worst}", dir.display());
            }
        }
    }
}
