//! The rounds: relays, asks and answers, and whose relayed votes count.

use super::*;

fn relaying(robot: &str, set: &Arc<ModelSet>, relay_after: Option<Duration>) -> Engine {
    let mut e = engine(robot, set);
    e.cfg.relay_after = relay_after;
    e
}

/// Three robots that know each other, each having heard from the others.
fn team_of_three(set: &Arc<ModelSet>, relay_after: Option<Duration>) -> Vec<Engine> {
    let mut team: Vec<Engine> = ["a", "b", "c"].iter().map(|r| relaying(r, set, relay_after)).collect();
    for i in 0..3 {
        for j in (0..3).filter(|&j| j != i) {
            let other = team[j].cfg.robot.clone();
            team[i].handle(Input::MemberJoined(other), ms(0));
        }
    }
    let warm: Vec<Vec<Output>> =
        (0..3).map(|i| team[i].handle(Input::Frame(frame(["a", "b", "c"][i], 1, false)), ms(0))).collect();
    // Each hears the others' embeddings.
    for (i, out) in warm.iter().enumerate() {
        for j in (0..3).filter(|&j| j != i) {
            team[j].handle(Input::Embedding(take_embedding(out)), ms(1));
        }
    }
    team
}

/// Tick `t` where all three see the worker and a's share never reaches b directly.
/// Returns each robot's outputs of the tick so far.
fn tick_losing_a_vote_to_b(team: &mut [Engine], t: u64) -> Vec<Vec<Output>> {
    let now = ms(100 * t);
    let mut outs: Vec<Vec<Output>> =
        (0..3).map(|i| team[i].handle(Input::Frame(frame(["a", "b", "c"][i], t, true)), now)).collect();
    let shares: Vec<Input> = outs.iter().map(|o| Input::Embedding(take_embedding(o))).collect();
    for i in 0..3 {
        for (j, e) in shares.iter().enumerate().filter(|(j, _)| *j != i && !(*j == 0 && i == 1)) {
            let said = team[i].handle(e.clone(), now + ms(1 + j as u64));
            outs[i].extend(said);
        }
    }
    outs
}

#[test]
fn relayed_ballots_fill_in_a_vote_lost_on_our_link_and_the_digests_agree() {
    let set = models();
    let mut team = team_of_three(&set, Some(ms(40)));
    let outs = tick_losing_a_vote_to_b(&mut team, 2);
    let (da, dc) = (decisions(&outs[0]), decisions(&outs[2]));
    assert_eq!((da.len(), dc.len()), (1, 1), "a and c hold every vote: they decide at once");
    assert!(decisions(&outs[1]).is_empty(), "b waits for a's vote");
    // Deciding, c relays what it holds; b takes a's vote from it and decides the same.
    let relay = outs[2].iter().find(|o| matches!(o, Output::Ballots(_))).expect("c relays as it decides");
    let Output::Ballots(relay) = relay else { unreachable!() };
    assert_eq!(relay.votes.len(), 3);
    let ob = team[1].handle(Input::Ballots(relay.clone()), ms(215));
    let db = decisions(&ob);
    assert_eq!(db.len(), 1);
    assert_eq!(db[0].decided_by, DecidedBy::AllVoted);
    assert_eq!((db[0].digest, &db[0].steps), (da[0].digest, &da[0].steps));
    assert_eq!(dc[0].digest, da[0].digest);
    assert_eq!(team[1].metrics.relayed_ballots_used, 1);
    // A relay for a decided tick is counted, never applied.
    let mut late = relay.clone();
    late.votes.push(VoteMsg { robot: id("d"), ..late.votes[0].clone() });
    let out = team[1].handle(Input::Ballots(late), ms(230));
    assert!(out.is_empty());
    assert_eq!(team[1].metrics.late_relayed_ballots, 1, "d's vote arrived after b decided without it");
    // a's next embedding carries its verdict: the same digest, nothing counted as differing.
    let compared = team[1].metrics.agreement_compared;
    let next = take_embedding(&team[0].handle(Input::Frame(frame("a", 3, false)), ms(300)));
    assert_eq!(next.verdict, Some(Verdict::of(da[0])));
    team[1].handle(Input::Embedding(next), ms(301));
    let m = &team[1].metrics;
    assert_eq!((m.agreement_compared, m.agreement_same, m.ballot_sets_differ), (compared + 1, compared + 1, 0));
}

