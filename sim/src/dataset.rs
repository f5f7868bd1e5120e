//! `spwi-sim dataset`: training data that NumPy and PyTorch read directly.
//!
//! Two parts, so that no export needs more than a few GB:
//!
//! - `spatial/`: graph inputs (node features, normalised adjacency, node mask) for a
//!   sample of frames — every `spatial_every`-th tick of each robot that sees the
//!   worker — built by the agent's own [`GraphBuilder`], labelled with the current
//!   intent. Enough to train the GCN; a 1024-d feature on every node of every frame
//!   would run to tens of GB.
//! - `temporal/`: one row per (episode, tick, robot), ordered so the arrays reshape to
//!   `[episodes, ticks, robots, …]`: keypoints, visibility, whether the worker is seen,
//!   the truth now and for the next 30 ticks, the worker's phase; and, given a trained
//!   GCN (`--gcn MODEL_SET_OR_ONNX`), its embedding and logits computed by the agent's
//!   own inference code — so training and serving cannot drift apart; and the worker's
//!   relations to the mapped stations as the agent's [`FloorView`] computes them, from
//!   the robot's own track and map (`relations_ego`) and from the team's fused track
//!   and shared map, every robot of the episode being a peer (`relations_team`); and
//!   for a set that fuses its peers with a learned set model, the same with the peers
//!   a robot hears drawn at random (`relations_heard`: each robot hears a random 0 to
//!   all of the others through an episode, each of their messages of a tick lost with
//!   probability [`HEARD_LOSS`]) beside one relation block per heard peer
//!   (`relations_peers`, [`PEER_SLOTS`] slots) — what its engine holds when its fleet
//!   is that small or its links that lossy; and where the worker's body faces, from
//!   the robot's own keypoints against the stations of its own map and track
//!   (`facing_ego`), and fused over the team's robots against the team's map and
//!   track (`facing_team`) ([`floor::facing`], [`floor::fuse_facings`]). With
//!   `--human-features`, also the worker node's 1024-d feature (the 1D-CNN baseline's
//!   input; 4 KB a row, so only when asked).
//!
//! Each episode runs on its floor under the conditions [`TrainingMix`] draws for it
//! (cameras that track the worker, maps warm from earlier work; by default the floor as
//! it is and empty maps), listed per episode in `dataset.json`.
//!
//! Episodes are split 60/20/20 (train/validation/test) by episode index, as in the paper.
//! `dataset.json` describes every array.

use crate::episodes::episode_seed;
use crate::npy::NpyWriter;
use crate::team_floor::{warm_up_seed, TeamFloor};
use crate::training_mix::TrainingMix;
use crate::world_args::{check_robots, WorldArgs};
use anyhow::{Context, Result};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde_json::json;
use spwi_core::floor::{self, FACING_DIM, RELATION_DIM};
use spwi_core::graph::{GraphBuilder, NodeFeatures, OnFloor, NODE_FEATURE_DIM};
use spwi_core::model::{Backend, Gcn};
use spwi_core::temporal::normalise_keypoints;
use spwi_proto::{DetectionFrame, RobotId, WorkerPhase, EMBEDDING_DIM, KEYPOINT_VALUES, NUM_CLASSES, TICKS_PER_SECOND};
use spwi_world::generate::NamedLayout;
use spwi_world::world::{Scenario, World};
use std::path::{Path, PathBuf};

/// Future ticks of truth stored with every row.
pub const FUTURE: usize = 30;
/// Peer blocks per row of `relations_peers`: up to 8 robots' worth of peers.
pub const PEER_SLOTS: usize = 7;
/// Share of a heard peer's messages lost on each tick in `relations_heard`.
pub const HEARD_LOSS: f64 = 0.1;

pub struct DatasetOptions {
    pub scenario: Scenario,
    /// Workers on the floor: the first is labelled, the others walk and hide it.
    pub workers: usize,
    pub episodes: u32,
    pub robots: usize,
    pub ticks: u32,
    pub seed: u64,
    pub out: PathBuf,
    pub spatial_every: u32,
    /// Episode e runs on floor e mod floors.len().
    pub floors: Vec<NamedLayout>,
    /// How the floors were named (`train:0..300`, a file): recorded in dataset.json.
    pub layouts: String,
    /// Graph size and edge weights; from the GCN's manifest when given.
    pub max_nodes: usize,
    pub edge_weight: spwi_core::graph::EdgeWeight,
    /// What the graph's distances and node features are made of.
    pub node_features: NodeFeatures,
    /// The GCN file whose embeddings fill the temporal part, if any.
    pub gcn: Option<PathBuf>,
    /// Also write the worker node's feature per row (temporal/human_feature.npy).
    pub human_features: bool,
    /// The cameras and warm-ups the episodes run under.
    pub mix: TrainingMix,
}

/// 0 train, 1 validation, 2 test: 60/20/20 by episode index.
pub fn split(episode: u32, episodes: u32) -> u8 {
    let at = episode as u64 * 10;
    if at < episodes as u64 * 6 {
        0
    } else if at < episodes as u64 * 8 {
        1
    } else {
        2
    }
}

