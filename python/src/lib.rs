//! `schrl._schrl`: the native module under the `schrl` Python package.
//!
//! `spec` backs `schrl.stl` (robustness on NumPy arrays); `envs` backs
//! `schrl.envs` (the robots as Gymnasium environments, single and vectorised); `run`
//! backs `schrl.load_planner` and `schrl.evaluate` (trained runs); `train` backs
//! `schrl.train`.

use pyo3::prelude::*;

mod envs;
mod run;
mod spec;
mod train;

/// The native module.
#[pymodule]
fn _schrl(m: &Bound<'_, PyModule>) -> PyResult<()> {
    // Whether this build simulates the Doggo (the `mujoco` feature).
    m.add("MUJOCO", cfg!(feature = "mujoco"))?;
    spec::register(m)?;
    envs::register(m)?;
    run::register(m)?;
    train::register(m)
}
