//! Per-tick features → the GRU's input window (paper II-D, DESIGN "Temporal").
//!
//! Each decided tick leaves one row. The paper's rows ([`RowLayout::Paper`]): the
//! robot's own embedding, the mean of the peers' embeddings that arrived for that tick,
//! and the worker's keypoints normalised by the image size to [0, 1]. Relation rows
//! ([`RowLayout::Relations`]): the keypoints and the worker's relations to the mapped
//! stations ([`crate::floor::relations`]: the robot's own track and map for the ego
//! model, the team's fused track and shared map for the collective) — no embedding,
//! because the GCN's embedding does not carry over to floors it was not trained on
//! (with it the GRU overfits its training floors: models/README.md). A tick with no row (frame lost) or a part missing (worker not
//! seen, no peer saw it) contributes zeros, which is how the models are trained to read
//! absence. Rows are keyed by tick, so a window is always the W ticks ending at t, in
//! order, whatever order the ticks were processed in.
//!
//! Rows with facing ([`RowLayout::RelationsFacing`]) add, after the relations, where
//! the worker's body faces against each station ([`crate::floor::facing`]), from the
//! robot's own view of the keypoints.
//!
//! A collective model with a peer set (`peer_slots` in its manifest) also reads, per
//! picked tick, one relation block per peer heard ([`crate::floor::peer_set`]): its
//! second input, `[frames, slots, RELATION_DIM]` ([`Window::peer_input`]).

use crate::floor::{self, FACING_DIM, RELATION_DIM};
use spwi_proto::{WorkerEstimate, EMBEDDING_DIM, KEYPOINT_VALUES, NUM_CLASSES};
use std::collections::BTreeMap;

/// Width of one ego-GRU row of the paper: own embedding ‖ keypoints.
pub const EGO_DIM: usize = EMBEDDING_DIM + KEYPOINT_VALUES;
/// Width of one collective-GRU row of the paper: own ‖ mean of peers ‖ keypoints.
pub const COLLECTIVE_DIM: usize = 2 * EMBEDDING_DIM + KEYPOINT_VALUES;

/// What a temporal row holds (recorded in the manifest: a model is only valid with the
/// rows it was trained on).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RowLayout {
    /// The paper's rows: embeddings and keypoints.
    #[default]
    Paper,
    /// Keypoints, then the worker's relations to the mapped stations (the robot's own
    /// for the ego model, the team's for the collective).
    Relations,
    /// [`RowLayout::Relations`], then where the worker faces against each station.
    RelationsFacing,
}

impl RowLayout {
    /// Rows of keypoints and relations (with or without facing): no embedding.
    pub fn reads_relations(self) -> bool {
        matches!(self, RowLayout::Relations | RowLayout::RelationsFacing)
    }

    /// The relation and facing blocks of a row of this layout (`None` for the parts
    /// it does not read): `worker` and where its body faces against `stations`.
    pub fn blocks(
        self,
        worker: Option<&WorkerEstimate>,
        facing: Option<f32>,
        stations: &[Option<[f32; 2]>; NUM_CLASSES],
    ) -> (Option<Vec<f32>>, Option<Vec<f32>>) {
        let relations = self.reads_relations().then(|| {
            let mut r = vec![0.0; RELATION_DIM];
            floor::relations(worker, stations, &mut r);
            r
        });
        let facing = (self == RowLayout::RelationsFacing).then(|| {
            let mut f = vec![0.0; FACING_DIM];
            floor::facing(worker, facing, stations, &mut f);
            f
        });
        (relations, facing)
    }
}

/// Width of a relation row: keypoints ‖ relations.
pub const RELATION_ROW_DIM: usize = KEYPOINT_VALUES + RELATION_DIM;
/// Width of a relation row with facing: keypoints ‖ relations ‖ facing.
pub const FACING_ROW_DIM: usize = RELATION_ROW_DIM + FACING_DIM;

/// Width of one row of the 1D-CNN baseline: the worker node's feature ‖ keypoints.
pub const CNN1D_DIM: usize = crate::graph::NODE_FEATURE_DIM + KEYPOINT_VALUES;

/// Which ticks of a `window`-tick history feed a model that reads `frames` rows:
/// uniform intervals, first and last included (the paper's "pick the required number
/// of frames at uniform intervals"). Offsets count from the oldest tick. Training
/// (models/train) picks with the same formula: round(j (window-1) / (frames-1)), halves up.
pub fn frame_offsets(window: usize, frames: usize) -> Vec<usize> {
    assert!(frames >= 1 && frames <= window, "1 <= frames <= window");
    if frames == 1 {
        return vec![window - 1];
    }
    (0..frames).map(|j| (2 * j * (window - 1) + (frames - 1)) / (2 * (frames - 1))).collect()
}