#[test]
fn without_relays_a_robot_that_decided_on_fewer_ballots_counts_it() {
    let set = models();
    let mut team = team_of_three(&set, None);
    let outs = tick_losing_a_vote_to_b(&mut team, 2);
    assert!(outs.iter().flatten().all(|o| !matches!(o, Output::Ballots(_))), "relaying is off");
    // c's next embedding, carrying its verdict of tick 2 (all three ballots), reaches b
    // while b still waits for a's vote: it is compared once b decides.
    let from_c = take_embedding(&team[2].handle(Input::Frame(frame("c", 3, false)), ms(250)));
    assert_eq!(from_c.verdict.as_ref().map(|v| (v.tick, v.voters.len())), Some((2, 3)));
    let compared = team[1].metrics.agreement_compared;
    team[1].handle(Input::Embedding(from_c), ms(251));
    assert_eq!(team[1].metrics.agreement_compared, compared, "b has not decided tick 2");
    let ob = team[1].handle(Input::Poll, ms(260));
    let db = decisions(&ob);
    assert_eq!((db.len(), db[0].decided_by, db[0].voters.len()), (1, DecidedBy::Deadline, 2));
    let m = &team[1].metrics;
    assert_eq!((m.agreement_compared, m.ballot_sets_differ, m.decided_on_fewer_ballots), (compared + 1, 1, 1));
    // a's verdict comes after b decided: compared at once. a shares it once.
    let da = decisions(&outs[0])[0].clone();
    assert_ne!(da.digest, db[0].digest);
    let from_a = take_embedding(&team[0].handle(Input::Frame(frame("a", 3, false)), ms(300)));
    assert_eq!(from_a.verdict, Some(Verdict::of(&da)));
    team[1].handle(Input::Embedding(from_a), ms(301));
    let m = &team[1].metrics;
    assert_eq!((m.agreement_compared, m.ballot_sets_differ, m.decided_on_fewer_ballots), (compared + 2, 2, 2));
    let again = take_embedding(&team[0].handle(Input::Frame(frame("a", 4, false)), ms(400)));
    assert_eq!(again.verdict, None, "a decided nothing since: nothing to share");
}

#[test]
fn relays_go_out_at_the_relay_time_when_the_tick_is_still_open() {
    let set = models();
    let mut a = relaying("a", &set, Some(ms(40)));
    a.handle(Input::MemberJoined(id("b")), ms(0));
    a.handle(Input::Embedding(share("b", 0, None, Some(one_step(Station::Workstation)), None)), ms(0));
    a.handle(Input::Poll, ms(99)); // tick 0, opened by b's share, is decided
                                   // b is an active member; a's own frame shows the worker at tick 1, b stays silent.
    let out = a.handle(Input::Frame(frame("a", 1, true)), ms(100));
    assert!(out.iter().all(|o| !matches!(o, Output::Ballots(_))));
    assert_eq!(a.next_deadline(), Some(ms(140)), "the relay comes first");
    let out = a.handle(Input::Poll, ms(140));
    let Some(Output::Ballots(b)) = out.first() else { panic!("a relay at 40 ms: {out:?}") };
    assert_eq!((b.tick, b.votes.len(), &b.votes[0].robot), (1, 1, &id("a")));
    // Still without b's vote, a asks for it, the asks spread to the deadline, then decides.
    let asks = a.cfg.ask_rounds;
    for k in 1..=asks {
        let at = ms(140) + ms(20) * k / (asks + 1);
        assert_eq!(a.next_deadline(), Some(at), "ask {k}");
        assert!(a.handle(Input::Poll, at - ms(1)).is_empty(), "not before its time");
        let out = a.handle(Input::Poll, at);
        assert!(matches!(out.as_slice(), [Output::Ballots(b)] if b.votes.len() == 1), "ask {k}: {out:?}");
    }
    assert_eq!(a.metrics.ballot_asks, u64::from(asks));
    assert_eq!(a.next_deadline(), Some(ms(160)), "no rounds left; the deadline is next");
    let out = a.handle(Input::Poll, ms(160));
    assert!(matches!(out.as_slice(), [Output::Decision(_)]), "{out:?}");
}

