//! What the evaluation scores: each robot's models, the team's decisions, and the
//! baselines beside them. The JSON and the results page name each as [`Scored::name`]
//! says; reports keep them in maps ordered by that name, as the JSON lists them.

use serde::Serialize;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Scored {
    /// The GCN alone, on one frame (t only).
    Gnn,
    /// The ego GRU of each robot that sees the worker.
    Ego,
    /// The collective GRU of each robot that sees the worker.
    Collective,
    /// The collective GRU of the robots whose camera works (fault studies).
    HealthyCollective,
    /// The collective GRU on the robot-ticks whose goal is missing from the team map.
    CollectiveGoalUnmapped,
    /// The team's decision, on the ticks some robot decided.
    Consensus,
    /// The same, from 10 s into each episode.
    ConsensusSettled,
    /// Every robot's decision on every tick, a tick without one counted as wrong.
    TeamAllTicks,
    /// A constant-velocity Kalman filter handed the true work spots.
    Cvm,
    /// The same, on the stations the team mapped.
    CvmMapped,
    /// Goal inference planning paths around the obstacles, on the team's track,
    /// handed the true work spots.
    Planner,
    /// The same, on the stations the team mapped.
    PlannerMapped,
    /// The paper's 1D-CNN + GRU baseline.
    Cnn1d,
    /// The collective GRU on the robot-ticks on which its robot also decided a class.
    CollectivePaired,
    /// The team's decision on those same robot-ticks.
    ConsensusPaired,
    /// The collective on the close pair's farther station (its recall).
    CollectiveFarther,
    /// The CVM likewise.
    CvmFarther,
}

impl Scored {
    /// The robots' models, the team's decisions and the baselines, in the order the
    /// tables list them.
    pub const LISTED: [Scored; 10] = [
        Scored::TeamAllTicks,
        Scored::Gnn,
        Scored::Ego,
        Scored::Collective,
        Scored::Consensus,
        Scored::Cvm,
        Scored::CvmMapped,
        Scored::Planner,
        Scored::PlannerMapped,
        Scored::Cnn1d,
    ];

    /// The name the JSON and the page use.
    pub fn name(self) -> &'static str {
        match self {
            Scored::Gnn => "gnn",
            Scored::Ego => "ego",
            Scored::Collective => "collective",
            Scored::HealthyCollective => "healthy_collective",
            Scored::CollectiveGoalUnmapped => "collective_goal_unmapped",
            Scored::Consensus => "consensus",
            Scored::ConsensusSettled => "consensus_settled",
            Scored::TeamAllTicks => "team_all_ticks",
            Scored::Cvm => "cvm",
            Scored::CvmMapped => "cvm_mapped",
            Scored::Planner => "planner",
            Scored::PlannerMapped => "planner_mapped",
            Scored::Cnn1d => "cnn1d",
            Scored::CollectivePaired => "collective_paired",
            Scored::ConsensusPaired => "consensus_paired",
            Scored::CollectiveFarther => "collective_farther",
            Scored::CvmFarther => "cvm_farther",
        }
    }
}

impl std::fmt::Display for Scored {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.pad(self.name())
    }
}

/// Ordered by name, so maps of them list as they always did.
impl Ord for Scored {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.name().cmp(other.name())
    }
}

impl PartialOrd for Scored {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_json_names_each_as_the_page_does() {
        for s in [Scored::Gnn, Scored::TeamAllTicks, Scored::CollectiveGoalUnmapped, Scored::Cnn1d] {
            assert_eq!(serde_json::to_value(s).unwrap(), serde_json::json!(s.name()));
        }
    }
}