/// Which temporal model a robot runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TemporalModel {
    /// Own observations only.
    Ego,
    /// Own observations plus the mean of the peers' embeddings.
    Collective,
}

impl TemporalModel {
    pub fn row_dim(self, layout: RowLayout) -> usize {
        match (layout, self) {
            (RowLayout::Paper, TemporalModel::Ego) => EGO_DIM,
            (RowLayout::Paper, TemporalModel::Collective) => COLLECTIVE_DIM,
            (RowLayout::Relations, _) => RELATION_ROW_DIM,
            (RowLayout::RelationsFacing, _) => FACING_ROW_DIM,
        }
    }
}

/// What one tick contributes to the window.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Row {
    pub own: Option<Vec<f32>>,
    pub peers_mean: Option<Vec<f32>>,
    pub keypoints: Option<Vec<f32>>,
    /// The relation block, for [`RowLayout::Relations`] and with facing.
    pub relations: Option<Vec<f32>>,
    /// The facing block, for [`RowLayout::RelationsFacing`].
    pub facing: Option<Vec<f32>>,
    /// The peers' relation blocks (`slots` × `RELATION_DIM`), for a peer-set model.
    pub peers: Option<Vec<f32>>,
}

/// Normalises pixel keypoints by the image size, x by width and y by height.
pub fn normalise_keypoints(keypoints: &[f32], image_size: [f32; 2]) -> Vec<f32> {
    keypoints.iter().enumerate().map(|(i, &v)| v / image_size[i % 2]).collect()
}

/// The mean of the given embeddings, or `None` if there are none.
pub fn mean<'a>(embeddings: impl IntoIterator<Item = &'a [f32]>) -> Option<Vec<f32>> {
    let mut sum = vec![0.0f32; EMBEDDING_DIM];
    let mut n = 0usize;
    for e in embeddings {
        for (s, v) in sum.iter_mut().zip(e) {
            *s += v;
        }
        n += 1;
    }
    (n > 0).then(|| sum.into_iter().map(|s| s / n as f32).collect())
}

/// The last `len` ticks' rows.
#[derive(Debug, Clone)]
pub struct Window {
    len: usize,
    layout: RowLayout,
    /// Which of the `len` ticks feed the model (all of them unless the model reads fewer frames).
    picked: Vec<usize>,
    /// Peer blocks per row of the peer input (0: the model reads none).
    peer_slots: usize,
    rows: BTreeMap<u64, Row>,
}

impl Window {
    /// `len` ≥ 1 ticks of paper rows, every one fed to the model.
    pub fn new(len: usize) -> Self {
        Self::with_frames(len, len, RowLayout::Paper)
    }

    /// `len` ≥ 1 ticks of which `frames` (1..=len), at uniform intervals, feed the model.
    pub fn with_frames(len: usize, frames: usize, layout: RowLayout) -> Self {
        assert!(len >= 1, "a window holds at least one tick");
        Window { len, layout, picked: frame_offsets(len, frames), peer_slots: 0, rows: BTreeMap::new() }
    }

    /// The same window, also giving the peer input of a model with `slots` peer slots.
    pub fn with_peer_slots(self, slots: usize) -> Self {
        Window { peer_slots: slots, ..self }
    }

