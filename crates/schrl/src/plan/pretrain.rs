//! Warm-starting the planner on the spec alone, before joint training.
//!
//! [`pretrain`] trains [`PretrainConfig::candidates`] planners from different seeds
//! (the run's seed, then seeds derived from it), [`PretrainConfig::updates`] updates
//! each (batch 64, no execution), with a path-length stand-in for `r_l`
//! (`r_l = −w · metres`: the controller has not run yet, and short plans are easy to
//! drive), and keeps one: among those whose mean paths satisfy the spec from at least
//! [`SATISFYING`] of 200 validation starts, the shortest; else the most satisfying.
//! While none satisfies, more candidates follow, up to three times as many, and up to
//! ten times as many while none has even [`FOUND`] the task. If none of those has
//! found the task, a *guided* candidate follows ([`PretrainConfig::guide`], on by
//! default for budgets of at least [`GUIDE_MIN_UPDATES`] updates a candidate): the
//! gradient planner, drawing waypoints at goal centres, plans from each of a batch of
//! starts, the network is fitted to those plans, and the constrained updates go on
//! from there with a smaller step, with the run's safe margin where the gradient
//! planner meets it, else on the task's own clearance. If still none satisfies with
//! the margin and no guided candidate kept it (satisfying from some starts), the
//! candidates are trained again with the task's own clearance, as many as the rules
//! above ask, a guided candidate without the margin counted among them (the run's
//! `safe_margin` becomes 0 when one of these is kept). A candidate whose attempts keep
//! failing ([`CURRICULUM_AFTER`] restarts) climbs a horizon curriculum where the spec
//! allows: the task on its first few waypoints, then more
//! ([`PretrainConfig::horizon_from`]). The kept planner
//! goes on with its λ, Adam state and random stream: the joint phase continues its
//! training (a λ reset to its initial value would weigh the constraint as at the
//! start of pre-training, not as the planner has learnt it).
//!
//! Why each rule (measured on Point; README): every candidate uses its whole budget,
//! because once the constraint is slack the length term keeps shortening the paths
//! (Seq seed 0: stopping at the first satisfying batch left a detour the controller
//! ran out of time on); several candidates, because a planner can settle on a detour
//! no small change shortens without crossing a wall (Branch seed 0); the curriculum,
//! because a recurrent planner that has learnt a short cycle extends it, where a
//! fresh one on the whole Loop settles at a fixed point on one corner's edge; the
//! guided candidate before the retry, not after it, because a retry that has found
//! nothing runs ten rounds (Drone Signal: 30 candidates, about 4 of its 12–19
//! minutes), and of the recorded runs only one, a Doggo exploration with a 0.25 m
//! margin, found the task in the retry where the first round had not; the guide with
//! the run's margin where a search meets it, because the margin is room for the
//! robot's error along its segments and a guided plan without it passed Drone
//! Signal's duck within 2 cm (seeds 0 and 1: 0.914 and 0.900 without, 0.986 and 1.000
//! with it).

use serde::{Deserialize, Serialize};

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::plan::cpg::{CpgConfig, PathLengthReward, PlanTrainer, TurnReward};
use crate::plan::gradient_planner::{self, GradientPlan, GradientPlannerConfig, WaypointDraw};
use crate::run::joint::JointTrainer;
use crate::task::Task;

/// A candidate satisfies when its mean paths do from this fraction of the validation
/// starts (Point Loop seed 4 kept a candidate at 0.960 under a 0.95 bar, and 10 % of
/// its runs reached a corner outside its disc).
pub const SATISFYING: f64 = 0.99;

/// Validation starts a candidate's mean paths are checked from.
const VALIDATION_STARTS: usize = 200;

/// While no candidate satisfies, up to this many times [`PretrainConfig::candidates`]
/// are tried (Point Loop seed 1: none of the first 3 met the shrunk corner discs).
const EXTRA_ROUNDS: usize = 3;

/// A candidate has found the task when its mean paths satisfy from this fraction of
/// the validation starts; below it the planner is of no use to the joint phase.
pub const FOUND: f64 = 0.9;

/// While no candidate has [`FOUND`] the task, candidates follow beyond
/// [`EXTRA_ROUNDS`], up to this many times [`PretrainConfig::candidates`]. Point Loop
/// seed 9: none of its first 9 candidates found the corner cycle (each ended stuck
/// with every waypoint on the edge of one corner disc, robustness just below 0), so
/// the run kept a planner at 0.000 and failed; among 18, candidates 13–15 did
/// (0.950–0.965).
const FIND_ROUNDS: usize = 10;