fn phase_id(p: WorkerPhase) -> u8 {
    match p {
        WorkerPhase::Moving => 0,
        WorkerPhase::Transition => 1,
        WorkerPhase::Stationary => 2,
    }
}

/// Who hears whom through an episode: `hears[listener][speaker]`. Each robot hears a
/// number of the others drawn uniformly from none to all, then which ones at random.
fn random_hearing(rng: &mut ChaCha8Rng, robots: usize) -> Vec<Vec<bool>> {
    (0..robots)
        .map(|listener| {
            let mut others: Vec<usize> = (0..robots).filter(|&r| r != listener).collect();
            let k = rng.gen_range(0..=others.len());
            for i in 0..k {
                let j = rng.gen_range(i..others.len());
                others.swap(i, j);
            }
            let mut row = vec![false; robots];
            for &r in &others[..k] {
                row[r] = true;
            }
            row
        })
        .collect()
}

struct Spatial {
    x: NpyWriter<f32>,
    adj: NpyWriter<f32>,
    mask: NpyWriter<u8>,
    label: NpyWriter<u8>,
    episode: NpyWriter<u32>,
    split: NpyWriter<u8>,
    robot: NpyWriter<u8>,
    tick: NpyWriter<u32>,
}

struct Temporal {
    keypoints: NpyWriter<f32>,
    seen: NpyWriter<u8>,
    visibility: NpyWriter<u32>,
    truth: NpyWriter<u8>,
    phase: NpyWriter<u8>,
    episode: NpyWriter<u32>,
    split: NpyWriter<u8>,
    robot: NpyWriter<u8>,
    tick: NpyWriter<u32>,
    relations_ego: NpyWriter<f32>,
    relations_team: NpyWriter<f32>,
    relations_heard: NpyWriter<f32>,
    relations_peers: NpyWriter<f32>,
    facing_ego: NpyWriter<f32>,
    facing_team: NpyWriter<f32>,
    embedding: Option<NpyWriter<f32>>,
    gcn_logits: Option<NpyWriter<f32>>,
    human_feature: Option<NpyWriter<f32>>,
}

/// One robot's row of one tick, held until the future truth is known.
struct Pending {
    keypoints: Vec<f32>,
    seen: bool,
    visibility: u32,
    embedding: Vec<f32>,
    logits: [f32; NUM_CLASSES],
    human_feature: Vec<f32>,
    relations_ego: Vec<f32>,
    relations_team: Vec<f32>,
    relations_heard: Vec<f32>,
    relations_peers: Vec<f32>,
    facing_ego: Vec<f32>,
    facing_team: Vec<f32>,
}

