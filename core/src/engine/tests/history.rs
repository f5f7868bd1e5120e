//! A newcomer learns whom the team trusts from its peers' histories.

use super::*;

/// Veteran `a` hears b, c and d vote assembly on ticks `ticks` (it does not see the
/// worker itself), so it has seen all three agree.
fn veteran_of(ticks: std::ops::RangeInclusive<u64>, set: &Arc<ModelSet>) -> Engine {
    let mut a = engine("a", set);
    for p in ["b", "c", "d"] {
        a.handle(Input::MemberJoined(id(p)), ms(0));
    }
    for t in ticks {
        let now = ms(100 * t);
        for p in ["b", "c", "d"] {
            a.handle(Input::Embedding(share(p, t, None, Some(one_step(Station::Assembly)), None)), now);
        }
        a.handle(Input::Frame(frame("a", t, false)), now);
        a.handle(Input::Poll, now + ms(99));
    }
    a
}

/// A robot that joins at `now`, with the members a, b, c and d.
fn newcomer(set: &Arc<ModelSet>, now: Duration) -> Engine {
    let mut n = engine("n", set);
    for p in ["a", "b", "c", "d"] {
        n.handle(Input::MemberJoined(id(p)), now);
    }
    n
}

/// Tick `t` on which only b votes (workstation): what `e` publishes of it.
fn only_b_votes_out(e: &mut Engine, t: u64) -> Vec<Output> {
    let now = ms(100 * t);
    let me = e.config().robot.as_str().to_owned();
    let mut out = e.handle(Input::Embedding(share("b", t, None, Some(one_step(Station::Workstation)), None)), now);
    for p in ["a", "c", "d", "n"].into_iter().filter(|p| *p != me) {
        out.extend(e.handle(abstaining(p, t), now));
    }
    out.extend(e.handle(Input::Frame(frame(&me, t, false)), now));
    out.extend(e.handle(Input::Poll, now + ms(99)));
    out
}

/// Tick `t` on which only b votes (workstation): what `e` decides.
fn only_b_votes(e: &mut Engine, t: u64) -> (Vec<RobotId>, Option<Station>) {
    let out = only_b_votes_out(e, t);
    let d = decisions(&out).first().copied().cloned().expect("decided");
    (d.voters, d.steps.first().map(|s| s.class))
}

/// `n`, withholding its decisions for up to a second while it catches up.
fn catching_up(mut n: Engine) -> Engine {
    n.cfg.catch_up = Duration::from_secs(1);
    n
}

/// Whether `e` published a decision of tick `t` (b voting alone).
fn publishes(e: &mut Engine, t: u64) -> bool {
    !decisions(&only_b_votes_out(e, t)).is_empty()
}

/// `e` hears a's share of tick `t`, naming a's decision of tick `decided`.
fn hears_a_decided(e: &mut Engine, t: u64, decided: u64) {
    let mut s = share("a", t, None, None, None);
    s.verdict = Some(Verdict { tick: decided, class: None, voters: vec![], digest: 0 });
    e.handle(Input::Embedding(s), ms(100 * t));
}

/// `e` hears that a decided tick 20: the team was at work a second before a robot that
/// came at tick 31.
fn hears_a_team_at_work(e: &mut Engine, t: u64) {
    hears_a_decided(e, t, 20);
}

fn history_of(out: &[Output]) -> Option<HistoryMsg> {
    out.iter().find_map(|o| if let Output::History(h) = o { Some(h.clone()) } else { None })
}

