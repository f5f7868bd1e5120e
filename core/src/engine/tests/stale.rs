//! Feeds that repeat themselves, ours and a peer's.

use super::*;

#[test]
fn a_frozen_camera_stops_voting_until_it_changes() {
    let set = models();
    let mut a = engine("a", &set);
    let frozen = frame("a", 1, true);
    for t in 1..=4 {
        let out = a.handle(
            Input::Frame(DetectionFrame { capture_us: DetectionFrame::capture_at_tick(t), ..frozen.clone() }),
            ms(100 * t),
        );
        take_vote(&out);
    }
    assert!(!a.feed_is_stale());
    for t in 5..=7 {
        let out = a.handle(
            Input::Frame(DetectionFrame { capture_us: DetectionFrame::capture_at_tick(t), ..frozen.clone() }),
            ms(100 * t),
        );
        let e = take_embedding(&out);
        assert!(e.embedding.is_none() && e.vote.is_none() && e.visibility == 0 && e.worker.is_none(), "{e:?}");
        assert!(decisions(&out)[0].steps.is_empty());
    }
    assert!(a.feed_is_stale());
    assert_eq!(a.metrics.repeated_frames, 3);
    let out = a.handle(Input::Frame(frame("a", 8, true)), ms(800));
    take_vote(&out);
    assert!(!a.feed_is_stale(), "the feed changed: voting again");
}

#[test]
fn a_camera_playing_back_a_clip_stops_voting_once_the_clip_comes_round() {
    let set = models();
    let mut a = engine("a", &set);
    let clip: Vec<DetectionFrame> = (1..=20).map(|t| frame("a", t, true)).collect();
    for t in 1..=20u64 {
        take_vote(&a.handle(Input::Frame(frame("a", t, true)), ms(100 * t)));
    }
    // From tick 21 it shows its first 20 frames again, each stamped with the tick.
    for t in 21..=40u64 {
        let old = &clip[(t as usize - 21) % clip.len()];
        let replayed = DetectionFrame { capture_us: DetectionFrame::capture_at_tick(t), ..old.clone() };
        let e = take_embedding(&a.handle(Input::Frame(replayed), ms(100 * t)));
        // stale after 5: tick 20's new frame and the four shown before, from tick 24
        assert_eq!(e.vote.is_some(), t < 24, "tick {t}");
    }
    assert!(a.feed_is_stale());
    take_vote(&a.handle(Input::Frame(frame("a", 41, true)), ms(4100)));
}

#[test]
fn a_peer_whose_embedding_repeats_is_heard_as_abstaining() {
    let set = models();
    let mut b = engine("b", &set);
    b.trust.set_votes_record(&id("b"), 1.0); // established: decides a tick alone
    b.handle(Input::MemberJoined(id("a")), ms(0));
    let frozen = take_embedding(&engine("a", &set).handle(Input::Frame(frame("a", 1, true)), ms(100)));
    let vote_of_a = |tick| VoteMsg {
        visibility: 9,
        ..vote_msg("a", 1, tick, vec![StepVote { class: Station::Manufacturing, confidence: 1.0 }; 21])
    };
    for t in 1..=7u64 {
        let now = ms(100 * t);
        b.handle(Input::Embedding(EmbeddingMsg { tick: t, vote: Some(vote_of_a(t)), ..frozen.clone() }), now);
        let out = b.handle(Input::Frame(frame("b", t, true)), now);
        let mine = take_vote(&out);
        let d = decisions(&out);
        if t < 5 {
            assert_eq!(d[0].voters, vec![id("a"), id("b")], "tick {t}: a's vote counts");
        } else {
            assert_eq!(d[0].voters, vec![id("b")], "tick {t}: a's feed repeats itself, its vote is left out");
            assert_eq!(d[0].steps[0].class, mine.steps[0].class);
        }
    }
    assert_eq!(b.stale_peers(), vec![id("a")]);
    assert_eq!(b.metrics.stale_peer_messages, 3, "three shares left out");
    let moving = take_embedding(&engine("a", &set).handle(Input::Frame(frame("a", 8, true)), ms(800)));
    b.handle(Input::Embedding(moving), ms(800));
    assert!(b.stale_peers().is_empty(), "a's feed moves again");
}
