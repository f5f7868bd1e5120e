//! Detection frame → star graph (paper II-C). Pure: same frame, same graph.
//!
//! The worker is node 0, one node per detected object after it; node feature =
//! global scene feature ‖ local appearance feature (512 + 512). Edges connect the
//! worker to every object, weighted from their distance ([`EdgeWeight`]). Then A' = A + I
//! and the symmetric normalisation Â = D^-1/2 A' D^-1/2, computed here so the ONNX GCN
//! only multiplies. Graphs are padded to the model's fixed node count with zero rows and
//! columns (no self-loop), so padding never reaches the worker's embedding. When a frame
//! holds more objects than fit, the ones nearest the worker are kept.
//!
//! Which distance, and what else a node carries, is the set's [`NodeFeatures`]:
//! - **appearance** (the paper's): the distance between box centres in the image,
//!   normalised by its diagonal — which means nothing on another floor or to a robot
//!   that sees the scene from elsewhere;
//! - **floor relations**: the distance on the floor between the worker's tracked
//!   position and the object's footprint (back-projected through the robot's camera,
//!   `floor::CameraCalibration::footprint`), over [`FLOOR_RANGE`]; and each node's
//!   feature ends with its relations ([`FLOOR_RELATION_DIM`] values): the worker node
//!   the track's values, each object the worker's relation to it — distance, how fast
//!   it closes, the sideways speed, the bearing relative to the worker's motion
//!   (`floor::relations`, the same quantities the temporal rows give per station).
//!   Without a track, or for an object whose footprint is out of the image, the
//!   relation is zeros and the image distance weighs the edge.
//!
//! The builder owns its buffers: one allocation at start-up, none per tick.

use crate::floor::relations::{relation_to, track_values, PER_STATION, TRACK_VALUES};
use crate::floor::CameraCalibration;
use serde::{Deserialize, Serialize};
use spwi_proto::{DetectionFrame, WorkerEstimate, FEATURE_DIM};

/// Width of a node's appearance feature: global ‖ local.
pub const NODE_FEATURE_DIM: usize = 2 * FEATURE_DIM;
/// Relation values after the appearance feature with [`NodeFeatures::FloorRelations`]:
/// the track's ([`TRACK_VALUES`], worker node only), then one object's relation to
/// the worker ([`PER_STATION`], object nodes only).
pub const FLOOR_RELATION_DIM: usize = TRACK_VALUES + PER_STATION;
/// Floor distance (m) that counts as normalised distance 1 (an edge's weight is then
/// that of the image's diagonal).
pub const FLOOR_RANGE: f32 = 10.0;

/// How an edge weight derives from the normalised distance d ∈ [0, 1].
/// Recorded in the model manifest: a model is only valid with the kind it was trained on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EdgeWeight {
    /// w = d: the paper's literal wording ("weighted by their Euclidean distances").
    Distance,
    /// w = 1 − d: near objects weigh more, which is what the message passing needs
    /// (an object at the worker's feet should dominate a far one).
    Proximity,
}

impl EdgeWeight {
    fn weight(self, normalised_distance: f32) -> f32 {
        let d = normalised_distance.clamp(0.0, 1.0);
        match self {
            EdgeWeight::Distance => d,
            EdgeWeight::Proximity => 1.0 - d,
        }
    }
}

/// What the graph's distances and node features are made of (the manifest's
/// `node_features`; absent: the paper's).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NodeFeatures {
    /// Image distances, appearance features only.
    #[default]
    Appearance,
    /// Floor distances, appearance features followed by the floor relations.
    FloorRelations,
}

impl NodeFeatures {
    /// Width of a node's feature row.
    pub fn dim(self) -> usize {
        match self {
            NodeFeatures::Appearance => NODE_FEATURE_DIM,
            NodeFeatures::FloorRelations => NODE_FEATURE_DIM + FLOOR_RELATION_DIM,
        }
    }
}