/// Writes the dataset; returns (spatial samples, temporal rows).
pub fn export(o: &DatasetOptions) -> Result<(u64, u64)> {
    let (sd, td) = (o.out.join("spatial"), o.out.join("temporal"));
    std::fs::create_dir_all(&sd)
        .and_then(|_| std::fs::create_dir_all(&td))
        .with_context(|| format!("cannot create {}", o.out.display()))?;
    let n = o.max_nodes;
    let f = |d: &Path, name: &str| d.join(format!("{name}.npy"));
    let mut sp = Spatial {
        x: NpyWriter::create(&f(&sd, "x"), &[n, o.node_features.dim()])?,
        adj: NpyWriter::create(&f(&sd, "adj"), &[n, n])?,
        mask: NpyWriter::create(&f(&sd, "node_mask"), &[n])?,
        label: NpyWriter::create(&f(&sd, "label"), &[])?,
        episode: NpyWriter::create(&f(&sd, "episode"), &[])?,
        split: NpyWriter::create(&f(&sd, "split"), &[])?,
        robot: NpyWriter::create(&f(&sd, "robot"), &[])?,
        tick: NpyWriter::create(&f(&sd, "tick"), &[])?,
    };
    let mut tp = Temporal {
        keypoints: NpyWriter::create(&f(&td, "keypoints"), &[KEYPOINT_VALUES])?,
        seen: NpyWriter::create(&f(&td, "seen"), &[])?,
        visibility: NpyWriter::create(&f(&td, "visibility"), &[])?,
        truth: NpyWriter::create(&f(&td, "truth"), &[FUTURE + 1])?,
        phase: NpyWriter::create(&f(&td, "phase"), &[])?,
        episode: NpyWriter::create(&f(&td, "episode"), &[])?,
        split: NpyWriter::create(&f(&td, "split"), &[])?,
        robot: NpyWriter::create(&f(&td, "robot"), &[])?,
        tick: NpyWriter::create(&f(&td, "tick"), &[])?,
        relations_ego: NpyWriter::create(&f(&td, "relations_ego"), &[RELATION_DIM])?,
        relations_team: NpyWriter::create(&f(&td, "relations_team"), &[RELATION_DIM])?,
        relations_heard: NpyWriter::create(&f(&td, "relations_heard"), &[RELATION_DIM])?,
        relations_peers: NpyWriter::create(&f(&td, "relations_peers"), &[PEER_SLOTS, RELATION_DIM])?,
        facing_ego: NpyWriter::create(&f(&td, "facing_ego"), &[FACING_DIM])?,
        facing_team: NpyWriter::create(&f(&td, "facing_team"), &[FACING_DIM])?,
        embedding: o.gcn.as_ref().map(|_| NpyWriter::create(&f(&td, "embedding"), &[EMBEDDING_DIM])).transpose()?,
        gcn_logits: o.gcn.as_ref().map(|_| NpyWriter::create(&f(&td, "gcn_logits"), &[NUM_CLASSES])).transpose()?,
        human_feature: o
            .human_features
            .then(|| NpyWriter::create(&f(&td, "human_feature"), &[NODE_FEATURE_DIM]))
            .transpose()?,
    };
    let mut gcn = o.gcn.as_ref().map(|file| Gcn::load(file, n, o.node_features, Backend::Tract, None)).transpose()?;
    let mut graph = GraphBuilder::new(n, o.edge_weight, o.node_features);
    let ids: Vec<RobotId> = (0..o.robots).map(|i| RobotId::new(format!("r{i}"))).collect::<Result<_, _>>()?;
    let progress = crate::progress::Progress::new("episodes exported", o.episodes as u64, 5);
    let mut episode_conditions = Vec::with_capacity(o.episodes as usize);
    for e in 0..o.episodes {
        let seed = episode_seed(o.seed, e);
        let mut floor = o.floors[e as usize % o.floors.len()].layout.clone();
        let conditions = o.mix.draw(seed, floor.camera.policy);
        floor.camera.policy = conditions.camera;
        episode_conditions.push(conditions);
        let mut world = World::with_workers(floor.clone(), o.scenario, seed, o.robots, o.workers);
        let camera = crate::calibration::of(&floor.camera);
        let mut team_floor = match conditions.warm_up_ticks {
            0 => TeamFloor::new(camera.clone(), o.robots),
            ticks => TeamFloor::warmed(&floor, o.scenario, warm_up_seed(seed), o.robots, ticks)?,
        };
        // The same fleet as each robot holds it when it hears only some peers, some
        // of their messages lost: who hears whom is drawn once per episode.
        let mut heard_floor = team_floor.clone();
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x4845_4152_445f_5045); // "HEARD_PE"
        let hears = random_hearing(&mut rng, o.robots);
        let total = o.ticks as usize + FUTURE;
        let mut intents = Vec::with_capacity(total);
        let mut phases = Vec::with_capacity(total);
        let mut rows: Vec<Vec<Pending>> = Vec::with_capacity(o.ticks as usize);
        for t in 0..total as u32 {
            world.step();
            intents.push(u8::from(world.worker().goal));
            phases.push(phase_id(world.worker().phase));
            if t >= o.ticks {
                continue; // only the truth of these ticks is needed
            }
            let mut frames: Vec<DetectionFrame> =
                ids.iter().enumerate().map(|(slot, id)| world.observe(slot, id)).collect();
            // Of several people in view, each robot's row is of the one it follows.
            team_floor.follow(&mut frames);
            // What each robot's engine computes from its frame and, at its vote step,
            // every other robot of the episode being a peer whose estimate and
            // landmarks arrived.
            let all = team_floor.observe(&frames);
            let mut tick_rows = Vec::with_capacity(o.robots);
            for (slot, frame) in frames.iter().enumerate() {
                let keypoints = frame
                    .worker()
                    .map(|h| normalise_keypoints(&h.keypoints, frame.image_size))
                    .unwrap_or_else(|| vec![0.0; KEYPOINT_VALUES]);
                let mut row = Pending {
                    keypoints,
                    seen: frame.worker().is_some(),
                    visibility: frame.visibility(),
                    embedding: vec![0.0; EMBEDDING_DIM],
                    logits: [0.0; NUM_CLASSES],
                    human_feature: Vec::new(),
                    relations_ego: vec![0.0; RELATION_DIM],
                    relations_team: vec![0.0; RELATION_DIM],
                    relations_heard: vec![0.0; RELATION_DIM],
                    relations_peers: vec![0.0; PEER_SLOTS * RELATION_DIM],
                    facing_ego: vec![0.0; FACING_DIM],
                    facing_team: vec![0.0; FACING_DIM],
                };
                let on_floor = all[slot].own.as_ref().map(|worker| OnFloor { camera: &camera, worker });
                if let Some(g) = graph.build(frame, on_floor) {
                    if t % o.spatial_every == 0 {
                        sp.x.push(&g.x)?;
                        sp.adj.push(&g.adj)?;
                        let mask: Vec<u8> = (0..n).map(|i| u8::from(i < g.nodes)).collect();
                        sp.mask.push(&mask)?;
                        sp.label.push(&[world.worker().goal.into()])?;
                        sp.episode.push(&[e])?;
                        sp.split.push(&[split(e, o.episodes)])?;
                        sp.robot.push(&[slot as u8])?;
                        sp.tick.push(&[t])?;
                    }
                    if let Some(gcn) = gcn.as_mut() {
                        let out = gcn.run(g)?;
                        row.embedding = out.embedding;
                        row.logits = out.logits;
                    }
                    if o.human_features {
                        row.human_feature = g.x[..NODE_FEATURE_DIM].to_vec(); // node 0 is the worker
                    }
                }
                tick_rows.push(row);
            }
            for (slot, (row, h)) in tick_rows.iter_mut().zip(&all).enumerate() {
                let v = team_floor.view(slot);
                let (own_stations, team_stations) = (v.own_map.stations(), v.team_map.stations());
                floor::relations(h.own.as_ref(), &own_stations, &mut row.relations_ego);
                floor::relations(h.team.as_ref(), &team_stations, &mut row.relations_team);
                let facing = camera.facing_in(&frames[slot]);
                floor::facing(h.own.as_ref(), facing, &own_stations, &mut row.facing_ego);
                floor::facing(h.team.as_ref(), h.facing, &team_stations, &mut row.facing_team);
            }
            let delivered: Vec<Vec<bool>> =
                hears.iter().map(|row| row.iter().map(|&h| h && !rng.gen_bool(HEARD_LOSS)).collect()).collect();
            let heard = heard_floor.observe_heard(&frames, |listener, speaker| delivered[listener][speaker]);
            for (slot, (row, h)) in tick_rows.iter_mut().zip(&heard).enumerate() {
                let stations = heard_floor.view(slot).team_map.stations();
                floor::relations(h.team.as_ref(), &stations, &mut row.relations_heard);
                let peers: Vec<_> = h.peers.iter().collect();
                floor::peer_set(&peers, &stations, PEER_SLOTS, &mut row.relations_peers);
            }
            rows.push(tick_rows);
        }
        for (t, tick_rows) in rows.into_iter().enumerate() {
            let truth = &intents[t..=t + FUTURE];
            for (slot, r) in tick_rows.into_iter().enumerate() {
                tp.keypoints.push(&r.keypoints)?;
                tp.seen.push(&[u8::from(r.seen)])?;
                tp.visibility.push(&[r.visibility])?;
                tp.truth.push(truth)?;
                tp.phase.push(&[phases[t]])?;
                tp.episode.push(&[e])?;
                tp.split.push(&[split(e, o.episodes)])?;
                tp.robot.push(&[slot as u8])?;
                tp.tick.push(&[t as u32])?;
                tp.relations_ego.push(&r.relations_ego)?;
                tp.relations_team.push(&r.relations_team)?;
                tp.relations_heard.push(&r.relations_heard)?;
                tp.relations_peers.push(&r.relations_peers)?;
                tp.facing_ego.push(&r.facing_ego)?;
                tp.facing_team.push(&r.facing_team)?;
                if let (Some(em), Some(lg)) = (tp.embedding.as_mut(), tp.gcn_logits.as_mut()) {
                    em.push(&r.embedding)?;
                    lg.push(&r.logits)?;
                }
                if let Some(hf) = tp.human_feature.as_mut() {
                    if r.human_feature.is_empty() {
                        hf.push(&[0.0; NODE_FEATURE_DIM])?;
                    } else {
                        hf.push(&r.human_feature)?;
                    }
                }
            }
        }
        progress.inc();
    }
    let samples = sp.label.rows();
    let rows = tp.tick.rows();
    for w in [sp.x, sp.adj] {
        w.finish()?;
    }
    for w in [sp.mask, sp.label, sp.split, sp.robot] {
        w.finish()?;
    }
    sp.episode.finish()?;
    sp.tick.finish()?;
    for w in [
        tp.keypoints,
        tp.relations_ego,
        tp.relations_team,
        tp.relations_heard,
        tp.relations_peers,
        tp.facing_ego,
        tp.facing_team,
    ] {
        w.finish()?;
    }
    for w in [tp.seen, tp.truth, tp.phase, tp.split, tp.robot] {
        w.finish()?;
    }
    for w in [tp.visibility, tp.episode, tp.tick] {
        w.finish()?;
    }
    for w in [tp.embedding, tp.gcn_logits, tp.human_feature].into_iter().flatten() {
        w.finish()?;
    }
    let conditions = json!({
        "track_share": o.mix.track_share,
        "warm_share": o.mix.warm_share,
        "warm_up_max_s": f64::from(o.mix.warm_up_max_ticks) / f64::from(TICKS_PER_SECOND),
        "drawn": "per episode from its seed (sim/src/training_mix.rs): cameras track the worker with probability track_share, else the floor's own policy; with probability warm_share the fleet first works (0, warm_up_max_s] s on the floor, another worker, and the episode starts from the station maps it built",
        "camera_of_episode": episode_conditions.iter().map(|c| c.camera).collect::<Vec<_>>(),
        "warm_up_s_of_episode": episode_conditions.iter().map(|c| f64::from(c.warm_up_ticks) / f64::from(TICKS_PER_SECOND)).collect::<Vec<_>>(),
    });
    let mut description = json!({
        "scenario": o.scenario as u8,
        "episodes": o.episodes,
        "robots": o.robots,
        "ticks_per_episode": o.ticks,
        "seed": o.seed,
        "episode_seed": "seed * 1000003 + episode",
        "layouts": o.layouts,
        "floors": o.floors.len(),
        "floor_of_episode": "the (episode mod floors)-th floor the layouts name",
        "split": "by episode index: first 60% train (0), next 20% validation (1), last 20% test (2)",
        "classes": spwi_proto::Station::ALL.map(spwi_proto::Station::name),
        "max_nodes": n,
        "edge_weight": o.edge_weight,
        "node_features": o.node_features,
        "spatial": {
            "samples": samples,
            "sampling": format!("every {}th tick of each robot, when it sees the worker", o.spatial_every),
            "arrays": {
                "x": ["float32", ["samples", n, o.node_features.dim()], "node features: global scene feature ‖ local feature (‖ floor relations with node_features floor_relations: core/src/graph.rs); node 0 is the worker; padding rows are zero"],
                "adj": ["float32", ["samples", n, n], "normalised adjacency D^-1/2 (A + I) D^-1/2 of the star graph, zero padding"],
                "node_mask": ["uint8", ["samples", n], "1 for real nodes"],
                "label": ["uint8", ["samples"], "station the worker is heading to now"],
                "episode": ["uint32", ["samples"], "episode index"],
                "split": ["uint8", ["samples"], "0 train, 1 validation, 2 test"],
                "robot": ["uint8", ["samples"], "robot slot"],
                "tick": ["uint32", ["samples"], "tick within the episode"],
            }
        },
        "temporal": {
            "rows": rows,
            "order": "episode-major, then tick, then robot: reshape to [episodes, ticks, robots, ...]",
            "arrays": {
                "keypoints": ["float32", ["rows", KEYPOINT_VALUES], "17 COCO keypoints (x, y) / image size; zeros when the worker is not seen"],
                "seen": ["uint8", ["rows"], "1 when the robot detects the worker"],
                "visibility": ["uint32", ["rows"], "detections in the frame (worker + objects): N_detected"],
                "truth": ["uint8", ["rows", FUTURE + 1], "intent at t, t+1, ..., t+30"],
                "phase": ["uint8", ["rows"], "0 moving, 1 transition (goal changed within 2 s), 2 stationary"],
                "episode": ["uint32", ["rows"], "episode index"],
                "split": ["uint8", ["rows"], "0 train, 1 validation, 2 test"],
                "robot": ["uint8", ["rows"], "robot slot"],
                "tick": ["uint32", ["rows"], "tick within the episode"],
                "relations_ego": ["float32", ["rows", RELATION_DIM], "the worker's relations to the mapped stations from the robot's own track and map (core/src/floor/relations.rs)"],
                "relations_team": ["float32", ["rows", RELATION_DIM], "the same from the team's fused track and shared map, every robot of the episode a peer"],
                "relations_heard": ["float32", ["rows", RELATION_DIM], format!("the same when the robot hears a random subset of the others (drawn per episode and robot: how many uniform in 0..robots-1, then which), each of their messages lost with probability {HEARD_LOSS}")],
                "relations_peers": ["float32", ["rows", PEER_SLOTS, RELATION_DIM], "one relation block per peer heard in relations_heard: that peer's own estimate against the robot's team map; empty slots zero (floor::peer_set)"],
                "facing_ego": ["float32", ["rows", FACING_DIM], "where the worker's body faces (from the robot's own keypoints) against the stations of its own map, from its own track (core/src/floor/relations.rs, facing)"],
                "facing_team": ["float32", ["rows", FACING_DIM], "the team's facing (circular mean of its robots', core/src/floor/relations.rs, fuse_facings) against the team's fused track and shared map"],
                "embedding": ["float32", ["rows", EMBEDDING_DIM], "GCN embedding of the worker node (only with --gcn; zeros when not seen)"],
                "gcn_logits": ["float32", ["rows", NUM_CLASSES], "GCN logits (only with --gcn; zeros when not seen)"],
                "human_feature": ["float32", ["rows", NODE_FEATURE_DIM], "the worker node's feature, global ‖ local (only with --human-features; zeros when not seen)"],
            }
        }
    });
    // (set apart: one json! of it all exceeds the macro's recursion limit)
    description["conditions"] = conditions;
    description["gcn"] = json!(o.gcn.as_ref().map(|file| json!({"file": file})));
    // Describe only the arrays this export wrote.
    let optional =
        [("embedding", o.gcn.is_some()), ("gcn_logits", o.gcn.is_some()), ("human_feature", o.human_features)];
    if let Some(arrays) = description["temporal"]["arrays"].as_object_mut() {
        for (name, written) in optional {
            if !written {
                arrays.remove(name);
            }
        }
    }
    std::fs::write(o.out.join("dataset.json"), serde_json::to_string_pretty(&description)?)?;
    Ok((samples, rows))
}