/// After its history, a newcomer counts b alone as its peers do; without it, it
/// decides the tick without a class while they name b's station.
#[test]
fn a_newcomer_taught_the_teams_history_decides_a_lone_trusted_voters_tick_as_its_peers_do() {
    let set = models();
    let mut a = veteran_of(1..=30, &set);
    let joined = ms(3100);
    assert_eq!(
        history_of(&a.handle(Input::MemberJoined(id("n")), joined)),
        None,
        "a member that comes is sent nothing"
    );

    // The newcomer asks as soon as it sees a member, and a answers.
    let mut taught = engine("n", &set);
    let ask = history_of(&taught.handle(Input::MemberJoined(id("a")), joined)).expect("the newcomer asks");
    assert_eq!((ask.lessons.len(), ask.lessons[0].votes.len()), (1, 0), "an ask: one lesson without votes");
    let h = history_of(&a.handle(Input::History(ask.clone()), joined)).expect("a tells the newcomer its lessons");
    assert!(
        h.lessons.len() >= 25 && h.lessons.iter().all(|l| l.tick < ask.lessons[0].tick),
        "{} lessons",
        h.lessons.len()
    );
    assert_eq!(a.metrics.histories_sent, 1);
    assert_eq!(history_of(&a.handle(Input::History(ask), joined + ms(500))), None, "one answer a second per asker");
    for p in ["b", "c", "d"] {
        taught.handle(Input::MemberJoined(id(p)), joined);
    }
    taught.handle(Input::History(h), joined);
    assert!(taught.metrics.history_votes_learned >= 75, "{}", taught.metrics.history_votes_learned);
    let mut untaught = newcomer(&set, joined);

    let team = (vec![id("b")], Some(Station::Workstation));
    assert_eq!(only_b_votes(&mut a, 32), team, "b, seen agreeing, decides alone for its peers");
    assert_eq!(only_b_votes(&mut taught, 32), team, "and for the newcomer that learned what they saw");
    assert_eq!(
        only_b_votes(&mut untaught, 32),
        (vec![], None),
        "a newcomer that did not leaves the tick without a class"
    );
    // Taught, it asks no more; untaught, it asks again a second later, three times at most.
    assert_eq!(history_of(&taught.handle(Input::Poll, ms(5000))), None);
    let asked = |e: &mut Engine, at: u64| history_of(&e.handle(Input::Poll, ms(at))).is_some();
    assert_eq!([4200, 4300, 5300, 6400].map(|at| asked(&mut untaught, at)), [true, false, true, false]);
    assert_eq!(untaught.metrics.histories_asked, 3);
}

/// Robots that started together have nothing to teach each other: asks go unanswered.
/// One that was deciding before the asked tick but learned nothing answers with a
/// history of no lessons ("nothing came before").
#[test]
fn robots_that_started_together_answer_no_asks_and_one_that_learned_nothing_says_so() {
    let set = models();
    let mut a = veteran_of(1..=30, &set);
    // b asks what came before tick 1, the first it decided as a did.
    let ask = |t: u64| HistoryMsg { robot: id("b"), instance: 2, lessons: vec![Lesson { tick: t, votes: vec![] }] };
    assert_eq!(history_of(&a.handle(Input::History(ask(1)), ms(3100))), None);
    assert_eq!(a.metrics.histories_sent, 0);

    // e decided ticks 1 to 30 without a vote from anyone: it learned no lesson.
    let mut e = engine("e", &set);
    e.handle(Input::MemberJoined(id("b")), ms(0));
    for t in 1..=30 {
        e.handle(abstaining("b", t), ms(100 * t));
        e.handle(Input::Frame(frame("e", t, false)), ms(100 * t));
    }
    assert!(e.metrics.decisions >= 29, "{}", e.metrics.decisions);
    let h = history_of(&e.handle(Input::History(ask(31)), ms(3100))).expect("an answer");
    assert!(h.lessons.is_empty(), "{} lessons", h.lessons.len());
}

/// Until the team's history teaches it, a newcomer decides ticks without publishing
/// them (it would leave a lone trusted voter's tick without a class where its peers
/// name the station); once taught, it publishes what they do.
#[test]
fn a_newcomer_withholds_its_decisions_until_the_teams_history_taught_it() {
    let set = models();
    let mut a = veteran_of(1..=30, &set);
    let joined = ms(3100);
    let mut n = catching_up(engine("n", &set));
    let ask = history_of(&n.handle(Input::MemberJoined(id("a")), joined)).expect("the newcomer asks");
    for p in ["b", "c", "d"] {
        n.handle(Input::MemberJoined(id(p)), joined);
    }
    a.handle(Input::MemberJoined(id("n")), joined);
    let h = history_of(&a.handle(Input::History(ask), joined)).expect("a answers");

    hears_a_team_at_work(&mut n, 32);
    assert!(!publishes(&mut n, 32), "withheld while untaught");
    assert!(n.is_catching_up());
    assert_eq!((n.metrics.decisions, n.metrics.decisions_withheld), (0, 1));
    n.handle(Input::History(h), ms(3300));
    let out = only_b_votes_out(&mut n, 33);
    let d = decisions(&out);
    assert_eq!(d.len(), 1, "taught, it publishes");
    assert_eq!((d[0].voters.clone(), d[0].steps.first().map(|s| s.class)), (vec![id("b")], Some(Station::Workstation)));
    assert!(!n.is_catching_up());
    assert_eq!(n.metrics.decisions, 1);
}

