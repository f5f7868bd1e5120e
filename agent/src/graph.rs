//! Detection frame → star graph (paper II-C). Pure: same frame, same graph.
//!
//! The worker is node 0, one node per detected object after it; node feature =
//! global scene feature ‖ local appearance feature (512 + 512). Edges connect the
//! worker to every object, weighted from the distance between bbox centres normalised
//! by the image diagonal ([`EdgeWeight`]). Then A' = A + I and the symmetric
//! normalisation Â = D^-1/2 A' D^-1/2, computed here so the ONNX GCN only multiplies.
//! Graphs are padded to the model's fixed node count with zero rows and columns (no
//! self-loop), so padding never reaches the worker's embedding. When a frame holds more
//! objects than fit, the ones nearest the worker are kept.
//!
//! The builder owns its buffers: one allocation at start-up, none per tick.

use serde::{Deserialize, Serialize};
use spwi_proto::{DetectionFrame, FEATURE_DIM};

/// Width of a node feature: global ‖ local.
pub const NODE_FEATURE_DIM: usize = 2 * FEATURE_DIM;

/// How an edge weight derives from the normalised centre distance d ∈ [0, 1].
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

/// A padded star graph ready for the GCN: `x` is `[max_nodes, 1024]`, `adj` is the
/// normalised `[max_nodes, max_nodes]`, both row-major.
#[derive(Debug, Clone)]
pub struct StarGraph {
    pub max_nodes: usize,
    /// Real nodes (worker + objects kept); the rest is padding.
    pub nodes: usize,
    pub x: Vec<f32>,
    pub adj: Vec<f32>,
}

/// Builds star graphs into reused buffers.
#[derive(Debug, Clone)]
pub struct GraphBuilder {
    edge_weight: EdgeWeight,
    graph: StarGraph,
    order: Vec<(f32, usize)>,
    degree: Vec<f32>,
}

impl GraphBuilder {
    /// `max_nodes` includes the worker node and must be at least 1.
    pub fn new(max_nodes: usize, edge_weight: EdgeWeight) -> Self {
        assert!(max_nodes >= 1, "a star graph needs room for the worker node");
        GraphBuilder {
            edge_weight,
            graph: StarGraph {
                max_nodes,
                nodes: 0,
                x: vec![0.0; max_nodes * NODE_FEATURE_DIM],
                adj: vec![0.0; max_nodes * max_nodes],
            },
            order: Vec::with_capacity(spwi_proto::MAX_OBJECTS),
            degree: vec![0.0; max_nodes],
        }
    }

    /// The star graph of a frame, or `None` when the frame does not show the worker
    /// (the system is only activated when a human is detected).
    pub fn build(&mut self, frame: &DetectionFrame) -> Option<&StarGraph> {
        let human = frame.human.as_ref()?;
        let n_max = self.graph.max_nodes;
        let diag = (frame.image_size[0].powi(2) + frame.image_size[1].powi(2)).sqrt();
        let (hx, hy) = human.bbox.center();

        // Objects by normalised distance to the worker, nearest first; index breaks ties.
        self.order.clear();
        self.order.extend(frame.objects.iter().enumerate().map(|(i, o)| {
            let (ox, oy) = o.bbox.center();
            (((ox - hx).powi(2) + (oy - hy).powi(2)).sqrt() / diag, i)
        }));
        self.order.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        self.order.truncate(n_max - 1);
        let nodes = 1 + self.order.len();

        let g = &mut self.graph;
        g.nodes = nodes;
        g.x.fill(0.0);
        g.adj.fill(0.0);
        let mut put_node = |node: usize, local: &[f32]| {
            let row = &mut g.x[node * NODE_FEATURE_DIM..(node + 1) * NODE_FEATURE_DIM];
            row[..FEATURE_DIM].copy_from_slice(&frame.scene_feature);
            row[FEATURE_DIM..].copy_from_slice(local);
        };
        put_node(0, &human.feature);
        for (k, &(_, i)) in self.order.iter().enumerate() {
            put_node(k + 1, &frame.objects[i].feature);
        }

        // A' = A + I over the real nodes.
        for i in 0..nodes {
            g.adj[i * n_max + i] = 1.0;
        }
        for (k, &(d, _)) in self.order.iter().enumerate() {
            let w = self.edge_weight.weight(d);
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
            tick: 1,
            pose: None,
            image_size: [300.0, 400.0], // diagonal 500
            human: Some(HumanDetection {
                bbox: BBox { x: 90.0, y: 90.0, w: 20.0, h: 20.0 }, // centre (100, 100)
                keypoints: vec![0.0; KEYPOINT_VALUES],
                feature: feature(9.0),
            }),
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
        f.human = None;
        assert!(GraphBuilder::new(4, EdgeWeight::Proximity).build(&f).is_none());
    }

    #[test]
    fn star_graph_is_normalised_by_hand() {
        // One object 300 px right of the worker: d = 300/500 = 0.6, proximity w = 0.4.
        let mut b = GraphBuilder::new(3, EdgeWeight::Proximity);
        let g = b.build(&frame(&[(400.0, 100.0)])).unwrap().clone();
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
        let mut b = GraphBuilder::new(3, EdgeWeight::Distance);
        let g = b.build(&frame(&[(400.0, 100.0)])).unwrap();
        // A' = [[1, .6], [.6, 1]]
        assert!((g.adj[1] - 0.6 / 1.6).abs() < 1e-6);
    }

    #[test]
    fn adjacency_is_symmetric_and_keeps_nearest_objects() {
        let mut b = GraphBuilder::new(3, EdgeWeight::Proximity);
        // three objects, room for two: the far one (index 0) is dropped
        let g = b.build(&frame(&[(290.0, 400.0), (110.0, 100.0), (100.0, 150.0)])).unwrap();
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
