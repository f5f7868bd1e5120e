//! Trust: learned from the ballots, weighing them.

use super::*;

/// Robot a, which does not see the worker, hears b and c vote 1 and d vote 3 for
/// 150 ticks: a decides from their votes and learns whom to trust.
fn a_after_d_kept_disagreeing(set: &Arc<ModelSet>) -> Engine {
    let mut a = engine("a", set);
    for p in ["b", "c", "d"] {
        a.handle(Input::MemberJoined(id(p)), ms(0));
    }
    for t in 1..=150u64 {
        let now = ms(100 * t);
        a.handle(Input::Frame(frame("a", t, false)), now);
        for (p, class) in [("b", Station::Workstation), ("c", Station::Workstation), ("d", Station::Manufacturing)] {
            let steps = vec![StepVote { class, confidence: 0.8 }; 3];
            a.handle(Input::Embedding(share(p, t, None, Some(steps), None)), now);
        }
        a.handle(Input::Poll, now + ms(99));
    }
    a
}

#[test]
fn a_peer_that_keeps_disagreeing_loses_our_trust_and_leaves_our_fusion() {
    let set = models();
    let a = a_after_d_kept_disagreeing(&set);
    assert_eq!(a.metrics.decisions, 150);
    let trust = a.trust();
    // d, judged by b and c together on ticks 2..=150 (on tick 1 nobody had been
    // heard from yet), lost 2/100 of its trust each time: 0.5 × 0.98^149, floored
    // at 0.1; b and c are not judged (each has one other agreeing, as trusted as
    // itself, and d against it) and keep what a voter starts with
    assert_eq!(trust[&id("d")], 0.1, "{trust:?}");
    assert_eq!((trust[&id("b")], trust[&id("c")]), (UNJUDGED, UNJUDGED), "{trust:?}");
    assert!(!trust.contains_key(&id("a")), "a never voted: not known as a voter");

    // Tick 152: a sees the worker and fuses its peers' latest embeddings (of tick
    // 151) into its row. What d sent changes nothing; what b sent does.
    let vote_with = |b: f32, d: f32| {
        let mut a = a_after_d_kept_disagreeing(&set);
        for (p, x) in [("b", b), ("c", 0.3), ("d", d)] {
            a.handle(Input::Embedding(share(p, 151, Some(x), None, None)), ms(15_100));
        }
        take_vote(&a.handle(Input::Frame(frame("a", 152, true)), ms(15_200)))
    };
    assert_eq!(vote_with(0.3, -0.9).steps, vote_with(0.3, 0.9).steps, "d is not fused");
    assert_ne!(vote_with(-0.9, 0.3).steps, vote_with(0.9, 0.3).steps, "b is");
}

#[test]
fn a_peer_that_places_the_worker_where_nobody_else_does_loses_our_trust() {
    let set = models();
    let mut a = engine("a", &set);
    for p in ["b", "c", "d"] {
        a.handle(Input::MemberJoined(id(p)), ms(0));
    }
    let at = |x: f32| WorkerEstimate { position: [x, 2.0], velocity: [0.0; 2], covariance: [0.04, 0.0, 0.5] };
    for t in 1..=100u64 {
        let now = ms(100 * t);
        a.handle(Input::Frame(frame("a", t, false)), now);
        // b and c place the worker 0.3 m apart, d 4 m away; all three vote alike
        for (p, x) in [("b", 5.0), ("c", 5.3), ("d", 9.0)] {
            let mut e = share(p, t, None, Some(one_step(Station::Assembly)), None);
            e.vote.as_mut().unwrap().worker = Some(at(x));
            a.handle(Input::Embedding(e), now);
        }
        a.handle(Input::Poll, now + ms(99));
    }
    let trust = a.trust();
    // judged on the ballots of ticks 1..=98: a tick is learned from two ticks after it
    // is decided, with the votes that came after the decision (tick 1, decided before
    // a heard anyone) included. Every vote agrees (1 − 0.5 × 0.99^98 each), d's worker
    // estimate never does (0.98^98)
    let votes = 1.0 - 0.5 * 0.99f32.powi(98);
    assert!((trust[&id("d")] - votes * 0.98f32.powi(98)).abs() < 1e-3, "{trust:?}");
    assert!((trust[&id("b")] - votes).abs() < 1e-3 && (trust[&id("c")] - votes).abs() < 1e-3, "{trust:?}");
    assert_eq!(a.metrics.decisions, 100);
}