/// The arguments of `spwi-sim dataset`.
#[derive(clap::Args, Debug)]
pub struct DatasetArgs {
    #[command(flatten)]
    pub world: WorldArgs,
    #[arg(long, default_value_t = 100)]
    pub episodes: u32,
    #[arg(long, default_value_t = 4)]
    pub robots: usize,
    /// Ticks per episode (10 per second).
    #[arg(long, default_value_t = 300)]
    pub ticks: u32,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    #[arg(long)]
    pub out: PathBuf,
    /// Keep the graph of every Nth tick per robot for the spatial part.
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u32).range(1..))]
    pub spatial_every: u32,
    /// The GCN that computes the temporal part's embeddings (via the agent's code):
    /// a model set folder, or a lone gcn .onnx file.
    #[arg(long, value_name = "MODEL_SET_OR_ONNX")]
    pub gcn: Option<PathBuf>,
    /// Graph size, unless --gcn names a model set (then: its manifest's).
    #[arg(long, default_value_t = 16)]
    pub max_nodes: usize,
    /// Edge weights, unless --gcn names a model set (then: its manifest's).
    #[arg(long, default_value = "proximity", value_parser = parse_edge_weight)]
    pub edge_weight: spwi_core::graph::EdgeWeight,
    /// What the graph is made of, unless --gcn names a model set (then: its
    /// manifest's): "appearance" (image distances, the paper's) or "floor_relations"
    /// (floor distances, each node's relations to the worker).
    #[arg(long, default_value = "appearance", value_parser = parse_node_features)]
    pub node_features: NodeFeatures,
    /// Also write the worker node's 1024-d feature per row (the 1D-CNN baseline's input).
    #[arg(long)]
    pub human_features: bool,
    /// Share of the episodes (drawn per episode) whose cameras track the worker; the
    /// others keep the floor's policy (or --camera's).
    #[arg(long, default_value_t = 0.0)]
    pub track_share: f64,
    /// Share of the episodes (drawn per episode) that start from the station maps of a
    /// fleet that first worked on the floor for up to --warm-up-max seconds.
    #[arg(long, default_value_t = 0.0)]
    pub warm_share: f64,
    /// The longest warm-up, seconds: each warm episode's is drawn uniformly up to it.
    #[arg(long, default_value_t = 0)]
    pub warm_up_max: u32,
}

