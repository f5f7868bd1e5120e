//! Members whose liveliness token goes away for a moment while the fleet takes a new
//! roster.
//!
//! Zenoh sets a session's access rules when it opens, so every member reopens its
//! session within a couple of seconds of adopting a roster ([`crate::fleet::live`]).
//! Peers see its token withdrawn and declared again some tens of milliseconds later;
//! counted as it happens, that is a member leaving and rejoining, and the ticks decided
//! in between count one member fewer. So while a roster change is fresh (ours adopted
//! less than [`SEASON`] ago), a member whose token goes is held for [`GRACE`] before it
//! is let go, and a member whose token comes back in that time never left. After our
//! own reopen every member is held the same way until the new session hears its token,
//! so one that left while we were away is let go rather than counted for ever.
//!
//! Outside a roster change a departure is let go at once, as always: a robot that
//! fails is out of the vote within its lease. A revoked robot never passes through
//! here: the daemon lets it go the moment the roster is adopted.

use spwi_proto::RobotId;
use std::collections::BTreeMap;
use std::time::{Duration, Instant};

/// How long after adopting a roster departures are held: the longest spread of the
/// members' reopens ([`crate::fleet::live::reopen_delay`]) and a margin for a member
/// that adopted it a little after us.
pub(super) const SEASON: Duration = Duration::from_millis(4_000);

/// How long a held member may stay away before it is let go: a reopen takes tens of
/// milliseconds, and up to a second when the old session's port is slow to free.
pub(super) const GRACE: Duration = Duration::from_millis(1_000);

/// The members held, and until when departures are held.
#[derive(Debug, Default)]
pub(super) struct Departures {
    held: BTreeMap<RobotId, Instant>,
    season_until: Option<Instant>,
}

impl Departures {
    /// We adopted a roster at `now`: members are about to reopen their sessions.
    pub fn roster_adopted(&mut self, now: Instant) {
        self.season_until = Some(now + SEASON);
    }

    /// We reopened our session at `now`: every member we counted is held until the
    /// new session hears its token.
    pub fn reopened(&mut self, members: impl IntoIterator<Item = RobotId>, now: Instant) {
        for m in members {
            self.held.entry(m).or_insert(now + GRACE);
        }
    }

    /// A member's token went at `now`: whether to let it go at once (otherwise it is
    /// held, and [`Departures::due`] lets it go if it does not come back).
    pub fn left(&mut self, robot: &RobotId, now: Instant) -> bool {
        if self.season_until.is_some_and(|until| now < until) {
            self.held.entry(robot.clone()).or_insert(now + GRACE);
            return false;
        }
        self.held.remove(robot);
        true
    }

    /// A member's token is there: it is no longer held. Whether it was.
    pub fn joined(&mut self, robot: &RobotId) -> bool {
        self.held.remove(robot).is_some()
    }

    /// When the next held member is due to be let go.
    pub fn next_due(&self) -> Option<Instant> {
        self.held.values().min().copied()
    }

    /// The held members that stayed away past their grace, no longer held.
    pub fn due(&mut self, now: Instant) -> Vec<RobotId> {
        let gone: Vec<RobotId> = self.held.iter().filter(|(_, &at)| at <= now).map(|(r, _)| r.clone()).collect();
        for r in &gone {
            self.held.remove(r);
        }
        gone
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn r(name: &str) -> RobotId {
        RobotId::new(name).unwrap()
    }

    #[test]
    fn outside_a_roster_change_a_departure_is_let_go_at_once() {
        let mut d = Departures::default();
        let t0 = Instant::now();
        assert!(d.left(&r("r2"), t0));
        assert_eq!(d.next_due(), None);
        d.roster_adopted(t0);
        assert!(d.left(&r("r2"), t0 + SEASON), "the season is over");
    }

    #[test]
    fn a_member_that_reopens_during_a_roster_change_never_leaves() {
        let mut d = Departures::default();
        let t0 = Instant::now();
        d.roster_adopted(t0);
        assert!(!d.left(&r("r2"), t0 + Duration::from_millis(700)));
        assert!(d.due(t0 + Duration::from_millis(710)).is_empty());
        assert!(d.joined(&r("r2")), "it came back within its grace");
        assert!(d.due(t0 + Duration::from_secs(10)).is_empty());
        assert!(!d.joined(&r("r2")), "a join of a member never held is nothing to cancel");
    }

    #[test]
    fn a_member_that_stays_away_is_let_go_after_its_grace() {
        let mut d = Departures::default();
        let t0 = Instant::now();
        d.roster_adopted(t0);
        let went = t0 + Duration::from_millis(100);
        assert!(!d.left(&r("r2"), went));
        assert!(!d.left(&r("r3"), went + Duration::from_millis(50)));
        assert_eq!(d.next_due(), Some(went + GRACE));
        assert!(d.due(went + GRACE - Duration::from_millis(1)).is_empty());
        assert_eq!(d.due(went + GRACE), vec![r("r2")]);
        assert_eq!(d.due(went + GRACE + Duration::from_millis(50)), vec![r("r3")]);
        assert_eq!(d.next_due(), None);
    }

    #[test]
    fn after_our_reopen_members_not_heard_again_are_let_go() {
        let mut d = Departures::default();
        let t0 = Instant::now();
        d.reopened([r("r2"), r("r3")], t0);
        assert!(d.joined(&r("r2")), "the new session heard r2's token");
        assert_eq!(d.due(t0 + GRACE), vec![r("r3")], "r3 left while we were away");
    }
}
