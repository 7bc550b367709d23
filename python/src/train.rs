//! `schrl.train`: a task trained end to end into a run directory, through the same
//! library call as `schrl train` (`schrl::train::RunSession`), with the GIL released
//! while it trains and a Python callable as its progress hook.

use std::path::PathBuf;

use pyo3::exceptions::{PyFileExistsError, PyKeyboardInterrupt, PyRuntimeError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use schrl::plan::cpg::{AnchorKind, Method};
use schrl::plan::planner::PlannerKind;
use schrl::run::joint::{JointMetrics, JointRunSettings};
use schrl::store::{Existing, StoreError};
use schrl::task::Task;
use schrl::train::{Progress, ResumeChanges, RunSession, Stop, TrainError, Watcher};
use sim::Robot;

/// The settings keywords of `schrl.train`: `schrl train`'s flags with `_` for `-`.
const SETTINGS: [&str; 33] = [
    "steps",
    "target",
    "controller",
    "semantics",
    "planner",
    "plan_batch",
    "method",
    "pg_weight",
    "lambda_lr",
    "pretrain_updates",
    "pretrain_candidates",
    "pretrain_horizon_from",
    "pretrain_length_weight",
    "pretrain_turn_weight",
    "pretrain_guide",
    "freeze_planner",
    "runs_per_start",
    "control_weight",
    "length_weight",
    "turn_weight",
    "anchor_weight",
    "anchor_on",
    "plan_step_limit",
    "freeze_controller",
    "goal_margin",
    "safe_margin",
    "turn_margin",
    "obstacle_sdf",
    "eval_groups",
    "save_every",
    "select_every",
    "select_rule",
    "controller_tries",
];

/// Sets the setting `key` of `s` to `value`; returns whether its value changed.
fn apply(s: &mut JointRunSettings, key: &str, value: &Bound<'_, PyAny>) -> PyResult<bool> {
    fn set<T: PartialEq>(slot: &mut T, v: T) -> bool {
        let changed = *slot != v;
        *slot = v;
        changed
    }
    let get = |what: &str| PyTypeError::new_err(format!("{key}: expected {what}, got {value}"));
    let count = || value.extract::<usize>().map_err(|_| get("a whole number"));
    let number = || value.extract::<f64>().map_err(|_| get("a number"));
    let flag = || value.extract::<bool>().map_err(|_| get("True or False"));
    let text = || value.extract::<String>().map_err(|_| get("a string"));
    let j = &mut s.joint;
    Ok(match key {
        "steps" => set(&mut s.steps, count()?),
        "target" => set(&mut s.target, Some(number()?)),
        "controller" => set(&mut s.controller, Some(value.extract::<PathBuf>().map_err(|_| get("a path"))?)),
        "semantics" => set(&mut s.cpg.semantics, parsed(key, &text()?)?),
        "planner" => {
            let kind = parsed::<PlannerKind>(key, &text()?)?;
            let changed = kind != s.cpg.planner;
            s.set_planner(kind);
            changed
        }
        "plan_batch" => set(&mut j.plan_batch, count()?),
        "method" => set(&mut s.cpg.method, parsed::<Method>(key, &text()?)?),
        "pg_weight" => set(&mut s.cpg.pg_weight, number()?),
        "lambda_lr" => set(&mut s.cpg.lambda_lr, number()?),
        "pretrain_updates" => set(&mut s.pretrain.updates, count()?),
        "pretrain_candidates" => set(&mut s.pretrain.candidates, count()?),
        "pretrain_horizon_from" => set(&mut s.pretrain.horizon_from, count()?),
        "pretrain_length_weight" => set(&mut s.pretrain.length_weight, number()?),
        "pretrain_turn_weight" => set(&mut s.pretrain.turn_weight, number()?),
        "pretrain_guide" => set(&mut s.pretrain.guide, flag()?),
        "freeze_planner" => set(&mut j.freeze_planner, flag()?),
        "runs_per_start" => set(&mut j.runs_per_start, count()?),
        "control_weight" => set(&mut j.control_weight, number()?),
        "length_weight" => set(&mut j.length_weight, number()?),
        "turn_weight" => set(&mut j.turn_weight, number()?),
        "anchor_weight" => set(&mut j.anchor_weight, number()?),
        "anchor_on" => set(&mut j.anchor_on, parsed::<AnchorKind>(key, &text()?)?),
        "plan_step_limit" => set(&mut j.plan_step_limit, number()?),
        "freeze_controller" => set(&mut j.freeze_controller, flag()?),
        "goal_margin" => set(&mut j.goal_margin, number()?),
        "safe_margin" => set(&mut j.safe_margin, number()?),
        "turn_margin" => set(&mut j.turn_margin, number()?),
        // `schrl train --obstacle-sdf`: the neural SDF (a `schrl sdf fit` file) the planner sees.
        "obstacle_sdf" => {
            let path = value.extract::<PathBuf>().map_err(|_| get("a path"))?;
            let net = schrl::store::sdf::load(&path).map_err(|e| PyValueError::new_err(e.to_string()))?;
            set(&mut j.neural_obstacle, Some(net))
        }
        "eval_groups" => set(&mut s.eval_groups, count()?),
        "save_every" => set(&mut s.save_every, count()?),
        "select_every" => set(&mut s.select_every, count()?),
        "select_rule" => set(&mut s.select_rule, parsed(key, &text()?)?),
        "controller_tries" => set(&mut s.controller_tries, count()?),
        other => {
            return Err(PyTypeError::new_err(format!(
                "train() got an unexpected keyword argument '{other}'; the settings are {}",
                SETTINGS.join(", ")
            )));
        }
    })
}

/// Sets every given (not None) setting of `settings` in `s`; returns the names of
/// those that changed a value.
fn apply_all(s: &mut JointRunSettings, settings: Option<&Bound<'_, PyDict>>) -> PyResult<Vec<String>> {
    let mut changed = vec![];
    let mut given = settings
        .into_iter()
        .flat_map(|d| d.iter())
        .map(|(k, v)| Ok((k.extract::<String>()?, v)))
        .collect::<PyResult<Vec<_>>>()?;
    // The planner first: choosing one resets the anchor weight it cannot use, and a
    // weight given beside it must win whatever the keywords' order.
    given.sort_by_key(|(k, _)| k != "planner");
    for (key, value) in given {
        if !value.is_none() && apply(s, &key, &value)? {
            changed.push(key);
        }
    }
    Ok(changed)
}

/// `schrl.train`'s view of a run: progress and notes to the Python callback (notes to
/// stderr without one), Ctrl-C and a raising callback as requests to stop.
struct PyWatcher {
    callback: Option<Py<PyAny>>,
    /// The exception that stopped training (KeyboardInterrupt, or the callback's).
    raised: Option<PyErr>,
}

impl PyWatcher {
    fn call(&mut self, fill: impl FnOnce(&Bound<'_, PyDict>) -> PyResult<()>) {
        if self.raised.is_some() {
            return;
        }
        let Some(cb) = &self.callback else { return };
        Python::with_gil(|py| {
            let d = PyDict::new(py);
            if let Err(e) = fill(&d).and_then(|()| cb.call1(py, (d,)).map(drop)) {
                self.raised = Some(e);
            }
        });
    }
}

impl Watcher for PyWatcher {
    fn progress(&mut self, p: Progress<'_>) {
        self.call(|d| match p {
            Progress::Controller { metrics, total } => {
                d.set_item("stage", "controller")?;
                d.set_item("done", metrics.update)?;
                d.set_item("total", total)?;
                d.set_item("success_rate", metrics.success_rate)
            }
            Progress::Pretrain(p) => {
                d.set_item("stage", "pretrain")?;
                d.set_item("done", p.done)?;
                d.set_item("total", p.total)?;
                d.set_item("candidate", p.candidate)?;
                d.set_item("plan_satisfaction", p.satisfaction)
            }
            Progress::Joint { metrics, total_steps, satisfaction, plan_satisfaction } => {
                d.set_item("stage", "joint")?;
                d.set_item("done", metrics.env_steps)?;
                d.set_item("total", total_steps)?;
                d.set_item("iteration", metrics.iteration)?;
                d.set_item("satisfaction", satisfaction)?;
                d.set_item("plan_satisfaction", plan_satisfaction)?;
                d.set_item("lambda", metrics.lambda)
            }
        });
    }

    fn note(&mut self, note: &str) {
        if self.callback.is_none() {
            eprintln!("{note}");
        }
        self.call(|d| {
            d.set_item("stage", "note")?;
            d.set_item("message", note)
        });
    }

    fn stop_requested(&mut self) -> bool {
        if self.raised.is_none()
            && let Err(e) = Python::with_gil(|py| py.check_signals())
        {
            self.raised = Some(e);
        }
        self.raised.is_some()
    }
}

fn train_error(e: TrainError) -> PyErr {
    match e {
        TrainError::Setting(e) => PyValueError::new_err(e.to_string()),
        TrainError::Task(e) => PyValueError::new_err(format!("task: {e}")),
        TrainError::Store(e @ StoreError::Exists { .. }) => PyFileExistsError::new_err(format!(
            "{e}; pass force=True to replace it, or resume=True to continue it"
        )),
        e => PyRuntimeError::new_err(e.to_string()),
    }
}

fn parsed<T: std::str::FromStr>(name: &str, text: &str) -> PyResult<T>
where
    T::Err: std::fmt::Display,
{
    text.parse::<T>().map_err(|e| PyValueError::new_err(format!("{name}: {e}")))
}

/// One joint iteration as a dict.
fn metrics_dict<'py>(py: Python<'py>, m: &JointMetrics) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("iteration", m.iteration)?;
    d.set_item("env_steps", m.env_steps)?;
    d.set_item("satisfaction", m.satisfaction)?;
    d.set_item("plan_satisfaction", m.plan_satisfaction)?;
    d.set_item("plan_rho", m.plan_rho)?;
    d.set_item("steps_to_reach", m.steps_to_reach)?;
    d.set_item("lambda", m.lambda)?;
    d.set_item("low_level_reward", m.low_level_reward)?;
    Ok(d)
}