/// After this many restarts of a candidate without a promising attempt, its attempts
/// climb a horizon curriculum ([`PretrainConfig::horizon_from`]) where the task has
/// one. 6: no Seq, Cover or Branch candidate of seeds 0–9 restarted more than 4 times
/// before its first promising attempt (Signal has no shorter form), so only the
/// tasks whose plain attempts keep failing climb (Point Loop: about one attempt in
/// 100 finds the corner cycle; README, *Why Loop's warm start is slow*).
pub const CURRICULUM_AFTER: usize = 6;

/// The guided candidate's sizes ([`PretrainConfig::guide`], [`GUIDE`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GuideSizes {
    /// Gradient-planner searches from the start region's centre; the most robust
    /// plan is the reference.
    pub references: usize,
    /// Starts the reference is refined for and the network fitted on.
    pub starts: usize,
    /// Adam steps of the fit ([`PlanTrainer::fit_mean_paths`], from the candidates'
    /// step size down to a tenth of it).
    pub fit_updates: usize,
    /// Fraction of the candidates' step size the constrained updates take.
    pub step_fraction: f64,
    /// Updates a candidate the guided candidate needs ([`GUIDE_MIN_UPDATES`]).
    pub min_updates: usize,
}

/// The guide's sizes, found on Drone Signal with the task's own clearance (a shipped
/// task whose candidates never found it), seeds 0–2:
/// - 13 searches: their plans ranged 0.03–0.10 in robustness; fitted to the most
///   robust, the candidates' mean paths satisfied from 0.90–0.99 of the starts after
///   3000 updates; fitted to the shortest (ρ 0.003–0.05), two of three from none.
/// - 8000 fit steps over 256 starts: 0.05–0.13 m rms.
/// - A thirtieth of the step (3e-3 → 1e-4): at 3e-4 the fitted plans' satisfaction
///   wandered between 0.6 and 0.8 over 2000 updates (seed 0), at 1e-4 it climbed to
///   0.97–1.00. The joint phase keeps it (the kept planner's own settings).
pub const GUIDE: GuideSizes = GuideSizes {
    references: 13,
    starts: 256,
    fit_updates: 8000,
    step_fraction: 1.0 / 30.0,
    min_updates: GUIDE_MIN_UPDATES,
};

/// The guided candidate follows only candidates of at least this many updates
/// ([`PretrainConfig::guide`]). Its constrained updates after the fit are
/// [`PretrainConfig::updates`] long, and on Drone Signal (seeds 0–2) its fitted mean
/// paths needed about 2000 of them at its small step to climb from 0.4–0.7 of the
/// starts to 0.9; below 1000 it cannot find the task either, and its fixed cost (13
/// searches, 256 refinements, 8000 fit steps: 1–3 minutes) would buy nothing, as in a
/// smoke test with a few updates per candidate.
pub const GUIDE_MIN_UPDATES: usize = 1000;

/// Settings of planner pre-training.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PretrainConfig {
    /// Updates per candidate (3000: the planner alone needed up to 2731 updates to
    /// satisfy Signal and 2492 for Loop over seeds 0–4). 0: no pre-training.
    pub updates: usize,
    /// Candidates trained before one is kept (3).
    pub candidates: usize,
    /// Weight of the path-length stand-in for `r_l`, per metre (0.05: without it,
    /// Point Seq plans met the spec by detours the controller could not follow).
    pub length_weight: f64,
    /// Weight per radian of the turn term beside the length one ([`TurnReward`]):
    /// candidates learn plans that turn less. 0 (the default, and runs saved before it
    /// existed): none.
    #[serde(default, skip_serializing_if = "crate::control::trainer::is_zero")]
    pub turn_weight: f64,
    /// Waypoints of the horizon curriculum's first rung (4; 0: no curriculum; runs
    /// saved before it existed have none). An attempt after [`CURRICULUM_AFTER`]
    /// restarts trains on the task's first `horizon_from` waypoints
    /// ([`Task::with_horizon`]), then [`PretrainConfig::horizon_step`] more each time a
    /// batch is promising, then on the whole task; 150 updates on a rung without a
    /// promising batch restart it (the restart rule). Point Loop, planner alone: from
    /// 4 by 2, the 17-waypoint corner cycle was found in 127–4449 updates (10 of 10
    /// seeds); without, about one 150-update attempt in 100 finds it.
    #[serde(default)]
    pub horizon_from: usize,
    /// Waypoints added per rung (2).
    #[serde(default = "two")]
    pub horizon_step: usize,
    /// Whether a guided candidate follows when no candidate has [`FOUND`] the task
    /// (module docs) and the candidates had at least [`GUIDE_MIN_UPDATES`] updates.
    /// On by default since 2026-12-06 (off before): of this project's recorded runs,
    /// only Drone Signal, Drone Loop seeds 4, 6, 7 and a Doggo Fig. 6 ablation (the
    /// MLP planner) ended pre-training without having found the task, so it changes
    /// no other result. Runs saved before it existed had none.
    #[serde(default)]
    pub guide: bool,
}

