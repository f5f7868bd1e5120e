//! What the evaluation runs beside each robot's engine, to compare against it: the
//! ego-GRU (the same window rows as the engine's, without the peers' part), the two
//! baselines the paper compares against (the constant-velocity model and the 1D-CNN)
//! and a planning yardstick (goal inference on the team's track, `planner.rs`).
//! They watch the robot's frames, its engine's embedding and its engine's own track
//! and map (the ego model's relations are the robot's own, never the team's); they
//! never feed the engine or the fleet.

use super::cvm::{Cvm, HEAD_HEIGHT};
use super::planner::Planner;
use anyhow::Result;
use spwi_core::floor::{CameraCalibration, FloorView};
use spwi_core::graph::{GraphBuilder, NodeFeatures, NODE_FEATURE_DIM};
use spwi_core::manifest::ModelKind;
use spwi_core::model::{Inference, Input, ModelSet, Runner};
use spwi_core::temporal::{frame_offsets, normalise_keypoints, Row, RowLayout, TemporalModel, Window, CNN1D_DIM};
use spwi_core::vote;
use spwi_proto::{DetectionFrame, Station, NUM_CLASSES};
use std::collections::BTreeMap;
use std::sync::Arc;

/// A robot's predictions for one tick (each `None` when it does not see the worker).
#[derive(Debug, Clone, Default)]
pub struct Predictions {
    /// The engine's GCN alone.
    pub gnn: Option<Station>,
    /// Station for t and each future step.
    pub ego: Option<Vec<Station>>,
    /// The engine's vote (its collective GRU).
    pub collective: Option<Vec<Station>>,
    pub cnn1d: Option<Vec<Station>>,
    /// The constant-velocity model given the true work spots.
    pub cvm: Option<Vec<Station>>,
    /// The same model given only the stations the team mapped (what our models get).
    pub cvm_mapped: Option<Vec<Station>>,
    /// Goal inference that plans paths around the obstacles (`planner.rs`), on the
    /// team's track, handed the true work spots...
    pub planner: Option<Vec<Station>>,
    /// ... and on the stations the team mapped.
    pub planner_mapped: Option<Vec<Station>>,
    /// Where the robot's team map put each station at this tick, as the distance from
    /// the station's true work spot (m); `None`: not on the map.
    pub map_error: [Option<f32>; NUM_CLASSES],
}

impl Predictions {
    /// Whether the robot's team map held station `k` at this tick.
    pub fn mapped(&self, k: Station) -> bool {
        self.map_error[k.index()].is_some()
    }
}

pub struct Observers {
    graph: GraphBuilder,
    ego: Inference,
    ego_rows: Window,
    cnn1d: Option<Box<dyn Runner>>,
    /// The 1D-CNN's rows (worker feature ‖ keypoints) by tick.
    cnn_rows: BTreeMap<u64, Vec<f32>>,
    cvm: Cvm,
    /// The planner on the true work spots, and on the team's map.
    planner: Planner,
    planner_mapped: Planner,
    camera: CameraCalibration,
    row_layout: RowLayout,
    keypoints: Option<Vec<f32>>,
    /// Where this tick's frame shows the worker facing, for rows with facing.
    facing: Option<f32>,
    scratch: Vec<f32>,
    window: usize,
    frames: usize,
    horizon: usize,
}

fn classes(logits: &[[f32; NUM_CLASSES]]) -> Vec<Station> {
    logits.iter().map(vote::top_station).collect()
}

impl Observers {
    /// The observers of one robot; the 1D-CNN only if `cnn1d` and the set ships one;
    /// the planners on `planner`'s floor.
    pub fn new(models: &Arc<ModelSet>, camera: CameraCalibration, cnn1d: bool, planner: Planner) -> Result<Self> {
        let m = &models.manifest;
        Ok(Observers {
            // The 1D-CNN reads the worker node's appearance only: no floor needed.
            graph: GraphBuilder::new(m.max_nodes, m.edge_weight, NodeFeatures::Appearance),
            ego: models.inference(TemporalModel::Ego)?,
            ego_rows: Window::with_frames(m.window, m.frames(), m.row),
            cnn1d: (cnn1d && m.models.cnn1d.is_some()).then(|| models.runner(ModelKind::Cnn1d)).transpose()?,
            cnn_rows: BTreeMap::new(),
            cvm: Cvm::new(spwi_proto::TICK_PERIOD.as_secs_f32()),
            planner_mapped: planner.clone(),
            planner,
            camera,
            row_layout: m.row,
            keypoints: None,
            facing: None,
            scratch: Vec::new(),
            window: m.window,
            frames: m.frames(),
            horizon: m.horizon,
        })
    }