/// What places a frame's graph on the floor: the robot's camera and its track of the
/// worker (after this frame). The frame carries the robot's pose.
#[derive(Debug, Clone, Copy)]
pub struct OnFloor<'a> {
    pub camera: &'a CameraCalibration,
    pub worker: &'a WorkerEstimate,
}

/// A padded star graph ready for the GCN: `x` is `[max_nodes, dim]`, `adj` is the
/// normalised `[max_nodes, max_nodes]`, both row-major.
#[derive(Debug, Clone)]
pub struct StarGraph {
    pub max_nodes: usize,
    /// Real nodes (worker + objects kept); the rest is padding.
    pub nodes: usize,
    /// Width of a node's feature row ([`NodeFeatures::dim`]).
    pub dim: usize,
    pub x: Vec<f32>,
    pub adj: Vec<f32>,
}

/// One object as the graph places it: normalised distance to the worker, index in the
/// frame, and its relation to the worker when it is known on the floor.
#[derive(Debug, Clone, Copy)]
struct Placed {
    distance: f32,
    index: usize,
    relation: Option<[f32; PER_STATION]>,
}

/// Builds star graphs into reused buffers.
#[derive(Debug, Clone)]
pub struct GraphBuilder {
    edge_weight: EdgeWeight,
    features: NodeFeatures,
    graph: StarGraph,
    order: Vec<Placed>,
    degree: Vec<f32>,
}

impl GraphBuilder {
    /// `max_nodes` includes the worker node and must be at least 1.
    pub fn new(max_nodes: usize, edge_weight: EdgeWeight, features: NodeFeatures) -> Self {
        assert!(max_nodes >= 1, "a star graph needs room for the worker node");
        let dim = features.dim();
        GraphBuilder {
            edge_weight,
            features,
            graph: StarGraph {
                max_nodes,
                nodes: 0,
                dim,
                x: vec![0.0; max_nodes * dim],
                adj: vec![0.0; max_nodes * max_nodes],
            },
            order: Vec::with_capacity(spwi_proto::MAX_OBJECTS),
            degree: vec![0.0; max_nodes],
        }
    }