fn two() -> usize {
    2
}

impl Default for PretrainConfig {
    fn default() -> Self {
        Self {
            updates: 3000,
            candidates: 3,
            length_weight: 0.05,
            turn_weight: 0.0,
            horizon_from: 4,
            horizon_step: 2,
            guide: true,
        }
    }
}

impl PretrainConfig {
    /// The stand-in for `r_l` the candidates follow: the path's length and its turns.
    pub fn path_terms(&self) -> (PathLengthReward, TurnReward) {
        (PathLengthReward { weight: self.length_weight }, TurnReward { weight: self.turn_weight })
    }

    /// Checks the settings, naming the bad one.
    pub fn validate(&self) -> Result<(), String> {
        if self.candidates == 0 {
            return Err("pretrain.candidates must be at least 1".into());
        }
        if self.horizon_step == 0 {
            return Err("pretrain.horizon_step must be at least 1".into());
        }
        for (name, w) in [("length_weight", self.length_weight), ("turn_weight", self.turn_weight)] {
            if !(w >= 0.0 && w.is_finite()) {
                return Err(format!("pretrain.{name} must be a non-negative number, got {w}"));
            }
        }
        Ok(())
    }
}

/// Progress of pre-training, for a progress display.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PretrainProgress {
    /// Updates done over all candidates so far.
    pub done: usize,
    /// Updates planned (grows when more candidates follow).
    pub total: usize,
    /// The candidate training (1-based).
    pub candidate: usize,
    /// Fraction of its last batch that satisfied the spec.
    pub satisfaction: f64,
}

/// One trained candidate, as validated.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CandidateScore {
    /// Fraction of validation starts whose mean path satisfies the spec.
    pub satisfaction: f64,
    /// Mean length of those paths (metres).
    pub length: f64,
    /// Whether it planned with the run's safe margin (else with the task's own
    /// clearance, the retry or the guided candidate).
    pub with_safe_margin: bool,
    /// Whether it is the guided candidate ([`PretrainConfig::guide`]).
    #[serde(default)]
    pub guided: bool,
}

/// What pre-training kept.
#[derive(Clone, Debug, PartialEq)]
pub struct Pretrained {
    /// Fraction of validation starts whose mean path satisfies the spec.
    pub satisfaction: f64,
    /// Mean length of those paths (metres).
    pub length: f64,
    /// Whether candidates were trained again with the task's own clearance (none
    /// satisfied with the safe margin).
    pub retried_without_safe_margin: bool,
    /// Whether the kept planner is one of those (the run's `safe_margin` is then 0).
    pub dropped_safe_margin: bool,
    /// Whether the kept planner is the guided candidate ([`PretrainConfig::guide`]).
    pub guided: bool,
    /// Every candidate trained, in order (so a user can see how hard the spec was).
    pub candidates: Vec<CandidateScore>,
}

/// Where pre-training stands after a candidate: enough to go on exactly. Each
/// candidate's training depends only on its round and its index (its seed is
/// derived from the run's), so a run that goes on from here trains the candidates
/// that follow as a run never stopped would have.
#[derive(Default)]
pub struct PretrainState {
    /// Every candidate validated so far, in order.
    pub scores: Vec<CandidateScore>,
    /// The best candidate of the first round (the run's safe margin).
    pub best_with_margin: Option<Candidate>,
    /// The best candidate of the retry with the task's own clearance.
    pub best_own: Option<Candidate>,
    /// Whether the guided candidate was tried (it is `None` when the gradient planner
    /// found no plan to fit, or pre-training never asked for it).
    pub guide_tried: bool,
    /// The guided candidate ([`PretrainConfig::guide`]).
    pub guided: Option<Candidate>,
}

impl PretrainState {
    /// The best candidate of the round with (or without) the safe margin.
    fn best(&self, with_safe_margin: bool) -> &Option<Candidate> {
        if with_safe_margin { &self.best_with_margin } else { &self.best_own }
    }

    /// Whether the guided candidate planned with the run's safe margin (its score says).
    fn guided_with_margin(&self) -> bool {
        self.scores.iter().any(|c| c.guided && c.with_safe_margin)
    }

    /// How satisfying the best candidate of a round is, the guided candidate counted
    /// in the round whose clearance it planned with.
    fn best_satisfaction(&self, with_safe_margin: bool) -> f64 {
        let guided = self.guided.as_ref().filter(|_| self.guided_with_margin() == with_safe_margin);
        [self.best(with_safe_margin).as_ref(), guided]
            .into_iter()
            .flatten()
            .map(|c| c.satisfaction)
            .fold(0.0, f64::max)
    }
}

