//! When a robot executing a plan counts a waypoint reached ([`Reach`]). The spec is
//! judged on the positions where waypoints were counted reached
//! ([`crate::run::execute`]), so this rule decides which of those positions lie in the
//! goals the plan put its waypoints in.

use serde::{Deserialize, Serialize};

/// When a waypoint counts as reached.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Reach {
    /// Within the waypoint reach radius ([`super::Task::waypoint_reach`]), the paper's
    /// rule. A waypoint planned near a goal's edge is then counted reached from up to
    /// that radius outside it: Doggo Seq's waypoints may lie anywhere in their 0.3 m
    /// goals (the goal margin stops at [`super::MIN_PLANNED_RADIUS`]) and are reached
    /// from 0.2 m, and runs that finished their plan failed the spec by millimetres.
    #[default]
    Radius,
    /// Within the reach radius and, as well, strictly inside every goal the planned
    /// waypoint lies in (the task's goals as loaded, regions to avoid excepted): the
    /// robot keeps driving to the waypoint until both hold. A waypoint in no goal is
    /// reached by the radius alone. Every goal atom true at the planned waypoint is
    /// then true where the robot counted it.
    InGoal,
}

impl std::fmt::Display for Reach {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Reach::Radius => "radius",
            Reach::InGoal => "in-goal",
        })
    }
}

impl std::str::FromStr for Reach {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "radius" => Ok(Reach::Radius),
            "in-goal" => Ok(Reach::InGoal),
            _ => Err(format!("'{s}' is not radius or in-goal")),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_bad_names_say_what_is_allowed() {
        for r in [Reach::Radius, Reach::InGoal] {
            assert_eq!(r.to_string().parse::<Reach>(), Ok(r));
        }
        let err = "goal".parse::<Reach>().unwrap_err();
        assert!(err.contains("radius or in-goal"), "{err}");
    }
}
