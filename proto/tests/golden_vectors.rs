//! Golden vectors: one example of every message, as the bytes the codec writes
//! (`proto/golden/<topic>.bin`) and as JSON (`<topic>.json`, the same value through
//! serde). A client in another language checks its encoder and decoder against them
//! (docs/PROTOCOL.md); this test fails when a message changes without its vectors.
//! After an intended change: `SPWI_BLESS_GOLDEN=1 cargo test -p spwi-proto --test golden_vectors`
//! writes them anew.

use spwi_proto::*;
use std::path::PathBuf;

/// Exactly representable values, so the JSON renders them without rounding.
fn values(n: usize, from: f32) -> Vec<f32> {
    (0..n).map(|i| from + (i % 16) as f32 * 0.25).collect()
}

fn id(s: &str) -> RobotId {
    RobotId::new(s).unwrap()
}

fn vote() -> VoteMsg {
    VoteMsg {
        robot: id("r1"),
        instance: 300,
        tick: 17_650_000_000,
        steps: vec![
            StepVote { class: Station::Assembly, confidence: 0.75 },
            StepVote { class: Station::Manufacturing, confidence: 0.5 },
        ],
        visibility: 4,
        quality: 0.5,
        worker: Some(WorkerEstimate { position: [3.5, -1.25], velocity: [0.5, 0.0], covariance: [0.25, 0.0, 1.0] }),
        signature: Vec::new(),
    }
}

fn decision() -> DecisionMsg {
    DecisionMsg {
        robot: id("r1"),
        instance: 300,
        tick: 17_650_000_000,
        steps: vec![TeamStep { class: Station::Assembly, score: 0.75 }],
        voters: vec![id("r1"), id("r2")],
        live_members: 3,
        decided_by: DecidedBy::Deadline,
        digest: 0x0123_4567_89ab_cdef,
    }
}

/// Every message's example, by the topic it travels on, as (bytes, JSON).
fn examples() -> Vec<(&'static str, Vec<u8>, serde_json::Value)> {
    fn both<M: Message>(m: &M) -> (Vec<u8>, serde_json::Value) {
        (encode(m), serde_json::to_value(m).unwrap())
    }
    let frame = DetectionFrame {
        robot: id("r1"),
        capture_us: 1_765_000_000_000_000,
        pose: Some(FloorPose { position: [2.0, 4.5], heading: 1.5 }),
        image_size: [640.0, 480.0],
        humans: vec![HumanDetection {
            bbox: BBox { x: 300.0, y: 200.0, w: 40.0, h: 120.0 },
            keypoints: values(KEYPOINT_VALUES, 300.0),
            feature: values(FEATURE_DIM, 0.0),
            track: Some(7),
        }],
        objects: vec![ObjectDetection {
            class: ObjectClass::Workbench,
            bbox: BBox { x: 100.0, y: 250.0, w: 80.0, h: 60.0 },
            score: 0.75,
            feature: values(FEATURE_DIM, -1.0),
        }],
        scene_feature: values(FEATURE_DIM, 1.0),
    };
    let embedding = EmbeddingMsg {
        robot: id("r1"),
        instance: 300,
        tick: 17_650_000_000,
        embedding: Some(values(EMBEDDING_DIM, 0.5)),
        visibility: 4,
        vote: Some(vote()),
        worker: vote().worker,
        facing: Some(-0.5),
        landmarks: vec![Landmark { station: Station::Assembly, position: [6.0, 1.5], sigma: 0.25 }],
        verdict: Some(Verdict::of(&decision())),
        people: vec![
            PersonShare { worker: WorkerId(0x0123_4567_89ab_cdef), estimate: vote().worker.unwrap() },
            PersonShare {
                worker: WorkerId(42),
                estimate: WorkerEstimate { position: [1.0, 2.0], velocity: [0.0, -0.5], covariance: [0.5, 0.25, 1.0] },
            },
        ],
    };
    let ballots = BallotsMsg {
        robot: id("r2"),
        instance: 301,
        tick: 17_650_000_000,
        votes: vec![vote(), VoteMsg { robot: id("r2"), instance: 301, signature: vec![7; 64], ..vote() }],
    };
    let history = HistoryMsg {
        robot: id("r2"),
        instance: 301,
        lessons: vec![
            Lesson {
                tick: 17_649_999_990,
                votes: vec![VoteMsg { tick: 17_649_999_990, signature: vec![9; 64], ..vote() }],
            },
            Lesson { tick: 17_650_000_000, votes: vec![vote()] },
        ],
    };
    let map = MapMsg { robot: id("r1"), instance: 7, stations: [Some([1.0, 2.0]), None, None, Some([-3.5, 8.25])] };
    let truth = TruthMsg {
        tick: 17_650_000_000,
        intent: Station::Storage,
        phase: WorkerPhase::Transition,
        worker_position: [3.5, -1.25],
        worker_heading: 0.5,
        robots: vec![RobotPose { robot: id("r1"), position: [2.0, 4.5], heading: 1.5 }],
    };
    let v = vote();
    let d = decision();
    vec![
        ("detections", both(&frame)),
        ("embedding", both(&embedding)),
        ("vote", both(&v)),
        ("decision", both(&d)),
        ("ballots", both(&ballots)),
        ("map", both(&map)),
        ("history", both(&history)),
        ("truth", both(&truth)),
    ]
    .into_iter()
    .map(|(topic, (bytes, json))| (topic, bytes, json))
    .collect()
}

#[test]
fn every_message_is_encoded_as_its_golden_vector_says() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("golden");
    let bless = std::env::var_os("SPWI_BLESS_GOLDEN").is_some();
    for (topic, bytes, json) in examples() {
        let (bin, text) = (dir.join(format!("{topic}.bin")), dir.join(format!("{topic}.json")));
        if bless {
            std::fs::write(&bin, &bytes).unwrap();
            std::fs::write(&text, serde_json::to_string_pretty(&json).unwrap() + "\n").unwrap();
            continue;
        }
        let golden = std::fs::read(&bin).unwrap_or_else(|e| panic!("{}: {e}", bin.display()));
        assert!(
            golden == bytes,
            "{topic}: the codec's bytes differ from {} (bless after an intended change)",
            bin.display()
        );
        let golden_json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&text).unwrap()).unwrap();
        assert_eq!(golden_json, json, "{topic}: the JSON rendering differs from {}", text.display());
    }
}

/// The golden bytes decode, with the key's robot checked, to the value their JSON names.
#[test]
fn every_golden_vector_decodes_to_its_json() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("golden");
    fn check<M: Message>(dir: &std::path::Path, topic: &str, robot: &RobotId) {
        let bytes = std::fs::read(dir.join(format!("{topic}.bin"))).unwrap();
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join(format!("{topic}.json"))).unwrap()).unwrap();
        let m: M = decode_from(&bytes, robot).unwrap_or_else(|e| panic!("{topic}: {e}"));
        assert_eq!(serde_json::to_value(&m).unwrap(), json, "{topic}");
    }
    let (r1, r2) = (id("r1"), id("r2"));
    check::<DetectionFrame>(&dir, "detections", &r1);
    check::<EmbeddingMsg>(&dir, "embedding", &r1);
    check::<VoteMsg>(&dir, "vote", &r1);
    check::<DecisionMsg>(&dir, "decision", &r1);
    check::<BallotsMsg>(&dir, "ballots", &r2);
    check::<MapMsg>(&dir, "map", &r1);
    check::<HistoryMsg>(&dir, "history", &r2);
    check::<TruthMsg>(&dir, "truth", &r1);
}