/// What [`pretrain_from`] tells its caller as it goes.
pub trait PretrainObserver {
    /// What [`PretrainObserver::candidate`] may fail with.
    type Error: From<candle_core::Error>;
    /// Called after every update.
    fn update(&mut self, progress: PretrainProgress);
    /// Called after each candidate is validated and kept or dropped, and after the
    /// guided one is tried: where to checkpoint. An error
    /// (a failed save, a stop request) ends pre-training with it.
    fn candidate(&mut self, state: &PretrainState) -> Result<(), Self::Error>;
}

/// An observer that only shows progress.
struct ProgressOnly<'a>(&'a mut dyn FnMut(PretrainProgress));

impl PretrainObserver for ProgressOnly<'_> {
    type Error = candle_core::Error;
    fn update(&mut self, progress: PretrainProgress) {
        (self.0)(progress)
    }
    fn candidate(&mut self, _: &PretrainState) -> candle_core::Result<()> {
        Ok(())
    }
}

/// Pre-trains `t`'s planner (module docs) and installs the kept one. `progress` is
/// called after every update. `None` when no candidate trained (`updates` 0).
pub fn pretrain(
    t: &mut JointTrainer,
    cfg: &PretrainConfig,
    progress: &mut dyn FnMut(PretrainProgress),
) -> candle_core::Result<Option<Pretrained>> {
    pretrain_from(t, cfg, PretrainState::default(), &mut ProgressOnly(progress))
}

/// [`pretrain`], going on from `state` (saved by an earlier call's `observer`, for
/// the same `t` and `cfg`; [`PretrainState::default`] to start), telling
/// `observer` after every update and every candidate.
pub fn pretrain_from<O: PretrainObserver>(
    t: &mut JointTrainer,
    cfg: &PretrainConfig,
    state: PretrainState,
    observer: &mut O,
) -> Result<Option<Pretrained>, O::Error> {
    pretrain_sized(t, cfg, &GUIDE, state, observer)
}

/// [`pretrain_from`] with the guided candidate of `sizes` (tests use small ones).
pub(crate) fn pretrain_sized<O: PretrainObserver>(
    t: &mut JointTrainer,
    cfg: &PretrainConfig,
    sizes: &GuideSizes,
    mut state: PretrainState,
    observer: &mut O,
) -> Result<Option<Pretrained>, O::Error> {
    if cfg.updates == 0 {
        return Ok(None);
    }
    let sat_of = |c: &Option<Candidate>| c.as_ref().map_or(0.0, |c| c.satisfaction);
    let base = *t.plan.config();
    best_candidate(&base, &candidate_task(t, true)?, cfg, &mut state, true, observer)?;
    let wants_guide =
        cfg.guide && cfg.updates >= sizes.min_updates && sat_of(&state.best_with_margin) < FOUND;
    if wants_guide && !state.guide_tried {
        // With the run's safe margin where a search meets it, as the first round: a
        // plan that keeps it leaves the joint phase the margin too (Drone Signal, with
        // the Drone holding its segments: README). Else on the task's own clearance,
        // as the retry. Each try draws from its own stream, so a run whose searches
        // find nothing with the margin guides as before the margin was tried.
        let margins: &[bool] = if t.config.safe_margin > 0.0 { &[true, false] } else { &[false] };
        let done = state.scores.len() * cfg.updates;
        let candidate = state.scores.len() + 1;
        let mut found = None;
        for &with_margin in margins {
            let task = candidate_task(t, with_margin)?;
            let g = guided_candidate(&base, &task, cfg, sizes, &mut |i, satisfaction| {
                observer.update(PretrainProgress {
                    done: done + i,
                    total: done + cfg.updates,
                    candidate,
                    satisfaction,
                })
            })?;
            if let Some(g) = g {
                found = Some((g, with_margin));
                break;
            }
        }
        if let Some((g, with_safe_margin)) = &found {
            state.scores.push(CandidateScore {
                satisfaction: g.satisfaction,
                length: g.length,
                with_safe_margin: *with_safe_margin,
                guided: true,
            });
        }
        (state.guide_tried, state.guided) = (true, found.map(|(g, _)| g));
        observer.candidate(&state)?;
    }
    // A guided candidate that kept the margin ends the search, once its mean paths
    // satisfy from any start: the retry is for a margin no plan keeps, and the
    // gradient planner found one that does (Drone Signal seeds 0 and 1: after one at
    // 0.50 and 0.41 of the starts, the retry's 30 candidates found nothing, 5 minutes;
    // the joint phase took the guided ones to 0.986 and 1.000). One whose fit found
    // nothing leaves the retry its chance.
    let guided_with_margin = state.guided_with_margin();
    let guide_kept_margin = guided_with_margin && state.guided.as_ref().is_some_and(|g| g.satisfaction > 0.0);
    let retried =
        !guide_kept_margin && state.best_satisfaction(true) < SATISFYING && t.config.safe_margin > 0.0;
    if retried {
        best_candidate(&base, &candidate_task(t, false)?, cfg, &mut state, false, observer)?;
    }
    let PretrainState { scores, best_with_margin: mut best, best_own, guided: guided_candidate, .. } = state;
    let mut keeps_margin = true;
    if sat_of(&best_own) > sat_of(&best) {
        best = best_own;
        keeps_margin = false;
    }
    let mut guided = false;
    if sat_of(&guided_candidate) > sat_of(&best) {
        best = guided_candidate;
        guided = true;
        keeps_margin = guided_with_margin;
    }
    let dropped = !keeps_margin && t.config.safe_margin > 0.0;
    if dropped {
        t.config.safe_margin = 0.0;
    }
    let Some(c) = best else { return Ok(None) };
    let mut plan = c.trainer;
    plan.set_control_reward(Box::new(t.config.path_terms()));
    t.plan = plan;
    if t.config.turn_margin > 0.0 {
        let joint = planned(t, true)?;
        t.plan.set_task(joint)?;
    }
    // The kept planner is the warm start the joint phase's trust region holds to.
    let anchor = if t.config.freeze_planner { 0.0 } else { t.config.anchor_weight };
    t.plan.anchor_here(anchor, t.config.anchor_on)?;
    t.plan.limit_joint_step(t.config.plan_step_limit)?;
    Ok(Some(Pretrained {
        satisfaction: c.satisfaction,
        length: c.length,
        retried_without_safe_margin: retried,
        dropped_safe_margin: dropped,
        guided,
        candidates: scores,
    }))
}

