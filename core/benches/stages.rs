//! Per-stage latency of one robot's tick, single-threaded, batch 1:
//! star graph, GCN, ego-GRU, collective-GRU, vote + consensus, a whole tick through the
//! engine, and encode/decode of every message. Reports p50 / p99 / mean per call.
//!
//! Run: `cargo bench -p spwi-core --bench stages` (add `--features ort` and set
//! ORT_DYLIB_PATH to include ONNX Runtime). `SPWI_BENCH_MODELS=DIR` picks a model set
//! (default: models/default, the shipped trained set).

use spwi_core::consensus::{self, Ballot, Rule};
use spwi_core::engine::{Engine, EngineConfig, Input};
use spwi_core::graph::GraphBuilder;
use spwi_core::model::{Backend, ModelSet};
use spwi_core::temporal::TemporalModel;
use spwi_core::trust::TrustBook;
use spwi_core::vote;
use spwi_proto::*;
use std::hint::black_box;
use std::path::PathBuf;
use std::time::{Duration, Instant};

#[path = "../tests/synthetic/mod.rs"]
mod synthetic;
use synthetic::frame;

fn measure(name: &str, iters: usize, mut f: impl FnMut()) {
    for _ in 0..iters / 10 {
        f();
    }
    let mut t: Vec<Duration> = (0..iters)
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed()
        })
        .collect();
    t.sort();
    let us = |d: Duration| d.as_secs_f64() * 1e6;
    let mean = t.iter().map(|d| us(*d)).sum::<f64>() / t.len() as f64;
    println!(
        "{name:<34} p50 {:>9.1} µs   p99 {:>9.1} µs   mean {:>9.1} µs",
        us(t[t.len() / 2]),
        us(t[t.len() * 99 / 100]),
        mean
    );
}

fn models_dir() -> PathBuf {
    std::env::var_os("SPWI_BENCH_MODELS")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../models/default"))
}

fn bench_backend(backend: Backend) {
    let set = match ModelSet::load(&models_dir(), backend, None) {
        Ok(s) => s,
        Err(e) => {
            println!("{backend:?}: skipped ({e:#})");
            return;
        }
    };
    let m = &set.manifest;
    println!("\n== {backend:?} (model set {:?}, W = {}, H = {}, {} nodes)", m.name, m.window, m.horizon, m.max_nodes);
    let f = frame(1, 12);
    let mut graph = GraphBuilder::new(m.max_nodes, m.edge_weight, m.node_features);
    let camera = spwi_core::floor::CameraCalibration::default();
    measure(&format!("star graph (12 objects, {:?})", m.node_features), 20_000, || {
        black_box(graph.build(black_box(&f), Some(synthetic::on_floor(&camera))));
    });
    let mut ego = set.inference(TemporalModel::Ego).unwrap();
    let mut col = set.inference(TemporalModel::Collective).unwrap();
    // The simulated floors show one to three objects beside the worker; 12 is a crowded
    // view. A GCN that names its node count is fed only the real nodes (m.gcn_nodes()).
    for objects in [3, 12] {
        let g = graph.build(&frame(1, objects), Some(synthetic::on_floor(&camera))).unwrap().clone();
        measure(&format!("GCN ({objects} objects, {:?})", m.gcn_nodes()), 3_000, || {
            black_box(ego.gcn(black_box(&g)).unwrap());
        });
    }
    let ego_in = vec![0.1f32; m.frames() * TemporalModel::Ego.row_dim(m.row)];
    let col_in = vec![0.1f32; m.frames() * TemporalModel::Collective.row_dim(m.row)];
    let col_peers = vec![0.1f32; m.frames() * col.peer_slots() * spwi_core::floor::RELATION_DIM];
    measure("ego-GRU", 3_000, || {
        black_box(ego.gru(black_box(&ego_in), &[]).unwrap());
    });
    measure("collective-GRU", 3_000, || {
        black_box(col.gru(black_box(&col_in), black_box(&col_peers)).unwrap());
    });
    let logits = col.gru(&col_in, &col_peers).unwrap();
    let ids: Vec<RobotId> = (0..8).map(|i| RobotId::new(format!("r{i}")).unwrap()).collect();
    let votes: Vec<Vec<StepVote>> = (0..8).map(|_| vote::vote(&logits, 1.3)).collect();
    measure("vote + consensus (8 robots, H+1 steps)", 20_000, || {
        let v = vote::vote(black_box(&logits), 1.3);
        let mut ballots: Vec<Ballot<'_>> = ids
            .iter()
            .zip(&votes)
            .map(|(r, s)| Ballot { robot: r, visibility: 5, trust: 0.9, quality: 0.8, steps: s })
            .collect();
        black_box((v, consensus::decide(&mut ballots, Rule::Trust)));
    });
    // After each decision every voter is judged against the others' decision.
    let mut book = TrustBook::new(Default::default());
    let ballots: Vec<Ballot<'_>> = ids
        .iter()
        .zip(&votes)
        .map(|(r, s)| Ballot { robot: r, visibility: 5, trust: 0.9, quality: 0.8, steps: s })
        .collect();
    measure("learning trust (8 voters, H+1 steps)", 20_000, || {
        book.learn(black_box(&ballots));
    });
    let mut engine = Engine::new(
        EngineConfig {
            robot: frame(0, 0).robot, // the engine takes only its own robot's frames
            instance: 1,
            temporal: TemporalModel::Collective,
            decision_deadline: Duration::from_millis(60),
            consensus: Rule::Trust,
            trust: Default::default(),
            max_open_ticks: 64,
            camera: Default::default(),
            relay_after: None,
            relayers: 4,
            ask_rounds: 2,
            catch_up: Duration::ZERO,
            stale_after: 0, // the bench repeats one frame on purpose
            window: Default::default(),
            floor_plan: None,
        },
        set.inference(TemporalModel::Collective).unwrap(),
    );
    let mut tick = 0u64;
    for objects in [3, 12] {
        let template = frame(0, objects);
        measure(&format!("whole tick ({objects} objects, alone)"), 3_000, || {
            tick += 1;
            let mut f = template.clone(); // a copy, as a received frame would be
            f.capture_us = DetectionFrame::capture_at_tick(tick);
            black_box(engine.handle(Input::Frame(f), Duration::from_millis(tick * 100)));
        });
    }
}

