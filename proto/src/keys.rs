//! Every Zenoh key expression spwi uses, built and parsed here and nowhere else.
//!
//! | key expression                           | payload                         | published by   |
//! |------------------------------------------|---------------------------------|----------------|
//! | `spwi/<fleet>/robot/<robot>/detections`  | [`DetectionFrame`]              | world / detector node |
//! | `spwi/<fleet>/robot/<robot>/embedding`   | [`EmbeddingMsg`] (and the vote) | agent          |
//! | `spwi/<fleet>/robot/<robot>/vote`        | [`VoteMsg`] (for observers)     | agent          |
//! | `spwi/<fleet>/robot/<robot>/decision`    | [`DecisionMsg`] (for observers) | agent          |
//! | `spwi/<fleet>/robot/<robot>/ballots`     | [`BallotsMsg`] (relayed votes)  | agent          |
//! | `spwi/<fleet>/robot/<robot>/map`         | [`MapMsg`] (when a robot joins) | agent          |
//! | `spwi/<fleet>/robot/<robot>/history`     | [`HistoryMsg`] (when a robot joins) | agent      |
//! | `spwi/<fleet>/alive/<robot>`             | liveliness token (no payload)   | agent          |
//! | `spwi/<fleet>/world/truth`               | [`TruthMsg`]                    | simulated world |
//! | `spwi/<fleet>/roster/<member>`           | the signed roster, `fleet.toml`'s TOML text | any member but an observer |
//!
//! [`DetectionFrame`]: crate::DetectionFrame
//! [`EmbeddingMsg`]: crate::EmbeddingMsg
//! [`VoteMsg`]: crate::VoteMsg
//! [`DecisionMsg`]: crate::DecisionMsg
//! [`BallotsMsg`]: crate::BallotsMsg
//! [`MapMsg`]: crate::MapMsg
//! [`HistoryMsg`]: crate::HistoryMsg
//! [`TruthMsg`]: crate::TruthMsg

use crate::id::{FleetId, RobotId};

const ROOT: &str = "spwi";

/// The per-robot topics under `spwi/<fleet>/robot/<robot>/`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Topic {
    Detections,
    Embedding,
    Vote,
    Decision,
    Ballots,
    Map,
    History,
}

impl Topic {
    pub const ALL: [Topic; 7] =
        [Topic::Detections, Topic::Embedding, Topic::Vote, Topic::Decision, Topic::Ballots, Topic::Map, Topic::History];

    pub fn as_str(self) -> &'static str {
        match self {
            Topic::Detections => "detections",
            Topic::Embedding => "embedding",
            Topic::Vote => "vote",
            Topic::Decision => "decision",
            Topic::Ballots => "ballots",
            Topic::Map => "map",
            Topic::History => "history",
        }
    }

    fn parse(s: &str) -> Option<Topic> {
        Topic::ALL.into_iter().find(|t| t.as_str() == s)
    }
}

/// `spwi/<fleet>/robot/<robot>/<topic>`
pub fn robot_topic(fleet: &FleetId, robot: &RobotId, topic: Topic) -> String {
    format!("{ROOT}/{fleet}/robot/{robot}/{}", topic.as_str())
}

/// `spwi/<fleet>/robot/*/<topic>`: the topic of every robot of the fleet.
pub fn all_robots(fleet: &FleetId, topic: Topic) -> String {
    format!("{ROOT}/{fleet}/robot/*/{}", topic.as_str())
}

/// `spwi/<fleet>/alive/<robot>`: the robot's liveliness token.
pub fn alive(fleet: &FleetId, robot: &RobotId) -> String {
    format!("{ROOT}/{fleet}/alive/{robot}")
}

/// `spwi/<fleet>/alive/*`: every member's liveliness token.
pub fn all_alive(fleet: &FleetId) -> String {
    format!("{ROOT}/{fleet}/alive/*")
}

/// `spwi/<fleet>/robot/<robot>/**`: every topic of one robot (what it may say).
pub fn robot_everything(fleet: &FleetId, robot: &RobotId) -> String {
    format!("{ROOT}/{fleet}/robot/{robot}/**")
}

/// `spwi/<fleet>/world/**`: everything the simulated world says besides the frames.
pub fn world_everything(fleet: &FleetId) -> String {
    format!("{ROOT}/{fleet}/world/**")
}

/// `spwi/<fleet>/world/truth`
pub fn truth(fleet: &FleetId) -> String {
    format!("{ROOT}/{fleet}/world/truth")
}