/// A trained candidate and its validation.
pub struct Candidate {
    /// Its trainer, as after validation.
    pub trainer: PlanTrainer,
    /// Fraction of validation starts whose mean path satisfies the spec.
    pub satisfaction: f64,
    /// Mean length of those paths (metres).
    pub length: f64,
}

/// The task the candidates of a round plan for (with the run's safe margin, or with
/// the task's own clearance): the turn margin is the joint phase's, not theirs (the
/// search does not find plans with it, Doggo Seq seed 0, 0.5 m: none of 30
/// candidates; the constrained updates move a found plan's turns out).
pub fn candidate_task(t: &JointTrainer, with_safe_margin: bool) -> candle_core::Result<Task> {
    let task = if with_safe_margin { t.plan.task().clone() } else { planned(t, false)? };
    Ok(task.with_turn_margin(0.0))
}

/// The task `t`'s planner plans for ([`crate::run::joint::JointConfig::planned_task`]).
fn planned(t: &JointTrainer, with_safe_margin: bool) -> candle_core::Result<Task> {
    t.config.planned_task(&t.task, with_safe_margin).map_err(|e| candle_core::Error::Msg(e.to_string()))
}

/// Trains the candidates of one round of [`pretrain`] on `task` (the round with the
/// safe margin, or the retry), going on after those `state` already scored, and
/// keeps the round's best in `state`; `observer` hears each update and each
/// candidate.
fn best_candidate<O: PretrainObserver>(
    base: &CpgConfig,
    task: &Task,
    cfg: &PretrainConfig,
    state: &mut PretrainState,
    with_safe_margin: bool,
    observer: &mut O,
) -> Result<(), O::Error> {
    let done = state.scores.iter().filter(|c| c.with_safe_margin == with_safe_margin && !c.guided).count();
    for k in done..cfg.candidates * FIND_ROUNDS {
        let best_sat = state.best_satisfaction(with_safe_margin);
        if (k >= cfg.candidates && best_sat >= SATISFYING)
            || (k >= cfg.candidates * EXTRA_ROUNDS && best_sat >= FOUND)
        {
            break;
        }
        let seeded = CpgConfig { seed: base.seed.wrapping_add(k as u64 * 1_000_003), ..*base };
        let mut plan = PlanTrainer::new(task.clone(), seeded)?;
        let total = cfg.updates * (k + 1).max(cfg.candidates);
        train_candidate(&mut plan, task, cfg, &mut |i, satisfaction| {
            observer.update(PretrainProgress {
                done: k * cfg.updates + i,
                total,
                candidate: k + 1,
                satisfaction,
            })
        })?;
        let (satisfaction, length) =
            (plan.mean_satisfaction(VALIDATION_STARTS)?, plan.mean_path_length(VALIDATION_STARTS)?);
        state.scores.push(CandidateScore { satisfaction, length, with_safe_margin, guided: false });
        let better = match state.best(with_safe_margin) {
            None => true,
            Some(b) if satisfaction >= SATISFYING && b.satisfaction >= SATISFYING => length < b.length,
            Some(b) => satisfaction > b.satisfaction,
        };
        if better {
            let kept = Some(Candidate { trainer: plan, satisfaction, length });
            match with_safe_margin {
                true => state.best_with_margin = kept,
                false => state.best_own = kept,
            }
        }
        observer.candidate(state)?;
    }
    Ok(())
}

