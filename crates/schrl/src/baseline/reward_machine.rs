//! Reward machines (Icarte, Klassen, Valenzano & McIlraith, "Reward Machines:
//! Exploiting Reward Function Structure in Reinforcement Learning", JAIR 2022): a
//! finite automaton over events whose transitions pay rewards, so a non-Markov task
//! becomes Markov on the environment's state ⊕ the machine's state.
//!
//! * *Events* ([`Labels`]): what is true after an environment step — the name of every
//!   goal of the task the robot is inside, `collision` when it touched an obstacle,
//!   and `counter` once the waypoint index the clock stands at reaches the task's
//!   `counter_from` (Signal).
//! * *Transitions*: from the current state, the first edge (in file order) whose
//!   condition holds is taken and pays its reward; when none holds the machine stays
//!   and pays 0. A condition is events joined by `&`, each possibly negated with `!`
//!   (`l1 & !counter`). Reaching a terminal state ends the episode.
//! * *Files*: a machine is TOML (`initial`, `terminal`, `[[edge]] from, to, on,
//!   reward`); the shipped tasks' machines are `tasks/machines/<task>.toml`, embedded
//!   at build time. They pay 1 for each step of progress the spec asks for and −1 for a
//!   collision, which ends the episode in a `fail` state.

use std::collections::BTreeSet;
use std::path::Path;

use serde::Deserialize;

use crate::task::Task;

/// A reward machine: states by index, the initial one, terminal ones, and edges.
#[derive(Clone, Debug, PartialEq)]
pub struct RewardMachine {
    /// State names, by index.
    pub states: Vec<String>,
    /// The initial state.
    pub initial: usize,
    /// Which states end the episode.
    pub terminal: Vec<bool>,
    edges: Vec<Edge>,
}

/// One transition.
#[derive(Clone, Debug, PartialEq)]
struct Edge {
    from: usize,
    to: usize,
    /// `(event, wanted)`: all must hold (`wanted` false: the event must be absent).
    on: Vec<(String, bool)>,
    reward: f64,
}