/// Trains `task` for `robot` into the run directory `out`, as `schrl train` does:
/// a general controller (or `controller`, a `schrl control train` run), planner
/// pre-training on the spec, joint training (Algorithm 1) with checkpoints, then the
/// evaluation (`eval_groups` × 100 runs). The other keywords (`settings`) are
/// `schrl train`'s flags with `_` for `-` (`plan_batch` for `--plan-batch`;
/// `semantics`, `planner` and `method` as their text), with the same defaults; None
/// means the default; an unknown one is a TypeError that lists them. An existing run in `out` is refused unless `force=True` (replace) or
/// `resume=True` (continue from its last checkpoint with its saved settings; only
/// `steps`, `target`, `eval_groups` and `save_every` may change).
///
/// `progress`, if given, is called with a dict per step of each stage: `stage`
/// ("controller", "pretrain", "joint", or "note" with a `message`), `done` and `total`
/// (updates, or environment steps in the joint stage), and the stage's figures.
/// Ctrl-C or an exception from `progress` stops training after saving a checkpoint,
/// then is raised.
///
/// Returns a dict: `out`, `iterations`, `env_steps`, `seconds`, `stop` ("steps" or
/// "target"), `history` (one dict per joint iteration), `evaluation` (as
/// `schrl.evaluate` returns, or None), `pictures` (paths) and `selected` (with
/// `select_every`: the deployed checkpoint's `iteration`, `env_steps`,
/// `satisfaction` and `steps_to_reach` as validated; else None).
#[pyfunction]
#[pyo3(signature = (task = None, *, out, robot = None, seed = None, force = false, resume = false, progress = None, **settings))]
#[allow(clippy::too_many_arguments)]
fn train<'py>(
    py: Python<'py>,
    task: Option<&str>,
    out: PathBuf,
    robot: Option<&str>,
    seed: Option<u64>,
    force: bool,
    resume: bool,
    progress: Option<Py<PyAny>>,
    settings: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyDict>> {
    if force && resume {
        return Err(PyValueError::new_err(
            "force=True replaces the run that resume=True continues; pass one",
        ));
    }
    let robot: Option<Robot> = robot.map(|r| parsed("robot", r)).transpose()?;
    let resolve = |robot, task: &str| {
        Task::resolve(robot, task).map_err(|e| PyValueError::new_err(format!("task: {e}")))
    };
    let session = if resume {
        let mut session = RunSession::resume(&out).map_err(train_error)?;
        let saved = session.settings().clone();
        let mut wanted = saved.clone();
        let mut changed = apply_all(&mut wanted, settings)?;
        changed.retain(|name| !["steps", "target", "eval_groups", "save_every"].contains(&name.as_str()));
        if seed.is_some_and(|s| s != saved.seed) {
            changed.push("seed".into());
        }
        if let Some(t) = task
            && Task::differs_from_saved(robot, t, saved.robot, (&saved.task_toml, &saved.task_spec))
                .map_err(|e| PyValueError::new_err(format!("task: {e}")))?
        {
            changed.push("task".into());
        }
        if robot.is_some_and(|r| r != saved.robot) {
            changed.push("robot".into());
        }
        if !changed.is_empty() {
            changed.sort();
            return Err(PyValueError::new_err(format!(
                "resume=True: {} differ from the saved run's settings; a resumed run keeps its settings \
                 (leave them out, or start a new run)",
                changed.join(", ")
            )));
        }
        let change = ResumeChanges {
            steps: Some(wanted.steps),
            target: wanted.target,
            eval_groups: Some(wanted.eval_groups),
            save_every: Some(wanted.save_every),
        };
        session.change(change).map_err(train_error)?;
        session
    } else {
        let Some(task) = task else {
            return Err(PyValueError::new_err("task is required for a new run"));
        };
        let task = resolve(robot, task)?;
        let mut s =
            JointRunSettings::for_task(&task, seed.unwrap_or(0)).map_err(|e| train_error(e.into()))?;
        apply_all(&mut s, settings)?;
        let existing = if force { Existing::Replace } else { Existing::Refuse };
        RunSession::create(&out, s, existing).map_err(train_error)?
    };
    let mut watcher = PyWatcher { callback: progress, raised: None };
    let trained = py.allow_threads(|| session.train(&mut watcher));
    if let Some(e) = watcher.raised {
        if e.is_instance_of::<PyKeyboardInterrupt>(py) {
            let saved = match &trained {
                Ok(t) => format!("iteration {}", t.trainer.iterations),
                Err(TrainError::StoppedInController { update, .. }) => {
                    format!("the general controller at update {update}")
                }
                Err(TrainError::StoppedInPretraining { candidates, .. }) => {
                    format!("planner pre-training after candidate {candidates}")
                }
                Err(e) => return Err(PyRuntimeError::new_err(e.to_string())),
            };
            return Err(PyKeyboardInterrupt::new_err(format!(
                "interrupted: saved {saved} in {}; continue with resume=True",
                out.display()
            )));
        }
        return Err(e);
    }
    let trained = trained.map_err(train_error)?;
    let t = &trained.trainer;
    let d = PyDict::new(py);
    d.set_item("out", out)?;
    d.set_item("iterations", t.iterations)?;
    d.set_item("env_steps", t.env_steps)?;
    d.set_item("seconds", trained.seconds)?;
    d.set_item("stop", if trained.stop == Stop::Target { "target" } else { "steps" })?;
    let history: PyResult<Vec<_>> = trained.history.iter().map(|m| metrics_dict(py, m)).collect();
    d.set_item("history", history?)?;
    let evaluation = trained.evaluation.as_ref().map(|e| crate::run::evaluation_dict(py, e)).transpose()?;
    d.set_item("evaluation", evaluation)?;
    d.set_item("pictures", trained.pictures)?;
    let selected = match &trained.selected {
        Some(v) => {
            let s = PyDict::new(py);
            s.set_item("iteration", v.iteration)?;
            s.set_item("env_steps", v.env_steps)?;
            s.set_item("satisfaction", v.satisfaction)?;
            s.set_item("steps_to_reach", v.steps_to_reach)?;
            Some(s)
        }
        None => None,
    };
    d.set_item("selected", selected)?;
    Ok(d)
}

/// Adds `train` to `m`.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(train, m)?)
}
