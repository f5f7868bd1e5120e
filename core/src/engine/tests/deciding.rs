//! Deciding: waiting for the members that vote, deadlines, membership, determinism.

use super::*;

#[test]
fn a_lone_robot_decides_each_tick_at_once() {
    let set = models();
    let mut e = engine("a", &set);
    let out = e.handle(Input::Frame(frame("a", 1, true)), ms(0));
    assert!(take_embedding(&out).embedding.is_some());
    let v = take_vote(&out);
    assert_eq!(v.steps.len(), set.manifest.horizon + 1);
    let d = decisions(&out);
    assert_eq!(d.len(), 1);
    assert_eq!(d[0].decided_by, DecidedBy::AllVoted);
    assert_eq!(d[0].steps[0].class, v.steps[0].class);
    assert_eq!(d[0].voters, vec![id("a")]);
}

#[test]
fn a_robot_that_does_not_see_the_worker_says_so_and_still_decides() {
    let set = models();
    let mut e = engine("a", &set);
    let out = e.handle(Input::Frame(frame("a", 1, false)), ms(0));
    let e = take_embedding(&out);
    assert_eq!((e.embedding, e.vote), (None, None));
    assert!(out.iter().all(|o| !matches!(o, Output::Vote(_))));
    assert!(decisions(&out)[0].steps.is_empty());
}

#[test]
fn two_robots_wait_for_each_other_and_agree() {
    let set = models();
    let (mut a, mut b) = (engine("a", &set), engine("b", &set));
    for (x, other) in [(&mut a, "b"), (&mut b, "a")] {
        x.handle(Input::MemberJoined(id(other)), ms(0));
    }
    // Peers heard from before: both are active members.
    let warm_a = a.handle(Input::Frame(frame("a", 1, true)), ms(0));
    let warm_b = b.handle(Input::Frame(frame("b", 1, true)), ms(0));
    // a has not heard from b yet: it decides alone at once; so does b.
    assert_eq!(decisions(&warm_a).len(), 1);
    assert_eq!(decisions(&warm_b).len(), 1);

    // Tick 2: now both are active; each votes at once and decides on hearing the other.
    let out_a = a.handle(Input::Embedding(take_embedding(&warm_b)), ms(1)); // late for tick 1
    assert!(out_a.is_empty());
    assert_eq!(a.metrics.late_messages, 1);
    b.handle(Input::Embedding(take_embedding(&warm_a)), ms(1));
    let oa = a.handle(Input::Frame(frame("a", 2, true)), ms(100));
    let ob = b.handle(Input::Frame(frame("b", 2, true)), ms(100));
    take_vote(&oa);
    assert!(decisions(&oa).is_empty(), "a must wait for b's share of the tick");
    let da = a.handle(Input::Embedding(take_embedding(&ob)), ms(101));
    let db = b.handle(Input::Embedding(take_embedding(&oa)), ms(101));
    let (da, db) = (decisions(&da)[0], decisions(&db)[0]);
    assert_eq!(da.steps, db.steps, "same votes, same decision");
    assert_eq!(da.voters, vec![id("a"), id("b")]);
    assert_eq!(da.decided_by, DecidedBy::AllVoted);
}

#[test]
fn a_silent_peer_is_waited_for_only_until_the_deadline() {
    let set = models();
    let mut a = engine("a", &set);
    a.handle(Input::MemberJoined(id("b")), ms(0));
    a.handle(Input::Frame(frame("a", 1, true)), ms(100));
    a.handle(abstaining("b", 1), ms(101));
    let out = a.handle(Input::Frame(frame("a", 2, true)), ms(200));
    take_vote(&out);
    assert!(decisions(&out).is_empty());
    assert_eq!(a.next_deadline(), Some(ms(260)));
    assert!(a.handle(Input::Poll, ms(259)).is_empty());
    let out = a.handle(Input::Poll, ms(260));
    assert_eq!(decisions(&out)[0].decided_by, DecidedBy::Deadline);
    assert_eq!(a.metrics.decisions_by_deadline, 1);
}

#[test]
fn a_peer_that_leaves_is_not_waited_for_and_an_unseeing_peer_need_not_vote() {
    let set = models();
    let mut a = engine("a", &set);
    a.handle(Input::Frame(frame("a", 1, true)), ms(0));
    for r in ["b", "c"] {
        a.handle(Input::MemberJoined(id(r)), ms(0));
        a.handle(abstaining(r, 1), ms(0));
    }
    take_vote(&a.handle(Input::Frame(frame("a", 2, true)), ms(100)));
    // c does not see the worker: its vote is not expected.
    assert!(decisions(&a.handle(abstaining("c", 2), ms(101))).is_empty(), "b has not been heard");
    let out = a.handle(Input::MemberLeft(id("b")), ms(102));
    let d = decisions(&out);
    assert_eq!(d[0].decided_by, DecidedBy::AllVoted);
    assert_eq!(d[0].live_members, 2);
}

#[test]
fn a_second_daemon_with_our_id_is_detected() {
    let set = models();
    let mut a = engine("a", &set);
    let ours = |instance| Input::Embedding(EmbeddingMsg { instance, ..share("a", 5, None, None, None) });
    a.handle(ours(1), ms(500));
    assert!(a.duplicates.is_empty(), "our own echo is not a clash");
    a.handle(ours(2), ms(500));
    assert_eq!(a.duplicates.iter().copied().collect::<Vec<_>>(), vec![2]);
    assert_eq!(a.metrics.duplicate_id_messages, 1);
}

#[test]
fn same_inputs_same_outputs() {
    let set = models();
    let run = || {
        let mut e = engine("a", &set);
        let mut all = Vec::new();
        for t in 0..30 {
            all.extend(e.handle(Input::Frame(frame("a", t, t % 7 != 3)), ms(t * 100)));
        }
        all
    };
    assert_eq!(run(), run());
}
