//! The floor: tracks, maps and relations shared and read.

use super::*;

#[test]
fn a_localised_robot_shares_its_worker_track_and_the_station_objects_it_sees() {
    let set = models();
    let mut a = engine("a", &set);
    let localised = |tick| DetectionFrame {
        pose: Some(FloorPose { position: [1.0, 2.0], heading: 0.5 }),
        ..frame("a", tick, true)
    };
    let mut last = None;
    for t in 1..=3 {
        last = Some(take_embedding(&a.handle(Input::Frame(localised(t)), ms(100 * t))));
    }
    let e = last.unwrap();
    let w = e.worker.expect("the worker's ankles are on the floor in view: an estimate");
    let range = (w.position[0] - 1.0).hypot(w.position[1] - 2.0);
    assert!((1.0..12.0).contains(&range), "in front of the camera: {w:?}");
    assert_eq!(e.landmarks.len(), 3, "crate, box and pallet mark the storage area");
    assert!(e.landmarks.iter().all(|l| l.station == Station::Storage));
    assert!(a.floor().own_map.station(Station::Storage).is_some(), "seen three times: on the map");
    // A frame without a pose shares nothing on the floor, and a peer's landmarks
    // reach the team map only.
    let out = a.handle(Input::Frame(frame("a", 4, true)), ms(400));
    assert!(take_embedding(&out).landmarks.is_empty());
    let peer = EmbeddingMsg {
        landmarks: vec![Landmark { station: Station::Manufacturing, position: [9.0, 9.0], sigma: 0.3 }; 3],
        ..share("b", 4, None, None, None)
    };
    a.handle(Input::Embedding(peer), ms(401));
    assert!(
        a.floor().team_map.station(Station::Manufacturing).is_some()
            && a.floor().own_map.station(Station::Manufacturing).is_none()
    );
}

#[test]
fn a_robot_that_joins_is_sent_the_team_map_and_takes_it_for_what_it_has_not_seen() {
    let set = models();
    let (mut a, mut b) = (engine("a", &set), engine("b", &set));
    let out = a.handle(Input::MemberJoined(id("b")), ms(0));
    assert!(!out.iter().any(|o| matches!(o, Output::Map(_))), "nothing mapped, nothing to send");
    let sighting = |station, x: f32| Landmark { station, position: [x, 9.0], sigma: 0.3 };
    for l in [sighting(Station::Manufacturing, 9.0), sighting(Station::Storage, 2.0)] {
        for _ in 0..3 {
            a.floor.team_map.add(&l, 0);
        }
    }
    b.floor.team_map.borrow(&[None, None, None, Some([50.0, 50.0])]); // heard from another
    let map = |out: Vec<Output>| match out.as_slice() {
        [Output::Map(m)] => m.clone(),
        other => panic!("expected the map alone, got {other:?}"),
    };
    let sent = map(a.handle(Input::MemberJoined(id("c")), ms(1)));
    assert_eq!(sent.robot, id("a"));
    assert_eq!(sent.stations[Station::Manufacturing.index()], Some([9.0, 9.0]));
    assert!(a.handle(Input::MemberJoined(id("c")), ms(2)).is_empty(), "once per join");
    b.handle(Input::Map(sent.clone()), ms(3));
    assert_eq!(b.floor().team_map.station(Station::Storage), Some([2.0, 9.0]));
    assert_eq!(b.floor().team_map.station(Station::Manufacturing), Some([29.5, 29.5]), "the mean of two peers'");
    assert_eq!(b.floor().own_map.stations(), [None; 4], "its own map is its own sightings");
    let echo = MapMsg { robot: id("b"), stations: [Some([7.0, 7.0]), None, None, None], ..sent };
    assert!(b.handle(Input::Map(echo), ms(4)).is_empty());
    assert_eq!(b.floor().team_map.station(Station::Storage), Some([2.0, 9.0]), "its own echo is ignored");
    // A robot that left and comes back is sent the map again.
    a.handle(Input::MemberLeft(id("c")), ms(5));
    map(a.handle(Input::MemberJoined(id("c")), ms(6)));
}

#[test]
fn a_relation_set_votes_from_a_fresh_track_and_says_so() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/relations");
    let set = ModelSet::load(&dir, Backend::Tract, None).unwrap();
    assert_eq!(set.manifest.row, RowLayout::Relations, "the shipped relations set reads relation rows");
    let mut a = engine("a", &set);
    let localised = |tick, seen| DetectionFrame {
        pose: Some(FloorPose { position: [1.0, 2.0], heading: 0.5 }),
        ..frame("a", tick, seen)
    };
    for t in 1..=3 {
        a.handle(Input::Frame(localised(t, true)), ms(100 * t));
    }
    // Tick 4: the worker is not seen, but the track is fresh: announce a vote and vote.
    let out = a.handle(Input::Frame(localised(4, false)), ms(400));
    let e = take_embedding(&out);
    assert!(e.embedding.is_none() && e.worker.is_some() && e.vote.is_some(), "{e:?}");
    assert!(!decisions(&out)[0].steps.is_empty(), "the team still has an answer");
    // Longer than FRESH_TICKS without the worker: the track is stale, no vote.
    let stale = 3 + crate::floor::track::FRESH_TICKS + 1;
    let out = a.handle(Input::Frame(localised(stale, false)), ms(100 * stale));
    let e = take_embedding(&out);
    assert!(e.worker.is_none() && e.vote.is_none());
    // A peer is waited for until its share of the tick comes, with its vote or without.
    let mut b = engine("b", &set);
    b.trust.set_votes_record(&id("b"), 1.0); // established: decides a tick alone
    b.handle(Input::MemberJoined(id("a")), ms(0));
    let from_a = |tick, votes: bool| {
        let vote =
            votes.then(|| VoteMsg { instance: e.instance, ..vote_msg("a", 1, tick, one_step(Station::Assembly)) });
        Input::Embedding(EmbeddingMsg { tick, vote, ..e.clone() })
    };
    b.handle(from_a(15, false), ms(1500)); // a is now an active member
    let out = b.handle(Input::Frame(DetectionFrame { robot: id("b"), ..localised(20, true) }), ms(1900));
    take_vote(&out);
    assert!(decisions(&out).is_empty(), "b waits for a's share of tick 20");
    let d = decisions(&b.handle(from_a(20, true), ms(1901)))[0].clone();
    assert_eq!(d.voters, vec![id("a"), id("b")]);
    b.handle(from_a(21, false), ms(2000));
    let out = b.handle(Input::Frame(DetectionFrame { robot: id("b"), ..localised(21, true) }), ms(2000));
    assert_eq!(decisions(&out)[0].voters, vec![id("b")], "a abstains from tick 21: b decides at once");
}

