//! One robot's pipeline in the evaluation: exactly the agent's stages, called as a
//! library — [`GraphBuilder`], the GCN and GRUs through [`Inference`], the temporal
//! [`Window`], [`vote`] — plus the two baselines the paper compares against (the
//! constant-velocity model and the 1D-CNN). The fleet wiring (who hears whom, the
//! consensus) is in `fleet.rs`.

use super::cvm::{back_project, Cvm, HEAD_HEIGHT};
use crate::layout::Camera;
use anyhow::Result;
use spwi_agent::graph::{GraphBuilder, NODE_FEATURE_DIM};
use spwi_agent::model::{Inference, Input, ModelSet, Runner};
use spwi_agent::temporal::{frame_offsets, normalise_keypoints, Row, TemporalModel, Window, CNN1D_DIM};
use spwi_agent::vote;
use spwi_proto::{DetectionFrame, RobotId, RobotPose, StepVote, NUM_CLASSES};
use std::collections::BTreeMap;
use std::sync::Arc;

/// What a robot makes of its own frame.
pub struct Perception {
    pub visibility: u32,
    pub embedding: Option<Vec<f32>>,
    pub gcn_class: Option<u8>,
    keypoints: Option<Vec<f32>>,
}

/// A robot's predictions for one tick (each `None` when it does not see the worker).
#[derive(Debug, Clone, Default)]
pub struct Predictions {
    pub gnn: Option<u8>,
    /// Class for t and each future step.
    pub ego: Option<Vec<u8>>,
    pub collective: Option<Vec<u8>>,
    pub cnn1d: Option<Vec<u8>>,
    pub cvm: Option<Vec<u8>>,
    /// The collective GRU's vote, as the daemon publishes it.
    pub vote: Option<Vec<StepVote>>,
}

pub struct RobotPipeline {
    pub id: RobotId,
    pub slot: usize,
    graph: GraphBuilder,
    ego: Inference,
    collective: Inference,
    cnn1d: Option<Box<dyn Runner>>,
    /// One window serves both GRUs: the ego input is the same rows without the peers' part.
    window_rows: Window,
    /// The 1D-CNN's rows (worker feature ‖ keypoints) by tick.
    cnn_rows: BTreeMap<u64, Vec<f32>>,
    cvm: Cvm,
    scratch: Vec<f32>,
    window: usize,
    frames: usize,
    horizon: usize,
    temperature: f32,
}

fn classes(logits: &[[f32; NUM_CLASSES]]) -> Vec<u8> {
    logits.iter().map(|z| vote::argmax(z) as u8).collect()
}

impl RobotPipeline {
    pub fn new(id: RobotId, slot: usize, models: &Arc<ModelSet>) -> Result<Self> {
        let m = &models.manifest;
        Ok(RobotPipeline {
            id,
            slot,
            graph: GraphBuilder::new(m.max_nodes, m.edge_weight),
            ego: models.inference(TemporalModel::Ego)?,
            collective: models.inference(TemporalModel::Collective)?,
            cnn1d: m.models.cnn1d.is_some().then(|| models.runner("cnn1d")).transpose()?,
            window_rows: Window::with_frames(m.window, m.frames()),
            cnn_rows: BTreeMap::new(),
            cvm: Cvm::new(0.1),
            scratch: Vec::new(),
            window: m.window,
            frames: m.frames(),
            horizon: m.horizon,
            temperature: models.temperature(TemporalModel::Collective),
        })
    }

    pub fn has_cnn1d(&self) -> bool {
        self.cnn1d.is_some()
    }

    /// Graph + GCN on this robot's frame, and the baselines' own tracking.
    pub fn perceive(&mut self, frame: &DetectionFrame, pose: &RobotPose, camera: &Camera) -> Result<Perception> {
        let t = frame.tick;
        let keypoints = frame.human.as_ref().map(|h| normalise_keypoints(&h.keypoints, frame.image_size));
        let mut p = Perception { visibility: frame.visibility(), embedding: None, gcn_class: None, keypoints };
        if let Some(g) = self.graph.build(frame) {
            let out = self.ego.gcn(g)?;
            p.gcn_class = Some(vote::argmax(&out.logits) as u8);
            p.embedding = Some(out.embedding);
            if self.cnn1d.is_some() {
                let mut row = g.x[..NODE_FEATURE_DIM].to_vec(); // node 0: the worker
                row.extend_from_slice(p.keypoints.as_deref().unwrap_or(&[]));
                row.resize(CNN1D_DIM, 0.0);
                self.cnn_rows.insert(t, row);
            }
        }
        self.cnn_rows = self.cnn_rows.split_off(&t.saturating_sub(self.window as u64 - 1));
        if let Some(h) = &frame.human {
            if let Some(z) = back_project(camera, pose, (h.keypoints[0], h.keypoints[1]), HEAD_HEIGHT) {
                self.cvm.observe(t, z);
            }
        }
        Ok(p)
    }

    /// Window rows in, then (if the worker is seen) every model's prediction. `peers_mean`
    /// is the mean of the peer embeddings this robot received for the tick.
    pub fn predict(
        &mut self,
        t: u64,
        p: Perception,
        peers_mean: Option<Vec<f32>>,
        station_spots: &[[f32; 2]],
    ) -> Result<Predictions> {
        let seen = p.embedding.is_some();
        self.window_rows.insert(t, Row { own: p.embedding, peers_mean, keypoints: p.keypoints });
        let mut out = Predictions { gnn: p.gcn_class, ..Default::default() };
        if !seen {
            return Ok(out);
        }
        self.window_rows.input(t, TemporalModel::Ego, &mut self.scratch);
        out.ego = Some(classes(&self.ego.gru(&self.scratch)?));
        self.window_rows.input(t, TemporalModel::Collective, &mut self.scratch);
        let logits = self.collective.gru(&self.scratch)?;
        out.collective = Some(classes(&logits));
        out.vote = Some(vote::vote(&logits, self.temperature));
        if let Some(cnn) = self.cnn1d.as_mut() {
            self.scratch.clear();
            self.scratch.resize(self.frames * CNN1D_DIM, 0.0);
            let oldest = t as i64 - (self.window as i64 - 1);
            for (j, k) in frame_offsets(self.window, self.frames).into_iter().enumerate() {
                let Ok(tick) = u64::try_from(oldest + k as i64) else { continue };
                if let Some(row) = self.cnn_rows.get(&tick) {
                    self.scratch[j * CNN1D_DIM..(j + 1) * CNN1D_DIM].copy_from_slice(row);
                }
            }
            let z = cnn.run(&[Input { shape: &[1, self.frames, CNN1D_DIM], data: &self.scratch }])?;
            let logits: Vec<[f32; NUM_CLASSES]> =
                z[0].chunks_exact(NUM_CLASSES).map(|c| c.try_into().expect("chunk of 4")).collect();
            out.cnn1d = Some(classes(&logits));
        }
        out.cvm = self.cvm.predict(station_spots).map(|k| vec![k as u8; self.horizon + 1]);
        Ok(out)
    }
}
