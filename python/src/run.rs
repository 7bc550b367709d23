//! `schrl.load_planner` and `schrl.evaluate`: a trained run (`schrl train --out DIR`)
//! from Python, through the same library calls as `schrl eval`.

use std::path::{Path, PathBuf};

use candle_core::{Device, Tensor};
use numpy::{IntoPyArray, PyArray2, PyArrayMethods};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use schrl::plan::gradient_planner::GradientPlannerConfig;
use schrl::run::evaluate::{
    EVAL_GROUPS, EVAL_PER_GROUP, EVAL_SEED, Plans, TaskEval, evaluate_task, mean_std,
};
use schrl::run::joint::{JointTrainer, paths_of};

/// The run's deployed checkpoint (the best validated one of a run that selects).
fn load(ckpt: &Path) -> PyResult<JointTrainer> {
    schrl::store::joint::load_deployed(ckpt)
        .map(|(t, _)| t)
        .map_err(|e| PyValueError::new_err(format!("{}: {e}", ckpt.display())))
}

fn runtime(e: impl std::fmt::Display) -> PyErr {
    PyRuntimeError::new_err(e.to_string())
}

/// A trained run's planner: `plan(start)` gives the waypoints `schrl eval` executes.
#[pyclass(name = "Planner", module = "schrl", unsendable)]
pub struct PyPlanner {
    run: JointTrainer,
}

#[pymethods]
impl PyPlanner {
    /// The plan from `start` (the robot's position): its mean path, the start first,
    /// as an array `[steps + 1, dim]`.
    fn plan<'py>(&self, py: Python<'py>, start: Vec<f64>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let task = &self.run.task;
        let dim = task.start.0.len();
        if start.len() != dim || start.iter().any(|x| !x.is_finite()) {
            return Err(PyValueError::new_err(format!(
                "start: expected {dim} finite numbers for the {} task, got {start:?}",
                task.name
            )));
        }
        let g0: Vec<f32> = start.iter().map(|&x| x as f32).collect();
        let g0 = Tensor::from_vec(g0, (1, dim), &Device::Cpu).map_err(runtime)?;
        let paths = paths_of(&self.run.plan.planner().mean_path(&g0, task.steps).map_err(runtime)?)
            .map_err(runtime)?;
        let path = &paths[0];
        let rows = path.len();
        let flat: Vec<f64> = path.iter().flatten().copied().collect();
        flat.into_pyarray(py).reshape([rows, dim])
    }

    /// The task's name.
    #[getter]
    fn task(&self) -> &str {
        &self.run.task.name
    }

    /// The task's robot.
    #[getter]
    fn robot(&self) -> String {
        self.run.task.robot.to_string()
    }
}

/// Loads the planner of a trained run.
#[pyfunction]
fn load_planner(ckpt: PathBuf) -> PyResult<PyPlanner> {
    Ok(PyPlanner { run: load(&ckpt)? })
}

/// Evaluates a trained run as `schrl eval` does: `groups × per_group` runs from random
/// starts, plans from `planner` ("network": mean paths, "sampled", or "gradient"),
/// executed by the run's controller. Returns a dict: `satisfaction` and
/// `steps_to_reach` per group, their `*_mean` and `*_std`, and the failure counts.
#[pyfunction]
#[pyo3(signature = (ckpt, groups = EVAL_GROUPS, per_group = EVAL_PER_GROUP, seed = EVAL_SEED, planner = "network"))]
fn evaluate<'py>(
    py: Python<'py>,
    ckpt: PathBuf,
    groups: usize,
    per_group: usize,
    seed: u64,
    planner: &str,
) -> PyResult<Bound<'py, PyDict>> {
    if groups == 0 || per_group == 0 {
        return Err(PyValueError::new_err("groups and per_group must be at least 1"));
    }
    let t = load(&ckpt)?;
    let plans = match planner {
        "network" => Plans::Mean(t.plan.planner()),
        "sampled" => Plans::Sampled(t.plan.planner()),
        "gradient" => Plans::Gradient { task: t.plan.task(), config: GradientPlannerConfig::default() },
        other => {
            return Err(PyValueError::new_err(format!(
                "planner: '{other}' is not one of network, sampled, gradient"
            )));
        }
    };
    let e =
        evaluate_task(&t.task, plans, &t.control.controller(), (groups, per_group), seed).map_err(runtime)?;
    evaluation_dict(py, &e)
}

/// An evaluation as `schrl.evaluate` returns it: `satisfaction` and `steps_to_reach`
/// per group, their `*_mean` and `*_std`, and the failure counts.
pub fn evaluation_dict<'py>(py: Python<'py>, e: &TaskEval) -> PyResult<Bound<'py, PyDict>> {
    let out = PyDict::new(py);
    let (sm, ss) = mean_std(&e.satisfaction);
    out.set_item("satisfaction", e.satisfaction.clone())?;
    out.set_item("satisfaction_mean", sm)?;
    out.set_item("satisfaction_std", ss)?;
    out.set_item("steps_to_reach", e.steps_to_reach.clone())?;
    if !e.steps_to_reach.is_empty() {
        let (tm, ts) = mean_std(&e.steps_to_reach);
        out.set_item("steps_to_reach_mean", tm)?;
        out.set_item("steps_to_reach_std", ts)?;
    }
    out.set_item("collisions", e.collisions)?;
    out.set_item("falls", e.falls)?;
    out.set_item("timeouts", e.timeouts)?;
    out.set_item("entered", e.entered)?;
    Ok(out)
}

/// Adds the run functions to `m`.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyPlanner>()?;
    m.add_function(wrap_pyfunction!(load_planner, m)?)?;
    m.add_function(wrap_pyfunction!(evaluate, m)?)?;
    Ok(())
}