/// The last row of a collective window at tick `t`, as the GRU reads it.
fn last_row(e: &Engine, t: u64) -> Vec<f32> {
    let mut x = Vec::new();
    e.window.input(t, TemporalModel::Collective, &mut x);
    x.split_off(x.len() - temporal::FACING_ROW_DIM)
}

fn default_set() -> Arc<ModelSet> {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/default");
    let set = ModelSet::load(&dir, Backend::Tract, None).unwrap();
    assert_eq!(set.manifest.row, RowLayout::RelationsFacing);
    set
}

fn localised(robot: &str, tick: u64, seen: bool) -> DetectionFrame {
    DetectionFrame { pose: Some(FloorPose { position: [1.0, 2.0], heading: 0.5 }), ..frame(robot, tick, seen) }
}

#[test]
fn the_collective_reads_the_facing_its_peers_saw() {
    let set = default_set();
    let (mut a, mut b) = (engine("a", &set), engine("b", &set));
    b.handle(Input::MemberJoined(id("a")), ms(0));
    // a sees the worker, b does not: b's team track and facing are a's.
    let mut facing = None;
    for t in 1..=4 {
        let e = take_embedding(&a.handle(Input::Frame(localised("a", t, true)), ms(100 * t)));
        facing = e.facing;
        let e = if t == 4 { e } else { EmbeddingMsg { facing: None, ..e } };
        b.handle(Input::Embedding(e), ms(100 * t));
        let out = b.handle(Input::Frame(localised("b", t, false)), ms(100 * t + 1));
        assert!(take_embedding(&out).facing.is_none(), "b's frame shows no worker");
    }
    assert!(facing.is_some(), "a's frame shows the worker's shoulders: a shares where it faces");
    let (three, four) = (last_row(&b, 3), last_row(&b, 4));
    assert_eq!(three[KEYPOINT_VALUES], 1.0, "b holds the team's track from a's estimate");
    assert_eq!(three[temporal::RELATION_ROW_DIM], 0.0, "a sent no facing for tick 3");
    assert_eq!(four[temporal::RELATION_ROW_DIM], 1.0, "b reads the facing a saw in tick 4");
}

#[test]
fn a_facing_set_reads_where_its_own_frame_shows_the_worker_facing() {
    let set = default_set();
    let mut a = engine("a", &set);
    for t in 1..=3 {
        take_vote(&a.handle(Input::Frame(localised("a", t, true)), ms(100 * t)));
    }
    let row = last_row(&a, 3);
    assert_eq!(row[KEYPOINT_VALUES], 1.0, "the worker is tracked");
    assert_eq!(row[temporal::RELATION_ROW_DIM], 1.0, "and its facing known from the frame");
    // Not seen: the fresh track still votes, but nothing shows where it faces.
    take_vote(&a.handle(Input::Frame(localised("a", 4, false)), ms(400)));
    let row = last_row(&a, 4);
    assert_eq!((row[KEYPOINT_VALUES], row[temporal::RELATION_ROW_DIM]), (1.0, 0.0));
}

#[test]
fn robots_name_the_person_they_both_see_alike_and_one_without_a_pose_names_nobody() {
    let set = models();
    let (mut a, mut b) = (engine("a", &set), engine("b", &set));
    a.handle(Input::MemberJoined(id("b")), ms(0));
    b.handle(Input::MemberJoined(id("a")), ms(0));
    let mut shared = Vec::new();
    for t in 1..=4 {
        let ea = take_embedding(&a.handle(Input::Frame(localised("a", t, true)), ms(100 * t)));
        let eb = take_embedding(&b.handle(Input::Frame(localised("b", t, true)), ms(100 * t + 1)));
        a.handle(Input::Embedding(eb.clone()), ms(100 * t + 2));
        b.handle(Input::Embedding(ea.clone()), ms(100 * t + 2));
        shared = vec![ea.people, eb.people];
    }
    // a, first of the members, named the person at once; b, second, took a's id.
    assert_eq!(shared[0].len(), 1, "one person in view: {shared:?}");
    assert_eq!(shared[0][0].worker, shared[1][0].worker, "b minted an id of its own");
    assert_eq!(a.floor().worker_ids().shared().1, &shared[0][..]);
    // Without a pose nobody is placed on the floor: nobody is named.
    let e = take_embedding(&a.handle(Input::Frame(frame("a", 5, true)), ms(500)));
    assert!(e.people.is_empty() && e.worker.is_none());
}
