//! The shipped relation sets score stations, not class slots: each station is judged by
//! its own relation to the worker (and, in the default set, by where the worker faces
//! against it), through one network shared by all stations (the `StationScorer` and
//! `FacingScorer` of models/train/nets.py). So if the stations of every row are
//! handed over in another order, the logits come back in that order, to float
//! precision. A model that learned "slot 2 on the training floors" fails this test.
//! Likewise a set that pools its peers (`peer_slots`) must not care which slot holds
//! which peer.

use spwi_core::floor::relations::{FACING_HEAD, FACING_PER_STATION, PER_STATION, TRACK_VALUES};
use spwi_core::manifest::ModelKind;
use spwi_core::model::{Backend, Input, ModelSet};
use spwi_core::temporal::{RowLayout, TemporalModel, RELATION_ROW_DIM};
use spwi_proto::{KEYPOINT_VALUES, NUM_CLASSES};
use std::path::Path;

/// The stations of every row of `x` (rows of `layout`) reordered: slot `k` of the
/// result holds station `order[k]`, in the relation block and in the facing block
/// where the rows have one.
fn reorder_stations(x: &[f32], layout: RowLayout, order: [usize; NUM_CLASSES]) -> Vec<f32> {
    // Relation rows are the same for the ego and the collective model.
    let row_dim = TemporalModel::Collective.row_dim(layout);
    let mut blocks = vec![(KEYPOINT_VALUES + TRACK_VALUES, PER_STATION)];
    if layout == RowLayout::RelationsFacing {
        blocks.push((RELATION_ROW_DIM + FACING_HEAD, FACING_PER_STATION));
    }
    let mut out = x.to_vec();
    for (row_in, row_out) in x.chunks_exact(row_dim).zip(out.chunks_exact_mut(row_dim)) {
        for &(first, width) in &blocks {
            for (k, &from) in order.iter().enumerate() {
                let (src, dst) = (first + from * width, first + k * width);
                row_out[dst..dst + width].copy_from_slice(&row_in[src..src + width]);
            }
        }
    }
    out
}

#[test]
fn reordering_the_stations_reorders_the_relation_sets_logits() {
    for (name, layout) in [("relations", RowLayout::Relations), ("default", RowLayout::RelationsFacing)] {
        reordering_the_stations_reorders_the_logits_of(name, layout);
    }
}

fn reordering_the_stations_reorders_the_logits_of(set_name: &str, layout: RowLayout) {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models").join(set_name);
    let set = ModelSet::load(&dir, Backend::Tract, None).unwrap();
    assert_eq!(set.manifest.row, layout, "{set_name}: its rows");
    let reference: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("reference.json")).unwrap()).unwrap();
    let order = [2, 0, 3, 1];
    for name in [ModelKind::EgoGru, ModelKind::CollectiveGru] {
        let spec = set.manifest.models.get(name).unwrap();
        let shape = &spec.inputs[0].fixed_shape().expect("a GRU's window has a fixed shape");
        let x: Vec<f32> = reference[name.name()]["inputs"][&spec.inputs[0].name]["data"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap() as f32)
            .collect();
        let known =
            |x: &[f32], s: usize| x[shape[2] * (shape[1] - 1) + KEYPOINT_VALUES + TRACK_VALUES + s * PER_STATION];
        assert!(
            (0..NUM_CLASSES).filter(|&s| known(&x, s) > 0.0).count() >= 2,
            "{set_name} {name}: the reference window should map at least two stations"
        );
        let mut runner = set.runner(name).unwrap();
        let mut logits = |x: &[f32]| runner.run(&[Input { shape, data: x }]).unwrap().remove(0);
        let plain = logits(&x);
        assert_eq!(shape[2], TemporalModel::Collective.row_dim(layout), "{set_name} {name}: a row's width");
        let reordered = logits(&reorder_stations(&x, layout, order));
        let mut differs = false;
        for (step, (p, r)) in plain.chunks_exact(NUM_CLASSES).zip(reordered.chunks_exact(NUM_CLASSES)).enumerate() {
            for (k, &from) in order.iter().enumerate() {
                assert!(
                    (r[k] - p[from]).abs() < 1e-4,
                    "{set_name} {name} step {step}: slot {k} {} vs station {from} {}",
                    r[k],
                    p[from]
                );
                differs |= (r[k] - p[k]).abs() > 1e-3;
            }
        }
        assert!(differs, "{set_name} {name}: the stations' scores should differ, or the test shows nothing");
    }
}

/// Every shipped set that fuses its peers with a set model gives the same logits
/// whatever slots its peers sit in (to float precision), and its output depends on
/// them: the pooling is over peers, not slot positions.
#[test]
fn a_peer_set_gives_the_same_logits_for_its_peers_in_any_slots() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models");
    let mut checked = 0;
    for dir in std::fs::read_dir(&root).unwrap().map(|e| e.unwrap().path()) {
        let Ok(set) = ModelSet::load(&dir, Backend::Tract, None) else { continue };
        let Some(slots) = set.manifest.peer_slots else { continue };
        let reference: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("reference.json")).unwrap()).unwrap();
        let spec = set.manifest.models.get(ModelKind::CollectiveGru).unwrap();
        let input = |i: usize| -> (Vec<usize>, Vec<f32>) {
            let t = &reference["collective_gru"]["inputs"][&spec.inputs[i].name];
            let shape = t["shape"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap() as usize).collect();
            (shape, t["data"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap() as f32).collect())
        };
        let ((x_shape, x), (p_shape, peers)) = (input(0), input(1));
        let block = p_shape[3];
        let frames: Vec<&[f32]> = peers.chunks_exact(slots * block).collect();
        let heard = |f: &[f32]| f.chunks_exact(block).filter(|b| b[0] > 0.0).count();
        assert!(
            frames.iter().any(|f| heard(f) >= 2),
            "{}: the reference window should hold two or more peers",
            dir.display()
        );
        let mut runner = set.runner(ModelKind::CollectiveGru).unwrap();
        let mut logits = |peers: &[f32]| {
            runner
                .run(&[Input { shape: &x_shape, data: &x }, Input { shape: &p_shape, data: peers }])
                .unwrap()
                .remove(0)
        };
        let plain = logits(&peers);
        // Each frame's slots rotated by a different amount: blocks move, empty slots too.
        let shuffled: Vec<f32> = frames
            .iter()
            .enumerate()
            .flat_map(|(j, f)| {
                let mut blocks: Vec<&[f32]> = f.chunks_exact(block).collect();
                blocks.rotate_left((j * 3 + 1) % slots);
                blocks.concat()
            })
            .collect();
        assert_ne!(shuffled, peers);
        let worst = plain.iter().zip(logits(&shuffled)).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        assert!(worst < 1e-4, "{}: shuffled peers change the logits by {worst}", dir.display());
        let alone = logits(&vec![0.0; peers.len()]);
        let moved = plain.iter().zip(&alone).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        assert!(moved > 1e-3, "{}: the logits should depend on the peers, or the test shows nothing", dir.display());
        checked += 1;
    }
    assert!(checked >= 1, "no shipped set has a peer set (models/peer-set)");
}