/// Hands every Ballots message among `outs[from]` to robot `to`; returns its outputs.
fn hand_ballots(team: &mut [Engine], outs: &[Vec<Output>], from: usize, to: usize, now: Duration) -> Vec<Output> {
    let ballots: Vec<Input> = outs[from]
        .iter()
        .filter_map(|o| if let Output::Ballots(b) = o { Some(Input::Ballots(b.clone())) } else { None })
        .collect();
    ballots.into_iter().flat_map(|b| team[to].handle(b, now)).collect()
}

fn count_ballots(out: &[Output]) -> usize {
    out.iter().filter(|o| matches!(o, Output::Ballots(_))).count()
}

#[test]
fn a_robot_whose_vote_and_relays_were_lost_asks_and_a_peer_that_decided_answers() {
    let set = models();
    let mut team = team_of_three(&set, Some(ms(40)));
    let outs = tick_losing_a_vote_to_b(&mut team, 2);
    let da = decisions(&outs[0])[0].clone();
    // a's and c's relays, sent as they decided, never reach b either. At the relay
    // time b relays what it holds, its own vote and c's: that shows a's is missing.
    let ob = team[1].handle(Input::Poll, ms(240));
    let Some(Output::Ballots(asked)) = ob.first() else { panic!("b relays at 40 ms: {ob:?}") };
    assert_eq!(asked.votes.iter().map(|v| v.robot.as_str()).collect::<Vec<_>>(), ["b", "c"]);
    // a decided tick 2 already; it answers with every vote it holds, a's among them.
    let answer = team[0].handle(Input::Ballots(asked.clone()), ms(241));
    let Some(Output::Ballots(answer)) = answer.first() else { panic!("a answers: {answer:?}") };
    assert_eq!(answer.votes.len(), 3);
    assert_eq!(team[0].metrics.ballot_answers, 1);
    let db = team[1].handle(Input::Ballots(answer.clone()), ms(242));
    let db = decisions(&db);
    assert_eq!(db.len(), 1);
    assert_eq!((db[0].decided_by, db[0].digest, &db[0].steps), (DecidedBy::AllVoted, da.digest, &da.steps));
    // Answers are bounded: a peer asking again and again gets ask_rounds of them.
    let more: usize = (0..5).map(|i| count_ballots(&team[0].handle(Input::Ballots(asked.clone()), ms(243 + i)))).sum();
    assert_eq!(more, (team[0].cfg.ask_rounds - 1) as usize);
    // A relayer that holds nothing the asker lacks does not answer.
    let mut full = answer.clone();
    full.robot = id("b");
    assert!(team[2].handle(Input::Ballots(full), ms(250)).is_empty());
}

#[test]
fn on_links_that_lose_nothing_each_robot_relays_once_and_nobody_asks_or_answers() {
    let set = models();
    let mut team = team_of_three(&set, Some(ms(40)));
    for t in 2..6 {
        let now = ms(100 * t);
        let mut outs: Vec<Vec<Output>> =
            (0..3).map(|i| team[i].handle(Input::Frame(frame(["a", "b", "c"][i], t, true)), now)).collect();
        let shares: Vec<Input> = outs.iter().map(|o| Input::Embedding(take_embedding(o))).collect();
        for i in 0..3 {
            for (j, e) in shares.iter().enumerate().filter(|(j, _)| *j != i) {
                let said = team[i].handle(e.clone(), now + ms(1 + j as u64));
                outs[i].extend(said);
            }
        }
        assert!(outs.iter().all(|o| decisions(o).len() == 1 && count_ballots(o) == 1), "tick {t}: {outs:?}");
        for from in 0..3 {
            for to in (0..3).filter(|&to| to != from) {
                let said = hand_ballots(&mut team, &outs, from, to, now + ms(5));
                assert!(said.is_empty(), "tick {t}: {to} answers {from}'s relay: {said:?}");
            }
        }
        for e in team.iter_mut() {
            assert!(e.handle(Input::Poll, now + ms(99)).is_empty());
        }
    }
    assert!(team.iter().all(|e| e.metrics.ballot_asks == 0 && e.metrics.ballot_answers == 0));
}

