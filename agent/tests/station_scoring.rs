//! The shipped relation set scores stations, not class slots: each station is judged by
//! its own relation to the worker, through one network shared by all stations (the
//! `StationScorer` of models/train/nets.py). So if the stations of every row are
//! handed over in another order, the logits come back in that order, to float
//! precision. A model that learned "slot 2 on the training floors" fails this test.

use spwi_agent::floor::relations::{PER_STATION, TRACK_VALUES};
use spwi_agent::manifest::ModelKind;
use spwi_agent::model::{Backend, Input, ModelSet};
use spwi_agent::temporal::RowLayout;
use spwi_proto::{KEYPOINT_VALUES, NUM_CLASSES};
use std::path::Path;

/// The stations of every row of `x` (rows of `row_dim`) reordered: slot `k` of the
/// result holds station `order[k]`.
fn reorder_stations(x: &[f32], row_dim: usize, order: [usize; NUM_CLASSES]) -> Vec<f32> {
    let first = KEYPOINT_VALUES + TRACK_VALUES;
    let mut out = x.to_vec();
    for (row_in, row_out) in x.chunks_exact(row_dim).zip(out.chunks_exact_mut(row_dim)) {
        for (k, &from) in order.iter().enumerate() {
            let (src, dst) = (first + from * PER_STATION, first + k * PER_STATION);
            row_out[dst..dst + PER_STATION].copy_from_slice(&row_in[src..src + PER_STATION]);
        }
    }
    out
}

#[test]
fn reordering_the_stations_reorders_the_default_sets_logits() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/default");
    let set = ModelSet::load(&dir, Backend::Tract, None).unwrap();
    assert_eq!(set.manifest.row, RowLayout::Relations, "the default set reads relation rows");
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
            "{name}: the reference window should map at least two stations"
        );
        let mut runner = set.runner(name).unwrap();
        let mut logits = |x: &[f32]| runner.run(&[Input { shape, data: x }]).unwrap().remove(0);
        let plain = logits(&x);
        let reordered = logits(&reorder_stations(&x, shape[2], order));
        let mut differs = false;
        for (step, (p, r)) in plain.chunks_exact(NUM_CLASSES).zip(reordered.chunks_exact(NUM_CLASSES)).enumerate() {
            for (k, &from) in order.iter().enumerate() {
                assert!(
                    (r[k] - p[from]).abs() < 1e-4,
                    "{name} step {step}: slot {k} {} vs station {from} {}",
                    r[k],
                    p[from]
                );
                differs |= (r[k] - p[k]).abs() > 1e-3;
            }
        }
        assert!(differs, "{name}: the stations' scores should differ, or the test shows nothing");
    }
}