/// The guided candidate (module docs) for `task`, `None` when the gradient planner
/// found no plan to fit: the reference from the start region's centre, the most
/// robust of `sizes.references` searches with waypoints drawn at goal centres; from
/// each of `sizes.starts` starts, the reference with that start, refined (no
/// redraws) until it is half as robust or better, so every start's plan keeps the
/// reference's shape and the network fits one smooth map from starts to plans (a
/// search per start picks other goals from other starts, and a network fitted to
/// those satisfied from none); the fit; then [`PretrainConfig::updates`]
/// constrained updates without the length stand-in, at `sizes.step_fraction` of
/// the step and never restarting. `update` hears each update's number and batch
/// satisfaction.
fn guided_candidate(
    base: &CpgConfig,
    task: &Task,
    cfg: &PretrainConfig,
    sizes: &GuideSizes,
    update: &mut dyn FnMut(usize, f64),
) -> candle_core::Result<Option<Candidate>> {
    let stl_err = |e: stl::EvalError| candle_core::Error::Msg(format!("spec: {e}"));
    let spec = task.spec();
    let dim = task.map.dim();
    let mut rng = ChaCha8Rng::seed_from_u64(base.seed ^ 0x6_u64.wrapping_mul(0x9E37_79B9_7F4A_7C15));
    // No target: each search ascends to the end of its attempt, the most robust
    // plan it meets.
    let search = GradientPlannerConfig {
        draw: WaypointDraw::GoalCentres,
        target: f64::INFINITY,
        ..Default::default()
    };
    let centre: Vec<f64> = task.start.0.iter().zip(&task.start.1).map(|(l, h)| (l + h) / 2.0).collect();
    let mut reference: Option<GradientPlan> = None;
    for _ in 0..sizes.references {
        let p = gradient_planner::plan(task, &spec, &centre, &search, &mut rng).map_err(stl_err)?;
        if reference.as_ref().is_none_or(|r| p.robustness > r.robustness) {
            reference = Some(p);
        }
    }
    let reference = reference.expect("at least one search");
    if !reference.satisfied() {
        return Ok(None);
    }
    let refine = GradientPlannerConfig { repair_every: 0, target: reference.robustness / 2.0, ..search };
    let (mut starts, mut targets) = (vec![], vec![]);
    for _ in 0..sizes.starts {
        let start = task.sample_start(&mut rng);
        let mut path = reference.path.clone();
        path[..dim].copy_from_slice(&start);
        let p = gradient_planner::refine(task, &spec, path, &refine, &mut rng).map_err(stl_err)?;
        if p.satisfied() {
            starts.extend(start.iter().map(|x| *x as f32));
            targets.extend(p.path.iter().map(|x| *x as f32));
        }
    }
    if starts.is_empty() {
        return Ok(None);
    }
    let guided = CpgConfig {
        seed: base.seed.wrapping_add(0x6_1DE),
        lr: base.lr * sizes.step_fraction,
        restart_after: None,
        ..*base
    };
    let mut plan = PlanTrainer::new(task.clone(), guided)?;
    plan.fit_mean_paths(&starts, &targets, sizes.fit_updates, base.lr)?;
    for i in 1..=cfg.updates {
        let s = plan.update()?;
        update(i, s.satisfaction);
    }
    let (satisfaction, length) =
        (plan.mean_satisfaction(VALIDATION_STARTS)?, plan.mean_path_length(VALIDATION_STARTS)?);
    Ok(Some(Candidate { trainer: plan, satisfaction, length }))
}