#[test]
fn a_few_members_relay_each_tick_a_different_few_each_time() {
    let set = models();
    let names = ["a", "b", "c", "d", "e", "f"];
    let mut team: Vec<Engine> = names
        .iter()
        .map(|r| {
            let mut e = relaying(r, &set, Some(ms(40)));
            e.cfg.relayers = 2;
            for other in names.iter().filter(|o| *o != r) {
                e.live.insert(id(other));
                e.active.insert(id(other));
            }
            e
        })
        .collect();
    let mut relayed = [0; 6];
    for t in 0..600 {
        let relayers: Vec<usize> = (0..6).filter(|&i| team[i].relays(t)).collect();
        assert_eq!(relayers.len(), 2, "tick {t}: every robot counts the same members, so exactly two relay");
        relayers.iter().for_each(|&i| relayed[i] += 1);
    }
    // 200 ticks each if the load is spread evenly (a binomial's sd is 11.5).
    assert!(relayed.iter().all(|n| (150..=250).contains(n)), "{relayed:?}");
    // A member we have not heard from yet is not counted: we relay whenever we did,
    // and on the ticks it ranked ahead of us too.
    let before: Vec<bool> = (0..600).map(|t| team[0].relays(t)).collect();
    team[0].active.remove(&id("f"));
    let after: Vec<bool> = (0..600).map(|t| team[0].relays(t)).collect();
    assert!(before.iter().zip(&after).all(|(b, a)| !b || *a));
    assert!(after.iter().filter(|a| **a).count() > relayed[0]);
    // No more members than relayers: every one relays, every tick.
    team[1].cfg.relayers = 6;
    assert!((0..100).all(|t| team[1].relays(t)));
}

#[test]
fn a_relayed_vote_counts_only_for_its_origins_live_instance_and_its_own_copy_wins() {
    let set = models();
    let mut a = engine("a", &set);
    for p in ["b", "c"] {
        a.handle(Input::MemberJoined(id(p)), ms(0));
    }
    // b and c speak directly (instance 2); tick 1 is decided. b is established, so its
    // vote alone decides a tick.
    a.trust.set_votes_record(&id("b"), 1.0);
    a.handle(abstaining("b", 1), ms(100));
    a.handle(abstaining("c", 1), ms(100));
    a.handle(Input::Frame(frame("a", 1, false)), ms(100));
    // Tick 2: c relays a vote of b's earlier run (instance 9) and one of x, no member.
    let old_b = vote_msg("b", 9, 2, one_step(Station::Assembly));
    let stranger = vote_msg("x", 2, 2, one_step(Station::Assembly));
    a.handle(
        Input::Ballots(BallotsMsg { robot: id("c"), instance: 2, tick: 2, votes: vec![old_b, stranger] }),
        ms(201),
    );
    assert_eq!(a.metrics.foreign_votes, 2);
    // c relays b's live vote, changed; then b's own copy arrives, then another.
    let changed = vote_msg("b", 2, 2, one_step(Station::Manufacturing));
    a.handle(Input::Ballots(BallotsMsg { robot: id("c"), instance: 2, tick: 2, votes: vec![changed] }), ms(202));
    assert_eq!(a.metrics.relayed_ballots_used, 1);
    a.handle(Input::Embedding(share("b", 2, None, Some(one_step(Station::Workstation)), None)), ms(203));
    a.handle(Input::Embedding(share("b", 2, None, Some(one_step(Station::Storage)), None)), ms(204));
    a.handle(abstaining("c", 2), ms(205));
    let out = a.handle(Input::Frame(frame("a", 2, false)), ms(206));
    let d = decisions(&out)[0];
    assert_eq!(d.voters, vec![id("b")]);
    assert_eq!(d.steps[0].class, Station::Workstation, "b's own first copy, not the relayed one nor its second");
}