    /// The star graph of a frame, or `None` when the frame does not show the worker
    /// (the system is only activated when a human is detected). `floor` is read by a
    /// [`NodeFeatures::FloorRelations`] builder only, and only with the frame's pose.
    pub fn build(&mut self, frame: &DetectionFrame, floor: Option<OnFloor<'_>>) -> Option<&StarGraph> {
        let human = frame.worker()?;
        let n_max = self.graph.max_nodes;
        let diag = (frame.image_size[0].powi(2) + frame.image_size[1].powi(2)).sqrt();
        let (hx, hy) = human.bbox.center();
        let floor = match (self.features, floor, frame.pose.as_ref()) {
            (NodeFeatures::FloorRelations, Some(f), Some(pose)) => Some((f, pose)),
            _ => None,
        };

        // Objects by normalised distance to the worker, nearest first; index breaks ties.
        self.order.clear();
        self.order.extend(frame.objects.iter().enumerate().map(|(index, o)| {
            let on_floor = floor.and_then(|(f, pose)| Some((f.worker, f.camera.footprint(pose, o)?.0)));
            match on_floor {
                Some((worker, at)) => {
                    let mut relation = [0.0; PER_STATION];
                    relation_to(worker, at, &mut relation);
                    let metres = (at[0] - worker.position[0]).hypot(at[1] - worker.position[1]);
                    Placed { distance: metres / FLOOR_RANGE, index, relation: Some(relation) }
                }
                None => {
                    let (ox, oy) = o.bbox.center();
                    Placed { distance: ((ox - hx).powi(2) + (oy - hy).powi(2)).sqrt() / diag, index, relation: None }
                }
            }
        }));
        self.order.sort_by(|a, b| a.distance.total_cmp(&b.distance).then(a.index.cmp(&b.index)));
        self.order.truncate(n_max - 1);
        let nodes = 1 + self.order.len();

        let g = &mut self.graph;
        let dim = g.dim;
        g.nodes = nodes;
        g.x.fill(0.0);
        g.adj.fill(0.0);
        let put_node = |x: &mut [f32], node: usize, local: &[f32]| {
            let row = &mut x[node * dim..(node + 1) * dim];
            row[..FEATURE_DIM].copy_from_slice(&frame.scene_feature);
            row[FEATURE_DIM..NODE_FEATURE_DIM].copy_from_slice(local);
        };
        put_node(&mut g.x, 0, &human.feature);
        if let Some((f, _)) = floor {
            track_values(f.worker, &mut g.x[NODE_FEATURE_DIM..NODE_FEATURE_DIM + TRACK_VALUES]);
        }
        for (k, p) in self.order.iter().enumerate() {
            put_node(&mut g.x, k + 1, &frame.objects[p.index].feature);
            if let Some(relation) = &p.relation {
                g.x[(k + 1) * dim + NODE_FEATURE_DIM + TRACK_VALUES..(k + 2) * dim].copy_from_slice(relation);
            }
        }

        // A' = A + I over the real nodes.
        for i in 0..nodes {
            g.adj[i * n_max + i] = 1.0;
        }
        for (k, p) in self.order.iter().enumerate() {
            let w = self.edge_weight.weight(p.distance);
            g.adj[k + 1] = w; // row 0
            g.adj[(k + 1) * n_max] = w; // column 0
        }
        // Â = D^-1/2 A' D^-1/2
        for i in 0..nodes {
            let deg: f32 = g.adj[i * n_max..i * n_max + nodes].iter().sum();
            self.degree[i] = if deg > 0.0 { deg.sqrt().recip() } else { 0.0 };
        }
        for i in 0..nodes {
            for j in 0..nodes {
                g.adj[i * n_max + j] *= self.degree[i] * self.degree[j];
            }
        }
        Some(&self.graph)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use spwi_proto::*;

    fn feature(v: f32) -> Vec<f32> {
        vec![v; FEATURE_DIM]
    }

    fn frame(objects: &[(f32, f32)]) -> DetectionFrame {
        DetectionFrame {
            robot: RobotId::new("r").unwrap(),
            capture_us: 1,
            pose: None,
            image_size: [300.0, 400.0], // diagonal 500
            humans: vec![HumanDetection {
                bbox: BBox { x: 90.0, y: 90.0, w: 20.0, h: 20.0 }, // centre (100, 100)
                keypoints: vec![0.0; KEYPOINT_VALUES],
                feature: feature(9.0),
                track: None,
            }],
            objects: objects
                .iter()
                .enumerate()
                .map(|(i, &(cx, cy))| ObjectDetection {
                    class: ObjectClass::Crate,
                    bbox: BBox { x: cx - 5.0, y: cy - 5.0, w: 10.0, h: 10.0 },
                    score: 0.9,
                    feature: feature(i as f32 + 1.0),
                })
                .collect(),
            scene_feature: feature(0.5),
        }
    }

    #[test]
    fn no_worker_no_graph() {
        let mut f = frame(&[(10.0, 10.0)]);
        f.humans.clear();
        assert!(GraphBuilder::new(4, EdgeWeight::Proximity, NodeFeatures::Appearance).build(&f, None).is_none());
    }

    #[test]
    fn star_graph_is_normalised_by_hand() {
        // One object 300 px right of the worker: d = 300/500 = 0.6, proximity w = 0.4.
        let mut b = GraphBuilder::new(3, EdgeWeight::Proximity, NodeFeatures::Appearance);
        let g = b.build(&frame(&[(400.0, 100.0)]), None).unwrap().clone();
        assert_eq!(g.nodes, 2);
        // A' = [[1, .4], [.4, 1]], degrees 1.4 both → Â = A' / 1.4
        let n = 3;
        let want = [1.0 / 1.4, 0.4 / 1.4, 0.0, 0.4 / 1.4, 1.0 / 1.4, 0.0, 0.0, 0.0, 0.0];
        for (i, (&got, &w)) in g.adj.iter().zip(&want).enumerate() {
            assert!((got - w).abs() < 1e-6, "adj[{}][{}] = {got}, want {w}", i / n, i % n);
        }
        // node features: scene ‖ local; padding stays zero
        assert_eq!(g.x[0], 0.5);
        assert_eq!(g.x[FEATURE_DIM], 9.0);
        assert_eq!(g.x[NODE_FEATURE_DIM + FEATURE_DIM], 1.0);
        assert!(g.x[2 * NODE_FEATURE_DIM..].iter().all(|&v| v == 0.0));
    }

    #[test]
    fn distance_kind_weighs_far_objects_more() {
        let mut b = GraphBuilder::new(3, EdgeWeight::Distance, NodeFeatures::Appearance);
        let g = b.build(&frame(&[(400.0, 100.0)]), None).unwrap();
        // A' = [[1, .6], [.6, 1]]
        assert!((g.adj[1] - 0.6 / 1.6).abs() < 1e-6);
    }

    #[test]
    fn adjacency_is_symmetric_and_keeps_nearest_objects() {
        let mut b = GraphBuilder::new(3, EdgeWeight::Proximity, NodeFeatures::Appearance);
        // three objects, room for two: the far one (index 0) is dropped
        let g = b.build(&frame(&[(290.0, 400.0), (110.0, 100.0), (100.0, 150.0)]), None).unwrap();
        assert_eq!(g.nodes, 3);
        for i in 0..3 {
            for j in 0..3 {
                assert_eq!(g.adj[i * 3 + j], g.adj[j * 3 + i]);
            }
        }
        assert_eq!(g.x[NODE_FEATURE_DIM + FEATURE_DIM], 2.0, "nearest object first");
        assert_eq!(g.x[2 * NODE_FEATURE_DIM + FEATURE_DIM], 3.0);
        // objects are not linked to each other
        assert_eq!(g.adj[3 + 2], 0.0);
    }
}

#[cfg(test)]
mod floor_tests {
    use super::*;
    use spwi_proto::*;