/// Robot `a` hears b and c vote `Workstation` at 0.8 every tick and d vote
/// `Manufacturing` at confidence 1 claiming the fullest view and visibility: a
/// confident liar. Returns a's decisions at t.
fn with_a_confident_liar(a: &mut Engine, ticks: std::ops::RangeInclusive<u64>) -> Vec<Option<Station>> {
    let mut decided = Vec::new();
    let me = a.cfg.robot.to_string();
    for t in ticks {
        let now = ms(100 * t);
        a.handle(Input::Frame(frame(&me, t, false)), now);
        for (p, class, confidence) in
            [("b", Station::Workstation, 0.8), ("c", Station::Workstation, 0.8), ("d", Station::Manufacturing, 1.0)]
        {
            let mut e = share(p, t, None, Some(vec![StepVote { class, confidence }; 3]), None);
            if p == "d" {
                let v = e.vote.as_mut().unwrap();
                (v.visibility, v.quality) = (10_000, 1.0);
            }
            let out = a.handle(Input::Embedding(e), now + ms(1));
            decided.extend(decisions(&out).iter().map(|d| d.steps.first().map(|s| s.class)));
        }
    }
    decided
}

#[test]
fn a_confident_liar_weighs_what_we_learned_of_it_and_stops_counting() {
    let set = models();
    let mut a = engine("a", &set);
    for p in ["b", "c", "d"] {
        a.handle(Input::MemberJoined(id(p)), ms(0));
    }
    let decided = with_a_confident_liar(&mut a, 1..=120);
    // As trusted as b and c at first, d outweighs both (e(1) = ln 297 = 5.7 against
    // 2 × ln 12 = 5.0), until b and c together judge it wrong a few times.
    let d = a.trust()[&id("d")];
    assert!(d < 0.5, "d disagreed with b and c for 12 s: {d}");
    assert!(a.metrics.votes_set_aside > 0, "d's votes are set aside once its trust falls below 0.5");
    // From its 4th second on (trust below 0.5), d decides nothing for the team.
    assert!(decided[70..].iter().all(|c| *c == Some(Station::Workstation)), "{:?}", &decided[70..]);
    let last = a.last_decision().unwrap();
    assert_eq!(last.voters, vec![id("b"), id("c")], "d is not counted");
    assert!(a.trust()[&id("b")] >= UNJUDGED, "the honest keep their trust: {:?}", a.trust());
}

#[test]
fn robots_that_counted_the_same_ballots_weigh_them_alike() {
    let set = models();
    let (mut a, mut e) = (engine("a", &set), engine("e", &set));
    for x in [&mut a, &mut e] {
        for p in ["b", "c", "d"] {
            x.handle(Input::MemberJoined(id(p)), ms(0));
        }
    }
    let (da, de) = (with_a_confident_liar(&mut a, 1..=90), with_a_confident_liar(&mut e, 1..=90));
    assert_eq!(da, de);
    let (ta, te) = (a.trust(), e.trust());
    assert_eq!(ta, te);
    assert!(ta[&id("d")] < 0.5, "{ta:?}");
    assert_eq!(a.last_decision().unwrap().digest, e.last_decision().unwrap().digest);
}

/// Robot `e` loses the liar d's share on every fifth tick and decides it at the
/// deadline without d's vote, which a relay of b's brings in only after: it still
/// learns from that tick what `a`, which heard everything, learns, so the two hold the
/// same trust of d while it is still falling.
#[test]
fn robots_that_counted_different_ballots_for_a_moment_still_learn_alike() {
    let set = models();
    let (mut a, mut e) = (engine("a", &set), engine("e", &set));
    for x in [&mut a, &mut e] {
        for p in ["b", "c", "d"] {
            x.handle(Input::MemberJoined(id(p)), ms(0));
        }
    }
    with_a_confident_liar(&mut a, 1..=40);
    let honest = || vec![StepVote { class: Station::Workstation, confidence: 0.8 }; 3];
    let mut differed = 0;
    for t in 1..=40u64 {
        let now = ms(100 * t);
        e.handle(Input::Frame(frame("e", t, false)), now);
        for p in ["b", "c"] {
            e.handle(Input::Embedding(share(p, t, None, Some(honest()), None)), now + ms(1));
        }
        let mut liar =
            share("d", t, None, Some(vec![StepVote { class: Station::Manufacturing, confidence: 1.0 }; 3]), None);
        let v = liar.vote.as_mut().unwrap();
        (v.visibility, v.quality) = (10_000, 1.0);
        if t % 5 == 0 {
            let out = e.handle(Input::Poll, now + ms(61));
            assert!(decisions(&out).iter().all(|d| !d.voters.contains(&id("d"))), "decided without d");
            differed += 1;
            let relayed = BallotsMsg { robot: id("b"), instance: 2, tick: t, votes: vec![liar.vote.unwrap()] };
            e.handle(Input::Ballots(relayed), now + ms(80));
        } else {
            e.handle(Input::Embedding(liar), now + ms(1));
        }
    }
    assert_eq!(differed, 8);
    let (ta, te) = (a.trust(), e.trust());
    assert!(ta[&id("d")] > 0.1 && ta[&id("d")] < 0.5, "still falling: {ta:?}");
    assert_eq!(ta, te, "the late votes joined what e learned");
}