/// `spwi/<fleet>/robot/*/*`: every robot topic of the fleet (observers: demo, bench).
pub fn all_robot_topics(fleet: &FleetId) -> String {
    format!("{ROOT}/{fleet}/robot/*/*")
}

/// `spwi/<fleet>/**`: everything the fleet says, liveliness aside (observers).
pub fn everything(fleet: &FleetId) -> String {
    format!("{ROOT}/{fleet}/**")
}

/// Parses `spwi/<fleet>/robot/<robot>/<topic>`; `None` for any other key, another fleet
/// or an invalid robot id.
pub fn parse_robot_topic(fleet: &FleetId, key: &str) -> Option<(RobotId, Topic)> {
    let mut parts = key.split('/');
    let (root, f, robot_kw, robot, topic) = (parts.next()?, parts.next()?, parts.next()?, parts.next()?, parts.next()?);
    if parts.next().is_some() || root != ROOT || f != fleet.as_str() || robot_kw != "robot" {
        return None;
    }
    Some((RobotId::new(robot).ok()?, Topic::parse(topic)?))
}

/// `spwi/<fleet>/roster/<member>`: the signed roster as `member` holds it, said when it
/// joins, when it adopts a newer one, and to a member heard saying an older one.
pub fn roster(fleet: &FleetId, member: &RobotId) -> String {
    format!("{ROOT}/{fleet}/roster/{member}")
}

/// `spwi/<fleet>/roster/*`
pub fn all_rosters(fleet: &FleetId) -> String {
    format!("{ROOT}/{fleet}/roster/*")
}

/// Parses `spwi/<fleet>/roster/<member>`.
pub fn parse_roster(fleet: &FleetId, key: &str) -> Option<RobotId> {
    parse_member_key(fleet, "roster", key)
}

/// Parses `spwi/<fleet>/alive/<robot>`.
pub fn parse_alive(fleet: &FleetId, key: &str) -> Option<RobotId> {
    parse_member_key(fleet, "alive", key)
}

/// The member named by `spwi/<fleet>/<tree>/<member>`.
fn parse_member_key(fleet: &FleetId, tree: &str, key: &str) -> Option<RobotId> {
    let rest = key.strip_prefix(ROOT)?.strip_prefix('/')?.strip_prefix(fleet.as_str())?.strip_prefix('/')?;
    RobotId::new(rest.strip_prefix(tree)?.strip_prefix('/')?).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ids() -> (FleetId, RobotId) {
        (FleetId::new("f1").unwrap(), RobotId::new("r-2").unwrap())
    }

    #[test]
    fn robot_topics_round_trip() {
        let (f, r) = ids();
        for t in Topic::ALL {
            let k = robot_topic(&f, &r, t);
            assert_eq!(parse_robot_topic(&f, &k), Some((r.clone(), t)));
        }
        assert_eq!(robot_topic(&f, &r, Topic::Vote), "spwi/f1/robot/r-2/vote");
        assert_eq!(all_robots(&f, Topic::Embedding), "spwi/f1/robot/*/embedding");
    }

    #[test]
    fn roster_keys_round_trip() {
        let (f, r) = ids();
        assert_eq!(roster(&f, &r), "spwi/f1/roster/r-2");
        assert_eq!(parse_roster(&f, &roster(&f, &r)), Some(r.clone()));
        assert_eq!(parse_roster(&FleetId::new("f2").unwrap(), &roster(&f, &r)), None);
        assert_eq!(parse_roster(&f, "spwi/f1/roster/bad name"), None);
    }

    #[test]
    fn foreign_or_malformed_keys_are_not_parsed() {
        let (f, _) = ids();
        for k in [
            "spwi/f2/robot/r/vote",
            "spwi/f1/robot/r/vote/extra",
            "spwi/f1/robot/r/other",
            "spwi/f1/robots/r/vote",
            "xx/f1/robot/r/vote",
            "spwi/f1/robot/*/vote",
        ] {
            assert_eq!(parse_robot_topic(&f, k), None, "{k}");
        }
    }

    #[test]
    fn alive_round_trips_and_rejects_others() {
        let (f, r) = ids();
        assert_eq!(parse_alive(&f, &alive(&f, &r)), Some(r));
        assert_eq!(parse_alive(&f, "spwi/f1/alive/a/b"), None);
        assert_eq!(parse_alive(&f, "spwi/f10/alive/a"), None);
        assert_eq!(all_alive(&f), "spwi/f1/alive/*");
        assert_eq!(truth(&f), "spwi/f1/world/truth");
        assert_eq!(all_robot_topics(&f), "spwi/f1/robot/*/*");
        assert_eq!(everything(&f), "spwi/f1/**");
    }
}