    /// A frame of the default camera at the origin, facing +x: the worker, an object
    /// whose footprint lies at `at` on the floor, and one cut by the image's lower edge.
    fn frame_on_floor(cam: &CameraCalibration, at: [f32; 2]) -> DetectionFrame {
        let pose = FloorPose { position: [0.0, 0.0], heading: 0.0 };
        let (u, v) = cam.project(&pose, [at[0], at[1], 0.0]).unwrap();
        let object = |bbox: BBox, v: f32| ObjectDetection {
            class: ObjectClass::Crate,
            bbox,
            score: 0.9,
            feature: vec![v; FEATURE_DIM],
        };
        DetectionFrame {
            robot: RobotId::new("r").unwrap(),
            capture_us: 1,
            pose: Some(pose),
            image_size: [cam.image[0] as f32, cam.image[1] as f32],
            humans: vec![HumanDetection {
                bbox: BBox { x: 300.0, y: 150.0, w: 40.0, h: 120.0 },
                keypoints: vec![0.0; KEYPOINT_VALUES],
                feature: vec![9.0; FEATURE_DIM],
                track: None,
            }],
            objects: vec![
                object(BBox { x: 500.0, y: 400.0, w: 60.0, h: 80.0 }, 2.0), // bottom at the image's edge
                object(BBox { x: u - 20.0, y: v - 30.0, w: 40.0, h: 30.0 }, 1.0),
            ],
            scene_feature: vec![0.5; FEATURE_DIM],
        }
    }