/// Robot a, which does not see the worker, hears b — honest, placing the worker on its
/// way from the workstation to assembly and then standing there — and d, naming
/// manufacturing every tick, sure of it and placing the worker nowhere. Neither was ever
/// judged, and nobody else votes, so their ballots cannot tell who is wrong.
#[test]
fn a_liar_beside_one_honest_voter_is_outweighed_by_what_we_check_and_judged_in_hindsight() {
    use crate::floor::StationMap;
    let set = models();
    let mut a = engine("a", &set);
    for p in ["b", "d"] {
        a.handle(Input::MemberJoined(id(p)), ms(0));
    }
    // The team's map: storage, workstation, assembly, manufacturing.
    let mut team = StationMap::default();
    team.borrow(&[Some([0.0, -8.0]), Some([0.0, 0.0]), Some([8.0, 0.0]), Some([8.0, 8.0])]);
    a.adopt_maps(StationMap::default(), team);
    let worker_at = |t: u64| {
        let x = (0.2 * t as f32).min(8.0); // walks 2 m/s, stands at assembly from tick 40
        WorkerEstimate { position: [x, 0.0], velocity: [0.0; 2], covariance: [0.04, 0.0, 0.5] }
    };
    let sure = |class| vec![StepVote { class, confidence: 1.0 }; 3];
    let tick = |a: &mut Engine, t: u64, b_votes: bool, d_votes: bool| {
        let now = ms(100 * t);
        let honest = b_votes.then(|| vec![StepVote { class: Station::Assembly, confidence: 0.7 }; 3]);
        let mut from_b = share("b", t, None, honest, Some(worker_at(t)));
        if let Some(v) = from_b.vote.as_mut() {
            v.worker = Some(worker_at(t));
        }
        let from_d = share("d", t, None, d_votes.then(|| sure(Station::Manufacturing)), None);
        let mut out = a.handle(Input::Embedding(from_b), now);
        out.extend(a.handle(Input::Embedding(from_d), now));
        out.extend(a.handle(Input::Frame(frame("a", t, false)), now));
        out.extend(a.handle(Input::Poll, now + ms(99)));
        decisions(&out).first().map(|d| (d.voters.clone(), d.steps.first().map(|s| s.class)))
    };
    // Both vote: d's vote, sure as it is, weighs a tenth of its claim beside b's, which
    // places the worker.
    let (voters, class) = tick(&mut a, 1, true, true).expect("decided");
    assert_eq!((voters, class), (vec![id("b"), id("d")], Some(Station::Assembly)));
    // d alone, while b (trusted as much, not established either) is live: no class.
    assert_eq!(tick(&mut a, 2, false, true), Some((vec![], None)), "an unjudged voter decides no tick alone");
    assert_eq!(a.metrics.lone_stranger_ticks, 1, "and /metrics counts the tick left so");
    for t in 3..=60 {
        tick(&mut a, t, true, true);
    }
    // The worker stood at assembly from tick 40: every vote since tick 1 is judged.
    let trust = a.trust();
    assert!(trust[&id("d")] < 0.3 && !a.trust.counts(&id("d")), "d was always wrong: {trust:?}");
    assert!(a.trust.established(&id("b")), "b was right: {trust:?}");
    assert_eq!(tick(&mut a, 61, true, false), Some((vec![id("b")], Some(Station::Assembly))), "b decides alone now");
    assert_eq!(tick(&mut a, 62, false, true), Some((vec![], None)), "d never does");
}