/// Trains one candidate for [`PretrainConfig::updates`] updates on `task` with the
/// length stand-in; its attempts after the [`CURRICULUM_AFTER`]th restart climb the
/// horizon curriculum ([`PretrainConfig::horizon_from`]) where `task` has one. Ends
/// on `task` whatever rung it reached. `update` hears each update's number (1-based)
/// and batch satisfaction.
fn train_candidate(
    plan: &mut PlanTrainer,
    task: &Task,
    cfg: &PretrainConfig,
    update: &mut dyn FnMut(usize, f64),
) -> candle_core::Result<()> {
    plan.set_control_reward(Box::new(cfg.path_terms()));
    let rungs: Vec<Task> = match cfg.horizon_from {
        0 => vec![],
        from => (from..task.steps).step_by(cfg.horizon_step).map_while(|n| task.with_horizon(n)).collect(),
    };
    // The rung the current attempt trains on; `None`: the whole task.
    let mut rung: Option<usize> = None;
    let mut restarts = plan.restarts();
    for i in 1..=cfg.updates {
        let s = plan.update()?;
        update(i, s.satisfaction);
        if plan.restarts() != restarts {
            restarts = plan.restarts();
            // A fresh attempt starts at the bottom rung (or, before the curriculum,
            // on the task it already trains on: no spec to rebuild).
            let bottom = (restarts >= CURRICULUM_AFTER && !rungs.is_empty()).then_some(0);
            if bottom.is_some() && rung != bottom {
                plan.set_task(rungs[0].clone())?;
            }
            rung = bottom;
        } else if let Some(r) = rung.filter(|_| plan.promising()) {
            rung = Some(r + 1).filter(|&next| next < rungs.len());
            plan.set_task(rung.map_or(task, |r| &rungs[r]).clone())?;
            plan.restart_clock();
        }
    }
    if rung.is_some() {
        plan.set_task(task.clone())?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::{ControlConfig, ControlTrainer};
    use crate::run::joint::JointConfig;
    use crate::store::{self, Existing, RunKind, RunWriter};
    use crate::task::TaskKind;

    /// The guide's sizes for tests: small, and after candidates of any budget.
    const SMALL_GUIDE: GuideSizes =
        GuideSizes { references: 4, starts: 64, fit_updates: 3000, min_updates: 0, ..GUIDE };

    /// A Point run of `kind` with `safe_margin` metres more clearance, whose candidates
    /// of `PRE` (two updates each) never find the task.
    fn point_run(kind: TaskKind, safe_margin: f64) -> JointTrainer {
        let control = ControlTrainer::new(ControlConfig::for_robot(sim::Robot::Point)).unwrap();
        let cfg = JointConfig { safe_margin, ..JointConfig::default() };
        JointTrainer::new(Task::point(kind), cfg, CpgConfig::default(), control).unwrap()
    }

    /// Point Seq with a safe margin no plan keeps (wider than the corridors), so the
    /// guided candidate plans with the task's own clearance.
    fn point_seq() -> JointTrainer {
        point_run(TaskKind::Seq, 5.0)
    }

    /// Pre-trains `t` with `PRE` and the small guide, hearing nothing.
    fn pretrained(t: &mut JointTrainer, cfg: &PretrainConfig) -> Pretrained {
        let mut quiet = |_: PretrainProgress| {};
        pretrain_sized(t, cfg, &SMALL_GUIDE, PretrainState::default(), &mut ProgressOnly(&mut quiet))
            .unwrap()
            .unwrap()
    }

    /// Regression: the guided candidate planned with the task's own clearance only,
    /// so the joint phase of every guided run lost the safe margin and its plans
    /// passed obstacles at the robot's radius (Drone Signal with the Drone holding
    /// its segments: 43 of 500 runs of seed 0 collided on hops its plans passed the
    /// duck within 2 cm on). Where the gradient planner meets the margin, the guided
    /// candidate plans with it and ends the search (no retry with the task's own
    /// clearance: a plan keeps the margin), and the run keeps the margin.
    #[test]
    fn the_guided_candidate_keeps_the_safe_margin_where_a_search_meets_it() {
        let mut t = point_run(TaskKind::Seq, 0.1);
        let kept = pretrained(&mut t, &PRE);
        let c = &kept.candidates;
        assert!(c[..10].iter().all(|c| c.with_safe_margin && !c.guided && c.satisfaction < FOUND), "{c:?}");
        assert!(c[10].guided && c[10].with_safe_margin && c[10].satisfaction >= FOUND, "{c:?}");
        assert_eq!(c.len(), 11, "no retry after a guided candidate that kept the margin: {c:?}");
        assert!(kept.guided && !kept.retried_without_safe_margin && !kept.dropped_safe_margin, "{kept:?}");
        assert_eq!((kept.satisfaction, t.config.safe_margin), (c[10].satisfaction, 0.1));
    }

    const PRE: PretrainConfig = PretrainConfig {
        updates: 2,
        candidates: 1,
        length_weight: 0.05,
        turn_weight: 0.0,
        horizon_from: 4,
        horizon_step: 2,
        guide: true,
    };

    /// Why the saving observer stopped pre-training: it was asked to (any other
    /// failure fails the test where it happens).
    #[derive(Debug)]
    struct AfterGuide;

    impl From<candle_core::Error> for AfterGuide {
        fn from(e: candle_core::Error) -> Self {
            panic!("pre-training failed: {e}")
        }
    }

    /// Saves pre-training after each candidate, as `schrl train` does, and stops once
    /// the guided candidate was tried when asked to.
    struct Saving {
        writer: RunWriter,
        stop_after_guide: bool,
    }

    impl PretrainObserver for Saving {
        type Error = AfterGuide;
        fn update(&mut self, _: PretrainProgress) {}
        fn candidate(&mut self, state: &PretrainState) -> Result<(), AfterGuide> {
            self.writer.save(|f| store::pretrain::save_into(f, state)).unwrap();
            if self.stop_after_guide && state.guide_tried { Err(AfterGuide) } else { Ok(()) }
        }
    }

    /// Regression: the guided candidate came after the retry with the task's own
    /// clearance, so a run whose candidates never found the task first trained ten
    /// rounds more (Drone Signal: 30 candidates, about 4 minutes). Now it follows the
    /// first round, and the retry counts it as found when it planned with the task's
    /// own clearance (no search met the margin): one round if it satisfies, else
    /// three (the candidates' own two updates find nothing; the guided one, the network
    /// fitted to the gradient planner's plans, finds the task). It is saved like every candidate: a run cut off after it goes on without
    /// fitting it again and ends bit for bit where a run never stopped ends.
    #[test]
    fn the_guided_candidate_comes_before_the_retry_shortens_it_and_is_saved() {
        let scratch = tempfile::tempdir().unwrap();
        let run = |dir: &str, stop_after_guide: bool| {
            let writer =
                RunWriter::create(&scratch.path().join(dir), RunKind::Pretrain, &PRE, Existing::Refuse)
                    .unwrap();
            let mut t = point_seq();
            let mut saving = Saving { writer, stop_after_guide };
            let kept = pretrain_sized(&mut t, &PRE, &SMALL_GUIDE, PretrainState::default(), &mut saving);
            (t, kept, saving.writer)
        };
        let (mut whole, kept, _) = run("whole", false);
        let kept = kept.unwrap().unwrap();
        let c = &kept.candidates;
        assert!(c[..10].iter().all(|c| c.with_safe_margin && !c.guided && c.satisfaction < FOUND), "{c:?}");
        assert!(c[10].guided && !c[10].with_safe_margin && c[10].satisfaction >= FOUND, "{c:?}");
        let retry = if c[10].satisfaction >= SATISFYING { 1 } else { EXTRA_ROUNDS };
        assert_eq!(c.len(), 11 + retry, "the retry after it: {c:?}");
        assert!(c[11..].iter().all(|c| !c.with_safe_margin && !c.guided));
        assert!(kept.guided && kept.retried_without_safe_margin && kept.dropped_safe_margin);
        assert_eq!((kept.satisfaction, whole.config.safe_margin), (c[10].satisfaction, 0.0));
        // The kept planner trains on at a fraction of the step, never restarting.
        let (own, base) = (whole.plan.config(), CpgConfig::default());
        assert_eq!((own.lr, own.restart_after), (base.lr * GUIDE.step_fraction, None));

        let (_, stopped, writer) = run("stopped", true);
        assert!(matches!(stopped, Err(AfterGuide)), "{stopped:?}");
        let mut resumed = point_seq();
        let state = store::pretrain::load_from(&writer.checkpoint(), &resumed).unwrap();
        assert!(state.guide_tried && state.guided.is_some() && state.scores.len() == 11);
        let mut heard = 0;
        let mut count = |p: PretrainProgress| heard = heard.max(p.candidate);
        let rest = pretrain_sized(&mut resumed, &PRE, &SMALL_GUIDE, state, &mut ProgressOnly(&mut count))
            .unwrap()
            .unwrap();
        assert!(
            heard <= EXTRA_ROUNDS,
            "only the retry's candidates trained, not the guide's {} updates",
            PRE.updates
        );
        assert_eq!(rest, kept);
        let sample = |t: &mut JointTrainer| {
            t.plan.sample(8).unwrap().paths.flatten_all().unwrap().to_vec1::<f32>().unwrap()
        };
        assert_eq!(sample(&mut resumed), sample(&mut whole), "the kept planner, weights and random stream");
        assert_eq!(resumed.plan.state(), whole.plan.state());
    }

    /// A candidate is validated, and kept, on the whole task: one whose updates ran
    /// out on a rung of the curriculum must not be judged on a shorter path.
    #[test]
    fn a_candidate_that_ends_on_a_rung_ends_on_the_whole_task() {
        let task = Task::point(TaskKind::Loop);
        // Restarting after every update reaches CURRICULUM_AFTER at once, and no
        // attempt is promising after one update.
        let cpg = CpgConfig { restart_after: Some(1), ..CpgConfig::default() };
        let cfg = PretrainConfig { updates: CURRICULUM_AFTER + 3, ..PretrainConfig::default() };
        let mut plan = PlanTrainer::new(task.clone(), cpg).unwrap();
        let mut seen = vec![];
        train_candidate(&mut plan, &task, &cfg, &mut |i, _| seen.push(i)).unwrap();
        assert_eq!(seen, (1..=cfg.updates).collect::<Vec<_>>());
        assert!(plan.restarts() > CURRICULUM_AFTER);
        assert_eq!((plan.task().steps, plan.task().formula()), (task.steps, task.formula()));
    }
}
