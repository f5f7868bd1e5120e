//! The fleet's clock: what lies outside the window is refused and blocks nothing.

use super::*;

#[test]
fn ticks_off_our_clock_are_refused_and_counted_and_block_nothing() {
    let set = models();
    let mut a = engine("a", &set);
    a.handle(Input::MemberJoined(id("z")), ms(0));
    a.handle(Input::Frame(frame("a", 10, true)), ms(1000));
    assert!(a.handle(Input::Frame(frame("a", 10, true)), ms(1001)).is_empty());
    assert_eq!(a.metrics.stale_frames, 1, "the same tick's frame twice");
    // At 1050 ms our clock is in tick 10: we take ticks 5..=12. A member floods a
    // thousand messages for ticks far ahead, far behind, decided, and ahead of ours.
    let flood = [1u64 << 62, u64::MAX, 13, 0, 4, 10, 11, 12];
    for k in 0..1000 {
        let t = flood[k % flood.len()];
        a.handle(Input::Embedding(share("z", t, None, Some(one_step(Station::Storage)), None)), ms(1050));
    }
    let off = |a: &Engine, why| a.metrics.off_clock.get(&why).copied().unwrap_or(0);
    assert_eq!(off(&a, OffClock::MessageTooNew), 375, "every message counted: 3 of 8 too far ahead");
    assert_eq!(off(&a, OffClock::MessageTooOld), 250);
    assert_eq!(a.metrics.late_messages, 125, "tick 10 is decided");
    assert_eq!(a.open.keys().copied().collect::<Vec<_>>(), vec![11, 12], "only ticks near ours are open");
    assert_eq!(a.peer_clocks()[&id("z")].refused, 625);
    // z's early share of tick 11 moved no deadline: it runs from tick 11's start.
    assert_eq!(a.next_deadline(), Some(ms(1160)));
    // The ticks that follow are decided as they come, z's votes in.
    for t in 11..=12 {
        let d = a.handle(Input::Frame(frame("a", t, true)), ms(100 * t));
        assert_eq!(decisions(&d)[0].voters, vec![id("a"), id("z")], "tick {t}");
    }
    // A frame without a capture time, or stamped a day off, is refused and counted.
    for capture_us in [0, 86_400_000_000 + 1_300_000] {
        assert!(a.handle(Input::Frame(DetectionFrame { capture_us, ..frame("a", 13, true) }), ms(1300)).is_empty());
    }
    assert_eq!((off(&a, OffClock::FrameTooOld), off(&a, OffClock::FrameTooNew)), (1, 1));
    // What we remember of decided ticks reaches back as far as the window.
    a.handle(Input::Poll, ms(5000));
    assert!(a.decided.keys().all(|&t| t >= 45), "{:?}", a.decided.keys());
}