    #[test]
    fn floor_relations_weigh_edges_by_floor_distance_and_give_each_node_its_relation() {
        let cam = CameraCalibration::default();
        // The worker 2 m short of the object, walking straight at it at 1 m/s.
        let worker = WorkerEstimate { position: [3.0, 0.0], velocity: [1.0, 0.0], covariance: [0.04, 0.0, 0.1] };
        let f = frame_on_floor(&cam, [5.0, 0.0]);
        let mut b = GraphBuilder::new(4, EdgeWeight::Proximity, NodeFeatures::FloorRelations);
        let g = b.build(&f, Some(OnFloor { camera: &cam, worker: &worker })).unwrap().clone();
        let dim = NODE_FEATURE_DIM + FLOOR_RELATION_DIM;
        assert_eq!((g.nodes, g.dim, g.x.len()), (3, dim, 4 * dim));
        let relations = |node: usize| &g.x[node * dim + NODE_FEATURE_DIM..(node + 1) * dim];
        // Node 0, the worker: the track's values, no object relation.
        let track = &relations(0)[..TRACK_VALUES];
        assert!(track[0] == 1.0 && track[1] == 1.0 && (track[2] - 0.2).abs() < 1e-6, "{track:?}");
        assert!(relations(0)[TRACK_VALUES..].iter().all(|&v| v == 0.0));
        // Node 1, the object on the floor (nearest first: 2 m): [known, 2 m / 10, closing
        // 1 m/s, sideways 0, straight ahead], to back-projection's centimetre.
        assert_eq!(g.x[dim + FEATURE_DIM], 1.0, "the object on the floor comes first");
        let want = [1.0, 0.2, 1.0, 0.0, 1.0, 0.0];
        for (got, want) in relations(1)[TRACK_VALUES..].iter().zip(want) {
            assert!((got - want).abs() < 2e-3, "{:?}", relations(1));
        }
        assert!(relations(1)[..TRACK_VALUES].iter().all(|&v| v == 0.0));
        // Node 2, the box cut by the image's edge: no relation, its image distance.
        assert_eq!(g.x[2 * dim + FEATURE_DIM], 2.0);
        assert!(relations(2).iter().all(|&v| v == 0.0));
        // Edge weights before normalisation: 1 − 2/10 on the floor; A' row 0 = [1, .8, w2].
        let d0 = 1.0 + 0.8 + (1.0 - g_image_distance(&f, 0));
        let want_01 = 0.8 / (d0.sqrt() * 1.8f32.sqrt());
        assert!((g.adj[1] - want_01).abs() < 1e-3, "{} against {want_01}", g.adj[1]);
    }

    /// Object `i`'s image distance to the worker, normalised by the diagonal.
    fn g_image_distance(f: &DetectionFrame, i: usize) -> f32 {
        let (hx, hy) = f.humans[0].bbox.center();
        let (ox, oy) = f.objects[i].bbox.center();
        (ox - hx).hypot(oy - hy) / f.image_size[0].hypot(f.image_size[1])
    }

    #[test]
    fn without_a_track_a_floor_graph_is_the_appearance_graph_with_zero_relations() {
        let cam = CameraCalibration::default();
        let f = frame_on_floor(&cam, [5.0, 0.0]);
        let plain =
            GraphBuilder::new(4, EdgeWeight::Proximity, NodeFeatures::Appearance).build(&f, None).unwrap().clone();
        let mut b = GraphBuilder::new(4, EdgeWeight::Proximity, NodeFeatures::FloorRelations);
        let g = b.build(&f, None).unwrap();
        assert_eq!(g.adj, plain.adj);
        let dim = g.dim;
        for node in 0..4 {
            let row = &g.x[node * dim..(node + 1) * dim];
            assert_eq!(row[..NODE_FEATURE_DIM], plain.x[node * NODE_FEATURE_DIM..(node + 1) * NODE_FEATURE_DIM]);
            assert!(row[NODE_FEATURE_DIM..].iter().all(|&v| v == 0.0));
        }
        // An appearance builder ignores the floor altogether.
        let worker = WorkerEstimate { position: [3.0, 0.0], velocity: [1.0, 0.0], covariance: [0.04, 0.0, 0.1] };
        let mut a = GraphBuilder::new(4, EdgeWeight::Proximity, NodeFeatures::Appearance);
        let on_floor = a.build(&f, Some(OnFloor { camera: &cam, worker: &worker })).unwrap();
        assert_eq!((&on_floor.x, &on_floor.adj), (&plain.x, &plain.adj));
    }
}