    /// Rows the model reads.
    pub fn frames(&self) -> usize {
        self.picked.len()
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// Records tick `tick`'s row and forgets rows that no window ending at or after
    /// `tick` can reach.
    pub fn insert(&mut self, tick: u64, row: Row) {
        self.rows.insert(tick, row);
        let newest = self.rows.keys().next_back().copied().unwrap_or(tick);
        let oldest = newest.saturating_sub(self.len as u64 - 1);
        self.rows = self.rows.split_off(&oldest);
    }

    /// The flattened `[frames, row_dim]` input for the window ending at `tick`, into
    /// `out`. Ticks before the first (tick < len - 1) and ticks with no row are zeros.
    pub fn input(&self, tick: u64, model: TemporalModel, out: &mut Vec<f32>) {
        let dim = model.row_dim(self.layout);
        out.clear();
        out.resize(self.picked.len() * dim, 0.0);
        for (j, row) in self.picked_rows(tick) {
            let slot = &mut out[j * dim..(j + 1) * dim];
            if self.layout.reads_relations() {
                if let Some(kp) = &row.keypoints {
                    slot[..KEYPOINT_VALUES].copy_from_slice(kp);
                }
                if let Some(r) = &row.relations {
                    slot[KEYPOINT_VALUES..RELATION_ROW_DIM].copy_from_slice(r);
                }
                if let (RowLayout::RelationsFacing, Some(f)) = (self.layout, &row.facing) {
                    slot[RELATION_ROW_DIM..].copy_from_slice(f);
                }
                continue;
            }
            if let Some(e) = &row.own {
                slot[..EMBEDDING_DIM].copy_from_slice(e);
            }
            let mut k = EMBEDDING_DIM;
            if model == TemporalModel::Collective {
                if let Some(p) = &row.peers_mean {
                    slot[k..k + EMBEDDING_DIM].copy_from_slice(p);
                }
                k += EMBEDDING_DIM;
            }
            if let Some(kp) = &row.keypoints {
                slot[k..k + KEYPOINT_VALUES].copy_from_slice(kp);
            }
        }
    }

    /// The flattened `[frames, slots, RELATION_DIM]` peer input for the window ending
    /// at `tick`, into `out` (empty when the model reads no peer set); rows without
    /// peer blocks are zeros, read as no peer heard.
    pub fn peer_input(&self, tick: u64, out: &mut Vec<f32>) {
        let dim = self.peer_slots * RELATION_DIM;
        out.clear();
        out.resize(self.picked.len() * dim, 0.0);
        for (j, row) in self.picked_rows(tick) {
            if let Some(p) = &row.peers {
                out[j * dim..(j + 1) * dim].copy_from_slice(p);
            }
        }
    }

    /// The rows the model reads for the window ending at `tick`, with the frame each
    /// fills: ticks before the first (left padding) and ticks with no row are skipped.
    fn picked_rows(&self, tick: u64) -> impl Iterator<Item = (usize, &Row)> {
        let oldest = tick as i64 - (self.len as i64 - 1); // may be negative: left padding
        self.picked.iter().enumerate().filter_map(move |(j, &k)| {
            u64::try_from(oldest + k as i64).ok().and_then(|t| self.rows.get(&t)).map(|row| (j, row))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(v: f32) -> Row {
        Row {
            own: Some(vec![v; EMBEDDING_DIM]),
            peers_mean: Some(vec![-v; EMBEDDING_DIM]),
            keypoints: Some(vec![v / 10.0; KEYPOINT_VALUES]),
            relations: Some(vec![v * 100.0; RELATION_DIM]),
            facing: Some(vec![-v; FACING_DIM]),
            peers: Some(vec![v; 2 * RELATION_DIM]),
        }
    }

    #[test]
    fn ego_rows_are_own_then_keypoints_in_tick_order() {
        let mut w = Window::new(3);
        w.insert(11, row(2.0));
        w.insert(10, row(1.0)); // out of order on purpose
        w.insert(12, row(3.0));
        let mut out = Vec::new();
        w.input(12, TemporalModel::Ego, &mut out);
        assert_eq!(out.len(), 3 * EGO_DIM);
        for (i, v) in [1.0, 2.0, 3.0].into_iter().enumerate() {
            assert_eq!(out[i * EGO_DIM], v);
            assert_eq!(out[i * EGO_DIM + EMBEDDING_DIM], v / 10.0);
        }
    }

    #[test]
    fn collective_rows_carry_the_peer_mean_and_gaps_are_zero() {
        let mut w = Window::new(3);
        w.insert(5, row(1.0));
        w.insert(7, Row { peers_mean: Some(vec![4.0; EMBEDDING_DIM]), ..Row::default() });
        let mut out = Vec::new();
        w.input(7, TemporalModel::Collective, &mut out);
        let d = COLLECTIVE_DIM;
        assert_eq!(&out[..3], &[1.0, 1.0, 1.0]);
        assert_eq!(out[EMBEDDING_DIM], -1.0);
        assert!(out[d..2 * d].iter().all(|&v| v == 0.0), "tick 6 missing → zeros");
        assert_eq!(out[2 * d], 0.0, "worker unseen at 7 → own zeros");
        assert_eq!(out[2 * d + EMBEDDING_DIM], 4.0);
    }

    #[test]
    fn early_ticks_are_left_padded_and_old_rows_forgotten() {
        let mut w = Window::new(4);
        w.insert(1, row(1.0));
        let mut out = Vec::new();
        w.input(1, TemporalModel::Ego, &mut out);
        assert!(out[..3 * EGO_DIM].iter().all(|&v| v == 0.0));
        assert_eq!(out[3 * EGO_DIM], 1.0);
        for t in 2..100 {
            w.insert(t, row(t as f32));
        }
        assert_eq!(w.rows.len(), 4);
    }

    #[test]
    fn fewer_frames_are_picked_at_uniform_intervals() {
        assert_eq!(frame_offsets(10, 10), (0..10).collect::<Vec<_>>());
        assert_eq!(frame_offsets(10, 5), vec![0, 2, 5, 7, 9]);
        assert_eq!(frame_offsets(10, 3), vec![0, 5, 9]);
        assert_eq!(frame_offsets(20, 1), vec![19]);
        let mut w = Window::with_frames(10, 3, RowLayout::Paper);
        for t in 0..30 {
            w.insert(t, row(t as f32));
        }
        let mut out = Vec::new();
        w.input(29, TemporalModel::Ego, &mut out);
        assert_eq!(out.len(), 3 * EGO_DIM);
        let firsts: Vec<f32> = (0..3).map(|j| out[j * EGO_DIM]).collect();
        assert_eq!(firsts, vec![20.0, 25.0, 29.0]);
    }

    #[test]
    fn relation_rows_are_keypoints_then_relations() {
        let mut w = Window::with_frames(2, 2, RowLayout::Relations);
        w.insert(4, row(1.0));
        w.insert(5, Row { relations: None, ..row(2.0) });
        let mut out = Vec::new();
        w.input(5, TemporalModel::Collective, &mut out);
        let d = RELATION_ROW_DIM;
        assert_eq!(TemporalModel::Ego.row_dim(RowLayout::Relations), d);
        assert_eq!(out.len(), 2 * d);
        assert!(out[..KEYPOINT_VALUES].iter().all(|&v| v == 0.1));
        assert!(out[KEYPOINT_VALUES..d].iter().all(|&v| v == 100.0));
        assert!(out[d..d + KEYPOINT_VALUES].iter().all(|&v| v == 0.2));
        assert!(out[d + KEYPOINT_VALUES..].iter().all(|&v| v == 0.0), "no relations: zeros");
    }

    #[test]
    fn each_layout_gets_the_blocks_it_reads() {
        let w = WorkerEstimate { position: [0.0, 0.0], velocity: [1.0, 0.0], covariance: [0.04, 0.0, 0.04] };
        let stations = [Some([5.0, 0.0]), None, None, None];
        let blocks = |layout: RowLayout| layout.blocks(Some(&w), Some(0.0), &stations);
        assert_eq!(blocks(RowLayout::Paper), (None, None));
        let (r, f) = blocks(RowLayout::Relations);
        assert!(r.is_some_and(|r| r.len() == RELATION_DIM && r[0] == 1.0) && f.is_none());
        let (r, f) = blocks(RowLayout::RelationsFacing);
        assert!(r.is_some_and(|r| r[0] == 1.0));
        assert_eq!(f.unwrap()[..3], [1.0, 1.0, 0.0], "facing known, station 0 straight ahead");
    }

    #[test]
    fn facing_rows_add_the_facing_block_after_the_relations() {
        let mut w = Window::with_frames(2, 2, RowLayout::RelationsFacing);
        w.insert(4, row(1.0));
        w.insert(5, Row { facing: None, ..row(2.0) });
        let mut out = Vec::new();
        w.input(5, TemporalModel::Ego, &mut out);
        let d = FACING_ROW_DIM;
        assert_eq!(TemporalModel::Collective.row_dim(RowLayout::RelationsFacing), d);
        assert_eq!(out.len(), 2 * d);
        assert!(out[KEYPOINT_VALUES..RELATION_ROW_DIM].iter().all(|&v| v == 100.0));
        assert!(out[RELATION_ROW_DIM..d].iter().all(|&v| v == -1.0));
        assert!(out[d + KEYPOINT_VALUES..d + RELATION_ROW_DIM].iter().all(|&v| v == 200.0));
        assert!(out[d + RELATION_ROW_DIM..].iter().all(|&v| v == 0.0), "facing unknown: zeros");
    }

    #[test]
    fn the_peer_input_holds_each_picked_ticks_peer_blocks() {
        let mut w = Window::with_frames(3, 2, RowLayout::Relations).with_peer_slots(2);
        w.insert(10, row(1.0));
        w.insert(11, row(2.0));
        w.insert(12, Row { peers: None, ..row(3.0) });
        let mut out = Vec::new();
        w.peer_input(12, &mut out);
        let d = 2 * RELATION_DIM;
        assert_eq!(out.len(), 2 * d, "frames 10 and 12");
        assert!(out[..d].iter().all(|&v| v == 1.0));
        assert!(out[d..].iter().all(|&v| v == 0.0), "no peer heard: zeros");
        Window::with_frames(3, 3, RowLayout::Relations).peer_input(12, &mut out);
        assert!(out.is_empty(), "a model without a peer set reads none");
    }

    #[test]
    fn mean_and_keypoint_normalisation() {
        let a = vec![1.0; EMBEDDING_DIM];
        let b = vec![3.0; EMBEDDING_DIM];
        assert_eq!(mean([a.as_slice(), b.as_slice()]).unwrap()[0], 2.0);
        assert!(mean(std::iter::empty()).is_none());
        assert_eq!(normalise_keypoints(&[64.0, 48.0], [640.0, 480.0]), vec![0.1, 0.1]);
    }
}
