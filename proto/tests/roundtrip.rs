//! Property tests of the codec: every valid message survives a round trip unchanged,
//! and no byte string makes `decode` panic.

use proptest::prelude::*;
use spwi_proto::*;

fn robot() -> impl Strategy<Value = RobotId> {
    "[A-Za-z0-9_-]{1,64}".prop_map(|s| RobotId::new(s).unwrap())
}

fn finite() -> impl Strategy<Value = f32> {
    -1.0e6f32..1.0e6
}

fn bbox() -> impl Strategy<Value = BBox> {
    (finite(), finite(), 0.0f32..2000.0, 0.0f32..2000.0).prop_map(|(x, y, w, h)| BBox { x, y, w, h })
}

fn frame() -> impl Strategy<Value = DetectionFrame> {
    let human =
        (bbox(), prop::collection::vec(finite(), KEYPOINT_VALUES), prop::collection::vec(finite(), FEATURE_DIM));
    let object = (
        prop::sample::select(ObjectClass::ALL.to_vec()),
        bbox(),
        0.0f32..=1.0,
        prop::collection::vec(finite(), FEATURE_DIM),
    )
        .prop_map(|(class, bbox, score, feature)| ObjectDetection { class, bbox, score, feature });
    (
        robot(),
        any::<u64>(),
        (1.0f32..4000.0, 1.0f32..4000.0),
        prop::collection::vec(human, 0..3),
        prop::collection::vec(object, 0..6),
        prop::collection::vec(finite(), FEATURE_DIM),
        prop::option::of((finite(), finite(), finite())),
    )
        .prop_map(|(robot, capture_us, (w, h), humans, objects, scene_feature, pose)| DetectionFrame {
            robot,
            capture_us,
            pose: pose.map(|(x, y, heading)| FloorPose { position: [x, y], heading }),
            image_size: [w, h],
            // Track ids, when a detector gives them, are distinct within a frame.
            humans: humans
                .into_iter()
                .enumerate()
                .map(|(i, (bbox, keypoints, feature))| HumanDetection {
                    bbox,
                    keypoints,
                    feature,
                    track: (i % 2 == 1).then_some(i as u32),
                })
                .collect(),
            objects,
            scene_feature,
        })
}

fn station() -> impl Strategy<Value = Station> {
    prop::sample::select(Station::ALL.to_vec())
}

fn steps() -> impl Strategy<Value = Vec<StepVote>> {
    prop::collection::vec(
        (station(), 0.0f32..=1.0).prop_map(|(class, confidence)| StepVote { class, confidence }),
        1..40,
    )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn frames_round_trip(f in frame()) {
        prop_assert_eq!(decode::<DetectionFrame>(&encode(&f)).unwrap(), f);
    }

    #[test]
    fn embeddings_round_trip(robot in robot(), instance in any::<u64>(), tick in any::<u64>(),
                             e in prop::option::of(prop::collection::vec(finite(), EMBEDDING_DIM)), visibility in any::<u32>(),
                             worker in prop::option::of((finite(), finite(), finite(), finite(), 0.01f32..10.0, -0.5f32..0.5, 1.0f32..10.0)),
                             facing in prop::option::of(finite()),
                             landmarks in prop::collection::vec((station(), finite(), finite(), 0.01f32..5.0), 0..8),
                             verdict in prop::option::of((any::<u64>(), prop::option::of(station()), prop::collection::btree_set(robot(), 0..10), any::<u64>())),
                             vote in prop::option::of((steps(), 0.0f32..=1.0)),
                             people in prop::collection::btree_map(any::<u64>(), (finite(), finite()), 0..=8)) {
        let worker = worker.map(|(x, y, vx, vy, pp, pv, vv)| WorkerEstimate { position: [x, y], velocity: [vx, vy], covariance: [pp, pv * pp.sqrt(), vv] });
        let landmarks = landmarks.into_iter().map(|(station, x, y, sigma)| Landmark { station, position: [x, y], sigma }).collect();
        let verdict = verdict.map(|(tick, class, voters, digest)| Verdict { tick, class, voters: voters.into_iter().collect(), digest });
        let vote = vote.map(|(steps, quality)| VoteMsg { robot: robot.clone(), instance, tick, steps, visibility, quality, worker, signature: vec![7; 64] });
        let people = people.into_iter().map(|(id, (x, y))| PersonShare { worker: WorkerId(id), estimate: WorkerEstimate { position: [x, y], velocity: [0.5, 0.0], covariance: [0.25, 0.0, 1.0] } }).collect();
        let m = EmbeddingMsg { robot, instance, tick, embedding: e, visibility, vote, worker, facing, landmarks, verdict, people };
        prop_assert_eq!(decode::<EmbeddingMsg>(&encode(&m)).unwrap(), m);
    }

    #[test]
    fn votes_round_trip(robot in robot(), instance in any::<u64>(), tick in any::<u64>(), steps in steps(), visibility in any::<u32>(),
                        quality in 0.0f32..=1.0) {
        let m = VoteMsg { robot: robot.clone(), instance, tick, steps, visibility, quality, worker: None, signature: vec![9; 64] };
        prop_assert_eq!(decode_from::<VoteMsg>(&encode(&m), &robot).unwrap(), m);
    }

    #[test]
    fn decisions_round_trip(robot in robot(), tick in any::<u64>(), voters in prop::collection::btree_set(robot(), 0..10),
                            steps in prop::collection::vec((station(), finite()).prop_map(|(class, score)| TeamStep { class, score }), 0..30)) {
        let voters = voters.into_iter().collect();
        let m = DecisionMsg { robot, instance: 1, tick, steps, voters, live_members: 3, decided_by: DecidedBy::Deadline, digest: tick.rotate_left(7) };
        prop_assert_eq!(decode::<DecisionMsg>(&encode(&m)).unwrap(), m);
    }

    #[test]
    fn relayed_ballots_round_trip(robot in robot(), tick in any::<u64>(), votes in prop::collection::vec((steps(), any::<u32>()), 0..6)) {
        let votes = votes.into_iter().enumerate().map(|(i, (steps, visibility))| VoteMsg {
            robot: RobotId::new(format!("o{i}")).unwrap(), instance: i as u64, tick, steps, visibility, quality: 0.5, worker: None, signature: Vec::new(),
        }).collect();
        let m = BallotsMsg { robot: robot.clone(), instance: 2, tick, votes };
        prop_assert_eq!(decode_from::<BallotsMsg>(&encode(&m), &robot).unwrap(), m);
    }

    #[test]
    fn arbitrary_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..2048)) {
        let _ = decode::<DetectionFrame>(&bytes);
        let _ = decode::<EmbeddingMsg>(&bytes);
        let _ = decode::<VoteMsg>(&bytes);
        let _ = decode::<DecisionMsg>(&bytes);
        let _ = decode::<BallotsMsg>(&bytes);
        let _ = decode::<TruthMsg>(&bytes);
    }

    #[test]
    fn flipped_bytes_never_panic(f in frame(), at in any::<prop::sample::Index>(), x in 1u8..=255) {
        let mut b = encode(&f);
        let i = at.index(b.len());
        b[i] ^= x;
        let _ = decode::<DetectionFrame>(&b);
    }
}
