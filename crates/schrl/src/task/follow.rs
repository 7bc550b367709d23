//! How a robot is handed the path it executes: the goal its controller sees at each
//! step ([`Follow`]). The planner checked the clearance along the straight segments
//! between waypoints ([`super::SafeAlong::Segments`]); how closely the robot keeps to
//! them depends on the goal it is given.

use serde::{Deserialize, Serialize};

/// What the controller is given as its goal while it drives a path.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Follow {
    /// The current waypoint itself (the paper's): from wherever the robot is, it heads
    /// straight for the waypoint, so a robot thrown off the planned segment (swinging
    /// out of a turn) rejoins it only at the waypoint.
    #[default]
    Waypoints,
    /// A point `lookahead` metres along the planned segment into the current waypoint,
    /// ahead of the robot's projection onto it and never past the waypoint (pure
    /// pursuit's "carrot"): the robot is pulled back onto the segment, whose clearance
    /// the planner checked, rather than driving a chord of its own. Must exceed the
    /// robot's reach radius, so only the waypoint itself is ever reached.
    Carrot {
        /// Metres ahead of the robot's projection onto the segment.
        lookahead: f64,
    },
}

impl Follow {
    /// Errors unless a carrot's lookahead exceeds `reach` (the radius within which the
    /// executing robot counts its goal reached): a nearer carrot would be "reached"
    /// part-way along a segment.
    pub fn check(self, reach: f64) -> Result<(), String> {
        match self {
            Follow::Carrot { lookahead } if lookahead <= reach => Err(format!(
                "carrot:{lookahead} looks no farther ahead than the robot's waypoint reach ({reach} m); \
                 use a lookahead above it"
            )),
            _ => Ok(()),
        }
    }

    /// The goal to give a robot at `position` driving the segment `from → to`.
    pub fn target(self, from: &[f64], to: &[f64], position: &[f64]) -> Vec<f64> {
        let Follow::Carrot { lookahead } = self else { return to.to_vec() };
        let d: Vec<f64> = to.iter().zip(from).map(|(t, f)| t - f).collect();
        let len = d.iter().map(|x| x * x).sum::<f64>().sqrt();
        if len <= 1e-12 {
            return to.to_vec();
        }
        let along = position.iter().zip(from).zip(&d).map(|((p, f), x)| (p - f) * x).sum::<f64>() / len;
        let s = (along.max(0.0) + lookahead) / len;
        if s >= 1.0 {
            return to.to_vec();
        }
        from.iter().zip(&d).map(|(f, x)| f + s * x).collect()
    }
}

impl std::fmt::Display for Follow {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Follow::Waypoints => write!(f, "waypoints"),
            Follow::Carrot { lookahead } => write!(f, "carrot:{lookahead}"),
        }
    }
}

impl std::str::FromStr for Follow {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.split_once(':') {
            None if s == "waypoints" => Ok(Follow::Waypoints),
            Some(("carrot", l)) => match l.parse::<f64>() {
                Ok(lookahead) if lookahead.is_finite() && lookahead > 0.0 => Ok(Follow::Carrot { lookahead }),
                _ => Err(format!("'{l}' is not a lookahead in metres (a positive number), as in carrot:0.6")),
            },
            _ => Err(format!("'{s}' is not waypoints or carrot:LOOKAHEAD (metres, e.g. carrot:0.6)")),
        }
    }
}