/// `spwi-sim dataset`: parses nothing more, runs the tool.
pub fn main(a: DatasetArgs) -> Result<()> {
    let DatasetArgs {
        world,
        episodes,
        robots,
        ticks,
        seed,
        out,
        spatial_every,
        gcn,
        max_nodes,
        edge_weight,
        node_features,
        human_features,
        track_share,
        warm_share,
        warm_up_max,
    } = a;
    let mix = TrainingMix::new(track_share, warm_share, warm_up_max.saturating_mul(10))?;
    let floors = world.floors()?;
    check_robots(robots, &floors)?;
    if episodes == 0 || ticks == 0 {
        anyhow::bail!("--episodes and --ticks must be at least 1");
    }
    let (gcn, max_nodes, edge_weight, node_features) = match gcn {
        Some(dir) if dir.is_dir() => {
            let m = spwi_core::manifest::Manifest::load(&dir)?;
            (Some(dir.join(&m.models.gcn.file)), m.max_nodes, m.edge_weight, m.node_features)
        }
        file => (file, max_nodes, edge_weight, node_features),
    };
    if !(1..=256).contains(&max_nodes) {
        anyhow::bail!("--max-nodes {max_nodes}: must be within 1..=256");
    }
    let started = std::time::Instant::now();
    let (samples, rows) = crate::dataset::export(&crate::dataset::DatasetOptions {
        scenario: world.scenario,
        workers: usize::from(world.workers),
        episodes,
        robots,
        ticks,
        seed,
        out: out.clone(),
        spatial_every,
        floors,
        layouts: world.describe(),
        max_nodes,
        edge_weight,
        node_features,
        gcn,
        human_features,
        mix,
    })?;
    println!(
        "wrote {} ({samples} graph samples, {rows} temporal rows) in {:.1} s",
        out.display(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

/// One of a manifest's named choices, as the manifest spells it.
fn parse_choice<T: serde::de::DeserializeOwned>(s: &str, what: &str, choices: &str) -> Result<T, String> {
    serde_json::from_value(serde_json::Value::String(s.to_owned()))
        .map_err(|_| format!("unknown {what} {s:?}; use {choices}"))
}

fn parse_edge_weight(s: &str) -> Result<spwi_core::graph::EdgeWeight, String> {
    parse_choice(s, "edge weight", "\"proximity\" or \"distance\"")
}

fn parse_node_features(s: &str) -> Result<NodeFeatures, String> {
    parse_choice(s, "node features", "\"appearance\" or \"floor_relations\"")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn export_to(dir: &Path, gcn: Option<PathBuf>) -> (u64, u64) {
        export_mixed(dir, gcn, TrainingMix::NONE)
    }

    fn export_mixed(dir: &Path, gcn: Option<PathBuf>, mix: TrainingMix) -> (u64, u64) {
        export_with(dir, gcn, mix, NodeFeatures::Appearance)
    }

    fn export_with(dir: &Path, gcn: Option<PathBuf>, mix: TrainingMix, node_features: NodeFeatures) -> (u64, u64) {
        let _ = std::fs::remove_dir_all(dir);
        export(&DatasetOptions {
            scenario: Scenario::Dynamic,
            workers: 1,
            episodes: 5,
            robots: 2,
            ticks: 40,
            seed: 3,
            out: dir.to_owned(),
            spatial_every: 2,
            floors: vec![NamedLayout { name: "test".into(), layout: spwi_world::layout::Layout::default_layout() }],
            layouts: "test".into(),
            max_nodes: 16,
            edge_weight: spwi_core::graph::EdgeWeight::Proximity,
            node_features,
            gcn,
            human_features: true,
            mix,
        })
        .unwrap()
    }

    /// The bytes after the header of a .npy file of the export in `dir` (the header's
    /// length is at offset 8).
    fn npy_data(dir: &Path, file: &str) -> Vec<u8> {
        let b = std::fs::read(dir.join(file)).unwrap();
        b[10 + u16::from_le_bytes([b[8], b[9]]) as usize..].to_vec()
    }

    #[test]
    fn mixed_episodes_run_under_the_drawn_cameras_and_start_from_warm_maps() {
        let base = std::env::temp_dir().join(format!("spwi-dataset-mix-{}", std::process::id()));
        let (cold, tracked, warm) = (base.join("cold"), base.join("tracked"), base.join("warm"));
        export_to(&cold, None);
        export_mixed(&tracked, None, TrainingMix::new(1.0, 0.0, 0).unwrap());
        export_mixed(&warm, None, TrainingMix::new(0.0, 1.0, 600).unwrap());
        let conditions = |dir: &Path| {
            let d: serde_json::Value =
                serde_json::from_str(&std::fs::read_to_string(dir.join("dataset.json")).unwrap()).unwrap();
            (d["conditions"]["camera_of_episode"].clone(), d["conditions"]["warm_up_s_of_episode"].clone())
        };
        assert_eq!(conditions(&cold), (json!(vec!["fixed"; 5]), json!(vec![0.0; 5])));
        assert_eq!(conditions(&tracked), (json!(vec!["track"; 5]), json!(vec![0.0; 5])));
        let (cameras, warm_ups) = conditions(&warm);
        assert_eq!(cameras, json!(vec!["fixed"; 5]));
        assert!(warm_ups.as_array().unwrap().iter().all(|s| (0.1..=60.0).contains(&s.as_f64().unwrap())), "{warm_ups}");
        // The cameras: tracking ones keep the worker in view on more rows.
        let seen = |dir: &Path| npy_data(dir, "temporal/seen.npy").iter().filter(|&&b| b == 1).count();
        assert!(
            seen(&tracked) > seen(&cold),
            "rows seeing the worker: tracked {}, fixed {}",
            seen(&tracked),
            seen(&cold)
        );
        // The warm-up: stations on the team map over each episode's first second (ticks
        // 0-9 of 40, 2 robots a tick); a fleet that has worked on the floor knows more.
        let known = |dir: &Path| {
            let bytes = npy_data(dir, "temporal/relations_team.npy");
            let values: Vec<f32> = bytes.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect();
            let rows: Vec<&[f32]> = values.chunks_exact(RELATION_DIM).collect();
            let at = |s: usize| floor::relations::TRACK_VALUES + s * floor::relations::PER_STATION;
            (0..rows.len())
                .filter(|i| i % (40 * 2) < 10 * 2)
                .map(|i| (0..4).filter(|&s| rows[i][at(s)] == 1.0).count())
                .sum::<usize>()
        };
        let (k_cold, k_warm) = (known(&cold), known(&warm));
        assert!(k_warm > k_cold + 10, "stations known in the first second: warm {k_warm}, cold {k_cold}");
        std::fs::remove_dir_all(base).unwrap();
    }

    #[test]
    fn floor_relation_graphs_carry_the_track_on_the_worker_node_and_a_relation_on_objects() {
        let base = std::env::temp_dir().join(format!("spwi-dataset-floor-{}", std::process::id()));
        let (plain, floor) = (base.join("plain"), base.join("floor"));
        // Cameras that follow the worker: objects beside it in most frames.
        let tracking = TrainingMix::new(1.0, 0.0, 0).unwrap();
        let (samples, _) = export_mixed(&plain, None, tracking);
        assert_eq!(export_with(&floor, None, tracking, NodeFeatures::FloorRelations).0, samples);
        let floats = |dir: &Path| -> Vec<f32> {
            npy_data(dir, "spatial/x.npy").chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect()
        };
        let (a, f) = (floats(&plain), floats(&floor));
        let dim = NodeFeatures::FloorRelations.dim();
        assert_eq!((a.len() / NODE_FEATURE_DIM, f.len() / dim), (samples as usize * 16, samples as usize * 16));
        let (mut tracked, mut related) = (0, 0);
        for (node, (plain_row, row)) in a.chunks_exact(NODE_FEATURE_DIM).zip(f.chunks_exact(dim)).enumerate() {
            let relations = &row[NODE_FEATURE_DIM..];
            if node % 16 == 0 {
                // The worker: its appearance as before (objects may come in another
                // order, now by floor distance), the track's values or nothing.
                assert_eq!(&row[..NODE_FEATURE_DIM], plain_row);
                assert!(relations[floor::relations::TRACK_VALUES..].iter().all(|&v| v == 0.0));
                tracked += usize::from(relations[0] == 1.0);
            } else {
                assert!(relations[..floor::relations::TRACK_VALUES].iter().all(|&v| v == 0.0));
                related += usize::from(relations[floor::relations::TRACK_VALUES] == 1.0);
            }
        }
        // Most graphs are of a tracked worker, and objects are placed on the floor.
        assert!(tracked * 2 > samples as usize, "{tracked} of {samples} graphs with a track");
        let objects = f.chunks_exact(dim).enumerate().filter(|(i, r)| i % 16 != 0 && r[0] != 0.0).count();
        assert!(related > 0 && related <= objects, "{related} of {objects} objects placed on the floor");
        std::fs::remove_dir_all(base).unwrap();
    }

    #[test]
    fn the_description_lists_only_the_arrays_written() {
        let dir = std::env::temp_dir().join(format!("spwi-dataset-plain-{}", std::process::id()));
        export_to(&dir, None);
        let d: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("dataset.json")).unwrap()).unwrap();
        // What models/train reads from the description besides the arrays.
        for key in [
            "scenario",
            "episodes",
            "robots",
            "ticks_per_episode",
            "seed",
            "layouts",
            "episode_seed",
            "split",
            "max_nodes",
            "edge_weight",
            "node_features",
        ] {
            assert!(d.get(key).is_some(), "dataset.json lacks {key:?}");
        }
        let arrays = d["temporal"]["arrays"].as_object().unwrap();
        assert!(!arrays.contains_key("embedding") && !arrays.contains_key("gcn_logits"));
        assert!(arrays.contains_key("human_feature") && dir.join("temporal/human_feature.npy").is_file());
        std::fs::remove_dir_all(dir).unwrap();
    }

    #[test]
    fn each_robot_hears_from_none_to_all_of_the_others_never_itself() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let mut counts = [0; 8];
        for _ in 0..400 {
            let hears = random_hearing(&mut rng, 8);
            for (listener, row) in hears.iter().enumerate() {
                assert!(!row[listener]);
                counts[row.iter().filter(|&&h| h).count()] += 1;
            }
        }
        assert!(counts.iter().all(|&c| c > 250), "0 to 7 peers, about equally often: {counts:?}");
    }

    #[test]
    fn splits_are_60_20_20_by_episode() {
        let counts = (0..10).fold([0; 3], |mut c, e| {
            c[split(e, 10) as usize] += 1;
            c
        });
        assert_eq!(counts, [6, 2, 2]);
    }

    #[test]
    fn export_sizes_match_the_description_and_the_same_seed_gives_the_same_bytes() {
        let base = std::env::temp_dir().join(format!("spwi-dataset-{}", std::process::id()));
        let gcn = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/fixture/gcn.onnx");
        let (samples, rows) = export_to(&base.join("a"), Some(gcn.clone()));
        assert_eq!(rows, 5 * 40 * 2);
        assert!(samples > 0 && samples <= 5 * 20 * 2);
        let data = |p: &str| npy_data(&base.join("a"), p).len() as u64;
        assert_eq!(data("spatial/x.npy"), samples * 16 * 1024 * 4);
        assert_eq!(data("spatial/adj.npy"), samples * 16 * 16 * 4);
        assert_eq!(data("spatial/label.npy"), samples);
        assert_eq!(data("temporal/truth.npy"), rows * 31);
        assert_eq!(data("temporal/embedding.npy"), rows * 128 * 4);
        assert_eq!(data("temporal/tick.npy"), rows * 4);
        assert_eq!(data("temporal/human_feature.npy"), rows * 1024 * 4);
        let described: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(base.join("a/dataset.json")).unwrap()).unwrap();
        assert_eq!(described["temporal"]["rows"], rows);
        assert_eq!(described["spatial"]["samples"], samples);

        export_to(&base.join("b"), Some(gcn));
        for f in [
            "spatial/x.npy",
            "spatial/adj.npy",
            "temporal/truth.npy",
            "temporal/embedding.npy",
            "temporal/keypoints.npy",
        ] {
            assert_eq!(
                std::fs::read(base.join("a").join(f)).unwrap(),
                std::fs::read(base.join("b").join(f)).unwrap(),
                "{f} differs"
            );
        }
        std::fs::remove_dir_all(base).unwrap();
    }
}