fn bench_codec() {
    println!("\n== codec");
    let f = frame(7, 12);
    let fb = encode(&f);
    let v = VoteMsg {
        robot: f.robot.clone(),
        instance: 1,
        tick: 7,
        steps: vec![StepVote { class: Station::Assembly, confidence: 0.7 }; 21],
        visibility: 13,
        worker: None,
        quality: 0.8,
        signature: Vec::new(),
    };
    let e = EmbeddingMsg {
        robot: f.robot.clone(),
        instance: 1,
        tick: 7,
        embedding: Some(vec![0.5; EMBEDDING_DIM]),
        visibility: 13,
        vote: Some(v),
        worker: Some(WorkerEstimate { position: [3.0, 4.0], velocity: [1.0, 0.2], covariance: [0.05, 0.01, 0.2] }),
        facing: Some(1.2),
        landmarks: Station::ALL
            .map(|s| Landmark { station: s, position: [s.index() as f32, 2.0], sigma: 0.4 })
            .to_vec(),
        verdict: Some(Verdict {
            tick: 6,
            class: Some(Station::Assembly),
            voters: (0..4).map(|i| RobotId::new(format!("r{i}")).unwrap()).collect(),
            digest: 0x5eed,
        }),
        people: vec![PersonShare {
            worker: WorkerId(7),
            estimate: WorkerEstimate { position: [3.0, 4.0], velocity: [1.0, 0.2], covariance: [0.05, 0.01, 0.2] },
        }],
    };
    let d = DecisionMsg {
        robot: f.robot.clone(),
        instance: 1,
        tick: 7,
        steps: vec![TeamStep { class: Station::Assembly, score: 0.6 }; 21],
        voters: (0..4).map(|i| RobotId::new(format!("r{i}")).unwrap()).collect(),
        live_members: 4,
        decided_by: DecidedBy::AllVoted,
        digest: 0x5eed,
    };
    let (eb, db) = (encode(&e), encode(&d));
    println!(
        "sizes: frame(12 objects) {} B, embedding with its vote {} B, decision {} B",
        fb.len(),
        eb.len(),
        db.len()
    );
    measure("encode frame (12 objects)", 5_000, || {
        black_box(encode(black_box(&f)));
    });
    measure("decode frame (12 objects)", 5_000, || {
        black_box(decode::<DetectionFrame>(black_box(&fb)).unwrap());
    });
    measure("encode + decode embedding with its vote", 20_000, || {
        black_box(decode::<EmbeddingMsg>(&encode(black_box(&e))).unwrap());
    });
    measure("encode + decode decision", 20_000, || {
        black_box(decode::<DecisionMsg>(&encode(black_box(&d))).unwrap());
    });
}

fn main() {
    if std::env::args().any(|a| a == "--list") {
        return; // `cargo test --benches` asks for the list; there are no named benches
    }
    bench_backend(Backend::Tract);
    #[cfg(feature = "ort")]
    bench_backend(Backend::Ort);
    bench_codec();
}
