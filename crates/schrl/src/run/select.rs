//! Choosing which checkpoint of a joint run to deploy, by validation.
//!
//! The joint phase trains on sampled plans and sampled actions; what is deployed and
//! evaluated is the mean plans driven with mean actions. The two need not move
//! together (on Doggo Cover seed 0 the final pair satisfied less than the warm-start
//! pair; README, *Selecting the deployed checkpoint*). With selection on, the deployed pair is
//! measured every few iterations on [`SELECT_RUNS`] runs of its own, and the best
//! measured checkpoint is the one `schrl eval` and the run's own evaluation use.
//!
//! *Held apart from the evaluation.* Validation runs start from [`SELECT_SEED`]'s
//! stream, never [`super::evaluate::EVAL_SEED`]'s, so choosing a checkpoint does not
//! look at the runs it is then judged on.
//!
//! *Order.* A validation is better than another when it satisfies more runs; at equal
//! satisfaction, when its satisfying runs reach the task's last goal in fewer steps; at
//! a tie on both, the earlier one stays (it trained less to get there).
//!
//! *When.* At the first iteration (the warm-start pair), at the first iteration after
//! each `select_every` more environment steps, and at the last: counted in steps, not
//! iterations, so tasks whose iterations differ tenfold in length (Doggo Cover about
//! 2 300 steps, Loop about 11 000) validate equally often. One validation is
//! [`SELECT_RUNS`] executed runs, the work of one evaluation group.

use serde::{Deserialize, Serialize};

use super::RunError;
use super::evaluate::{Plans, evaluate_task, mean_std};
use super::joint::JointTrainer;

/// Seed of the validation runs' starts and plans (not the evaluation's 2024).
pub const SELECT_SEED: u64 = 7;
/// Runs per validation: one evaluation group.
pub const SELECT_RUNS: usize = super::evaluate::EVAL_PER_GROUP;

/// Joint environment steps between validations by default for `robot`: the Doggo's
/// 250 000 (about twelve validations in its 3 M steps, chosen on its tuning seed 0,
/// README *Selecting the deployed checkpoint*); the Car's the same, re-derived on its
/// own tuning seeds 0–4 (README *Car and Drone*); 0 (the last checkpoint) for Point
/// and the Drone, whose runs were measured without selection and have not been
/// re-derived with it.
pub fn default_every(robot: sim::Robot) -> usize {
    match robot {
        sim::Robot::Doggo | sim::Robot::Car => 250_000,
        sim::Robot::Point | sim::Robot::Drone => 0,
    }
}

/// One validation of the deployed pair (mean plans, mean actions).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Validation {
    /// Joint iterations done when it was measured (0: the warm-start pair).
    pub iteration: usize,
    /// Joint environment steps done then.
    pub env_steps: usize,
    /// Fraction of the [`SELECT_RUNS`] runs satisfying the task.
    pub satisfaction: f64,
    /// Mean steps to reach of the satisfying runs (`None` when none satisfied).
    pub steps_to_reach: Option<f64>,
}

impl Validation {
    /// Validates `t`'s deployed pair now.
    pub fn of(t: &JointTrainer) -> Result<Self, RunError> {
        let eval = evaluate_task(
            &t.task,
            Plans::Mean(t.plan.planner()),
            &t.control.controller(),
            (1, SELECT_RUNS),
            SELECT_SEED,
        )?;
        Ok(Self {
            iteration: t.iterations,
            env_steps: t.env_steps,
            satisfaction: mean_std(&eval.satisfaction).0,
            steps_to_reach: (!eval.steps_to_reach.is_empty()).then(|| mean_std(&eval.steps_to_reach).0),
        })
    }

    /// Whether `self` beats `other` (see the module's *Order*).
    pub fn beats(&self, other: &Validation) -> bool {
        if self.satisfaction != other.satisfaction {
            return self.satisfaction > other.satisfaction;
        }
        match (self.steps_to_reach, other.steps_to_reach) {
            (Some(a), Some(b)) => a < b,
            _ => false,
        }
    }
}

/// Every validation of a run so far and which one is deployed; saved with each
/// checkpoint, so a resumed run goes on choosing as the uninterrupted one would.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Selection {
    /// The validations, in order.
    pub validations: Vec<Validation>,
    /// Index into `validations` of the best one.
    pub best: Option<usize>,
}

impl Selection {
    /// Whether the pair after `env_steps` joint steps is to be validated, with
    /// validations every `every` steps (`last`: the run's final iteration): at the
    /// first iteration, the first after each multiple of `every`, and the last, once
    /// each; never with `every` 0.
    pub fn due(&self, env_steps: usize, every: usize, last: bool) -> bool {
        if every == 0 {
            return false;
        }
        match self.validations.last() {
            None => true,
            Some(v) if v.env_steps == env_steps => false,
            Some(v) => last || env_steps / every > v.env_steps / every,
        }
    }

    /// Records `v`; `true` when it is the new best.
    pub fn record(&mut self, v: Validation) -> bool {
        let better = self.best().is_none_or(|b| v.beats(b));
        self.validations.push(v);
        if better {
            self.best = Some(self.validations.len() - 1);
        }
        better
    }

    /// The best validation so far.
    pub fn best(&self) -> Option<&Validation> {
        self.best.and_then(|i| self.validations.get(i))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v(iteration: usize, satisfaction: f64, steps: Option<f64>) -> Validation {
        Validation { iteration, env_steps: iteration * 100, satisfaction, steps_to_reach: steps }
    }

    #[test]
    fn more_satisfaction_wins_then_fewer_steps_and_a_tie_keeps_the_earlier() {
        let mut s = Selection::default();
        assert!(s.record(v(0, 0.90, Some(400.0))), "the first validation is the best so far");
        assert!(!s.record(v(10, 0.80, Some(300.0))), "faster but satisfying less");
        assert!(s.record(v(20, 0.90, Some(380.0))), "as satisfying and faster");
        assert!(!s.record(v(30, 0.90, Some(380.0))), "a tie keeps the earlier");
        assert!(s.record(v(40, 0.95, Some(500.0))), "more satisfying though slower");
        assert!(!s.record(v(50, 0.0, None)));
        assert_eq!(s.best().map(|b| b.iteration), Some(40));
    }

    #[test]
    fn validations_fall_on_the_first_iteration_each_crossing_and_the_last_once_each() {
        let mut s = Selection::default();
        assert!(s.due(0, 1000, false), "the warm-start pair");
        s.record(v(0, 0.5, None));
        assert!(!s.due(0, 1000, false), "once");
        assert!(!s.due(900, 1000, false));
        assert!(s.due(1100, 1000, false), "the first iteration past 1000 steps");
        s.record(v(11, 0.5, None));
        assert!(!s.due(1900, 1000, false));
        assert!(s.due(1950, 1000, true), "the run's last iteration");
        s.record(Validation { env_steps: 1950, ..v(19, 0.5, None) });
        assert!(!s.due(1950, 1000, true), "once: a resumed run that validated before saving");
        assert!(!Selection::default().due(0, 0, true), "every 0: selection off");
    }
}