/// A machine file that cannot be used, naming the file and the problem.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{path}: {message}")]
pub struct MachineError {
    /// The file.
    pub path: String,
    /// What is wrong (with line and column where the TOML says).
    pub message: String,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct MachineToml {
    initial: String,
    #[serde(default)]
    terminal: Vec<String>,
    edge: Vec<EdgeToml>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct EdgeToml {
    from: String,
    to: String,
    on: String,
    reward: f64,
}

/// The events true after a step (module docs), by name.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Labels(pub BTreeSet<String>);

impl Labels {
    /// The events of `task` with the robot at `position`, after a step that `collided`
    /// or not, at waypoint index `index` (fractional: the clock times the plan length).
    pub fn of(task: &Task, position: &[f64], collided: bool, index: f64) -> Self {
        let mut set: BTreeSet<String> = task
            .goals
            .iter()
            .filter(|g| {
                g.center.iter().zip(position).map(|(c, p)| (c - p) * (c - p)).sum::<f64>().sqrt() <= g.radius
            })
            .map(|g| g.name.clone())
            .collect();
        if collided {
            set.insert(COLLISION.into());
        }
        if task.counter_from.is_some_and(|c| index >= c as f64) {
            set.insert(COUNTER.into());
        }
        Self(set)
    }

    /// Whether `event` holds.
    pub fn has(&self, event: &str) -> bool {
        self.0.contains(event)
    }
}

/// The event of touching an obstacle.
pub const COLLISION: &str = "collision";
/// The event of Signal's counter having fired.
pub const COUNTER: &str = "counter";

/// The shipped machines, by task name.
const SHIPPED: [(&str, &str); 5] = [
    ("seq", include_str!("../../../../tasks/machines/seq.toml")),
    ("cover", include_str!("../../../../tasks/machines/cover.toml")),
    ("branch", include_str!("../../../../tasks/machines/branch.toml")),
    ("loop", include_str!("../../../../tasks/machines/loop.toml")),
    ("signal", include_str!("../../../../tasks/machines/signal.toml")),
];

impl RewardMachine {
    /// The shipped machine of a built-in task (`seq`, `cover`, `branch`, `loop`,
    /// `signal`), checked against the task's events.
    pub fn shipped(task: &Task) -> Result<Self, MachineError> {
        let Some((name, text)) = SHIPPED.iter().find(|(n, _)| *n == task.name) else {
            return Err(MachineError {
                path: task.name.clone(),
                message: format!(
                    "no shipped reward machine for task '{}' (shipped: seq, cover, branch, loop, signal); \
                     write one and pass its file",
                    task.name
                ),
            });
        };
        let path = format!("tasks/machines/{name}.toml");
        Self::parse(Path::new(&path), text, task)
    }

    /// The text of the shipped machine of the task named `name`, if there is one.
    pub fn shipped_text(name: &str) -> Option<&'static str> {
        SHIPPED.iter().find(|(n, _)| *n == name).map(|(_, t)| *t)
    }

    /// A machine file for `task`.
    pub fn from_file(path: &Path, task: &Task) -> Result<Self, MachineError> {
        let text = crate::task::read_text(path, crate::task::MAX_TASK_FILE_BYTES)
            .map_err(|e| MachineError { path: path.display().to_string(), message: e.to_string() })?;
        Self::parse(path, &text, task)
    }

    /// Parses a machine's TOML text; every event must be a goal of `task`,
    /// `collision`, or (for tasks with a counter) `counter`.
    pub fn parse(path: &Path, text: &str, task: &Task) -> Result<Self, MachineError> {
        let bad = |message: String| MachineError { path: path.display().to_string(), message };
        let m: MachineToml = toml::from_str(text).map_err(|e| bad(crate::task::toml_message(&e, text)))?;
        let mut states: Vec<String> = vec![m.initial.clone()];
        let index = |name: &str, states: &mut Vec<String>| match states.iter().position(|s| s == name) {
            Some(i) => i,
            None => {
                states.push(name.to_string());
                states.len() - 1
            }
        };
        let mut edges = Vec::with_capacity(m.edge.len());
        for (k, e) in m.edge.iter().enumerate() {
            let at = |msg: String| bad(format!("edge {} ({} -> {}): {msg}", k + 1, e.from, e.to));
            if !e.reward.is_finite() {
                return Err(at(format!("reward must be a finite number, got {}", e.reward)));
            }
            let mut on = vec![];
            for part in e.on.split('&') {
                let part = part.trim();
                let (name, wanted) = match part.strip_prefix('!') {
                    Some(n) => (n.trim(), false),
                    None => (part, true),
                };
                let known = task.goals.iter().any(|g| g.name == name)
                    || name == COLLISION
                    || (name == COUNTER && task.counter_from.is_some());
                if !known {
                    let goals: Vec<&str> = task.goals.iter().map(|g| g.name.as_str()).collect();
                    return Err(at(format!(
                        "unknown event '{name}' in on = \"{}\": events are the task's goals ({}), {COLLISION}{}",
                        e.on,
                        goals.join(", "),
                        if task.counter_from.is_some() { ", counter" } else { "" }
                    )));
                }
                on.push((name.to_string(), wanted));
            }
            let (from, to) = (index(&e.from, &mut states), index(&e.to, &mut states));
            edges.push(Edge { from, to, on, reward: e.reward });
        }
        let mut terminal = vec![false; states.len()];
        for t in &m.terminal {
            match states.iter().position(|s| s == t) {
                Some(i) => terminal[i] = true,
                None => return Err(bad(format!("terminal state '{t}' is on no edge"))),
            }
        }
        if terminal[0] {
            return Err(bad(format!("the initial state '{}' is terminal", m.initial)));
        }
        Ok(Self { states, initial: 0, terminal, edges })
    }

    /// Number of states.
    pub fn len(&self) -> usize {
        self.states.len()
    }

    /// `true` for a machine without states (never: the initial state always exists).
    pub fn is_empty(&self) -> bool {
        self.states.is_empty()
    }

    /// The transition from state `u` on `labels`: the next state and its reward.
    pub fn step(&self, u: usize, labels: &Labels) -> (usize, f64) {
        self.edges
            .iter()
            .filter(|e| e.from == u)
            .find(|e| e.on.iter().all(|(name, wanted)| labels.has(name) == *wanted))
            .map_or((u, 0.0), |e| (e.to, e.reward))
    }

    /// The edges that leave their state with a positive reward (DHRM's options):
    /// `(from, to)`, in file order.
    pub fn options(&self) -> Vec<(usize, usize)> {
        self.edges.iter().filter(|e| e.from != e.to && e.reward > 0.0).map(|e| (e.from, e.to)).collect()
    }

    /// The state's one-hot encoding, written into `out` (length [`RewardMachine::len`]).
    pub fn one_hot(&self, u: usize, out: &mut [f64]) {
        out.iter_mut().enumerate().for_each(|(i, x)| *x = f64::from(u8::from(i == u)));
    }
}