    /// The robot's frame of this tick (as its engine got it): the 1D-CNN's row and the
    /// constant-velocity model's track.
    pub fn see(&mut self, frame: &DetectionFrame) {
        let t = frame.tick();
        self.keypoints = frame.worker().map(|h| normalise_keypoints(&h.keypoints, frame.image_size));
        self.facing = (self.row_layout == RowLayout::RelationsFacing).then(|| self.camera.facing_in(frame)).flatten();
        if self.cnn1d.is_some() {
            if let Some(g) = self.graph.build(frame, None) {
                let mut row = g.x[..NODE_FEATURE_DIM].to_vec(); // node 0: the worker
                row.extend_from_slice(self.keypoints.as_deref().unwrap_or(&[]));
                row.resize(CNN1D_DIM, 0.0);
                self.cnn_rows.insert(t, row);
            }
            self.cnn_rows = self.cnn_rows.split_off(&t.saturating_sub(self.window as u64 - 1));
        }
        if let (Some(h), Some(pose)) = (frame.worker(), &frame.pose) {
            if let Some((z, _)) = self.camera.back_project(pose, (h.keypoints[0], h.keypoints[1]), HEAD_HEIGHT) {
                self.cvm.observe(t, z);
            }
        }
    }

    /// With the embedding the robot's engine computed for tick `t` (`None`: the worker
    /// was not seen) and its engine's floor view, every observer's prediction.
    pub fn predict(
        &mut self,
        t: u64,
        embedding: Option<Vec<f32>>,
        floor_view: &FloorView,
        station_spots: &[[f32; 2]],
    ) -> Result<Predictions> {
        let seen = embedding.is_some();
        let (worker, stations) = (floor_view.own_estimate(t), floor_view.own_map.stations());
        let (relations, facing) = self.row_layout.blocks(worker.as_ref(), self.facing.take(), &stations);
        let row = Row { own: embedding, keypoints: self.keypoints.take(), relations, facing, ..Row::default() };
        self.ego_rows.insert(t, row);
        let team: Vec<(Station, [f32; 2])> =
            Station::ALL.into_iter().filter_map(|k| floor_view.team_map.station(k).map(|at| (k, at))).collect();
        // The planners follow the team's track on every tick it has one.
        let (mut planned, mut planned_mapped) = (None, None);
        if let Some(w) = floor_view.team_track(t) {
            let (t_s, speed) = (t as f32 * spwi_proto::TICK_PERIOD.as_secs_f32(), w.velocity[0].hypot(w.velocity[1]));
            let truth: Vec<(Station, [f32; 2])> = Station::ALL.into_iter().zip(station_spots.iter().copied()).collect();
            planned = self.planner.observe(t_s, w.position, speed, &truth);
            planned_mapped = self.planner_mapped.observe(t_s, w.position, speed, &team);
        }
        let mut out = Predictions::default();
        if !seen {
            return Ok(out);
        }
        out.planner = planned.map(|k| vec![k; self.horizon + 1]);
        out.planner_mapped = planned_mapped.map(|k| vec![k; self.horizon + 1]);
        self.ego_rows.input(t, TemporalModel::Ego, &mut self.scratch);
        out.ego = Some(classes(&self.ego.gru(&self.scratch, &[])?));
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
        out.cvm = self.cvm.predict(station_spots).map(|k| vec![Station::ALL[k]; self.horizon + 1]);
        let spots: Vec<[f32; 2]> = team.iter().map(|&(_, at)| at).collect();
        out.cvm_mapped = self.cvm.predict(&spots).map(|i| vec![team[i].0; self.horizon + 1]);
        for &(k, at) in &team {
            let spot = station_spots[k.index()];
            out.map_error[k.index()] = Some(spwi_world::geometry::dist(at, spot));
        }
        Ok(out)
    }
}