/// A newcomer publishes as soon as every member that tells it answered (here all
/// four), even when they had nothing to tell.
#[test]
fn a_newcomer_told_nothing_came_before_by_every_teller_publishes_at_once() {
    let set = models();
    let mut n = catching_up(newcomer(&set, ms(3100)));
    hears_a_team_at_work(&mut n, 32);
    let nothing = |r: &str| Input::History(HistoryMsg { robot: id(r), instance: 2, lessons: vec![] });
    for p in ["a", "b", "c"] {
        n.handle(nothing(p), ms(3100));
    }
    assert!(!publishes(&mut n, 32), "d has not answered");
    n.handle(nothing("d"), ms(3300));
    assert!(publishes(&mut n, 33));
    assert_eq!(n.metrics.histories_ignored, 0, "an answer of nothing is an answer");
}

/// No peer can keep a newcomer silent by not answering: it publishes once
/// `catch_up` has passed since its first ask.
#[test]
fn a_newcomer_nobody_answers_publishes_once_its_catch_up_time_passed() {
    let set = models();
    let mut n = catching_up(newcomer(&set, ms(3100)));
    hears_a_team_at_work(&mut n, 35);
    assert!(!publishes(&mut n, 35));
    assert!(!publishes(&mut n, 40), "0.99 s after the ask");
    assert!(publishes(&mut n, 42), "1.1 s after");
    assert_eq!(n.metrics.decisions_withheld, 2);
}

/// Robots that start together have no team's history to wait for: a newcomer that
/// hears of no decision before it came publishes its first tick, answered or not.
#[test]
fn robots_that_start_together_withhold_nothing() {
    let set = models();
    let mut n = catching_up(newcomer(&set, ms(3100)));
    // n came at tick 31, when its window reached back to tick 26.
    hears_a_decided(&mut n, 32, 27);
    assert!(publishes(&mut n, 32), "a decided tick 27, within the window n came with: a started with n");
    assert_eq!((n.metrics.decisions_withheld, n.metrics.histories_asked), (0, 1));
}

/// An ask that comes before its asker's liveliness token is kept and answered when
/// the asker becomes a member — but not once [`super::history::ASK_KEPT`] has passed.
#[test]
fn an_ask_from_a_robot_not_yet_a_member_is_answered_when_it_joins() {
    let set = models();
    let ask = |r: &str| HistoryMsg { robot: id(r), instance: 2, lessons: vec![Lesson { tick: 31, votes: vec![] }] };
    let mut a = veteran_of(1..=30, &set);
    assert_eq!(history_of(&a.handle(Input::History(ask("n")), ms(3100))), None, "n is no member yet");
    let h = history_of(&a.handle(Input::MemberJoined(id("n")), ms(3150))).expect("answered as n joins");
    assert!(h.lessons.len() >= 25);

    let mut a = veteran_of(1..=30, &set);
    a.handle(Input::History(ask("m")), ms(3100));
    assert_eq!(history_of(&a.handle(Input::MemberJoined(id("m")), ms(5200))), None, "kept 2 s, no longer");
}

/// The sender's own votes teach nothing (it cannot make itself trusted by rewriting
/// its past), nor does a history from no live member, or one for ticks the receiver
/// decided itself.
#[test]
fn a_history_never_speaks_for_its_sender_nor_for_ticks_the_receiver_decided() {
    let set = models();
    let joined = ms(3100);
    let lesson = |t: u64, voters: &[&str]| Lesson {
        tick: t,
        votes: voters.iter().map(|r| vote_msg(r, 2, t, one_step(Station::Assembly))).collect(),
    };
    let history = |from: &str, voters: &[&str], ticks: std::ops::Range<u64>| HistoryMsg {
        robot: id(from),
        instance: 2,
        lessons: ticks.map(|t| lesson(t, voters)).collect(),
    };

    let mut n = newcomer(&set, joined);
    n.handle(Input::History(history("a", &["a"], 1..26)), joined);
    assert_eq!((n.metrics.histories_ignored, n.metrics.history_votes_learned), (1, 0));
    assert!(!n.trust().contains_key(&id("a")), "a's word about itself taught n nothing");

    n.handle(Input::History(history("x", &["b", "c", "d"], 1..26)), joined);
    assert_eq!(n.metrics.histories_ignored, 2, "x is no member");

    n.handle(Input::History(history("a", &["a", "b", "c", "d"], 1..26)), joined);
    assert_eq!(n.metrics.history_votes_learned, 75, "b's, c's and d's votes of 25 ticks, not a's");
    assert!(n.trust.established(&id("b")));

    // A robot that has decided for a while takes nothing: every tick within reach is
    // one it decided itself.
    let mut a = veteran_of(1..=30, &set);
    a.handle(Input::MemberJoined(id("n")), joined);
    let before = a.trust();
    a.handle(Input::History(history("b", &["c", "d"], 1..30)), joined);
    assert_eq!((a.metrics.histories_ignored, a.metrics.history_votes_learned), (1, 0));
    assert_eq!(a.trust(), before);
}
