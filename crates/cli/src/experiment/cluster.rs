//! Which cell a cluster array task runs.
//!
//! A Slurm job array (`sbatch --array=0-<N-1>`) gives each task `SLURM_ARRAY_TASK_ID`;
//! a Kubernetes Indexed Job gives each pod `JOB_COMPLETION_INDEX`. Either is a cell's
//! position in `schrl experiment <name> --list` (with the same selection flags).
//! The deploy files under `deploy/` start one task per cell this way.

use anyhow::{Result, bail};

/// The scheduler variables read, in order of precedence.
pub const INDEX_VARS: [&str; 2] = ["SLURM_ARRAY_TASK_ID", "JOB_COMPLETION_INDEX"];

/// The cell to run: `--cell` if given, else the scheduler's index, else `None` (run
/// every cell). `env` looks a variable up (`std::env::var` outside tests). A flag and
/// a variable that disagree, an index that is not a whole number, and one past the
/// last of `cells` cells are errors that say which.
pub fn cell_index(
    flag: Option<usize>,
    env: impl Fn(&str) -> Option<String>,
    cells: usize,
) -> Result<Option<usize>> {
    let from_env = INDEX_VARS.iter().find_map(|&var| env(var).map(|v| (var, v)));
    let index = match (flag, from_env) {
        (Some(i), Some((var, v))) if v.trim() != i.to_string() => {
            bail!("--cell {i} disagrees with {var}={v}; give one of them")
        }
        (Some(i), _) => Some(i),
        (None, Some((var, v))) => match v.trim().parse::<usize>() {
            Ok(i) => Some(i),
            Err(_) => bail!("{var}={v} is not a cell index (a whole number ≥ 0)"),
        },
        (None, None) => None,
    };
    if let Some(i) = index
        && i >= cells
    {
        bail!(
            "cell {i} does not exist: this selection has {cells} cells (0..={}); the array must match \
             `schrl experiment <name> --list` with the same flags",
            cells.saturating_sub(1)
        );
    }
    Ok(index)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env<'a>(vars: &'a [(&'a str, &'a str)]) -> impl Fn(&str) -> Option<String> + 'a {
        move |name| vars.iter().find(|(k, _)| *k == name).map(|(_, v)| v.to_string())
    }

    #[test]
    fn the_flag_the_slurm_index_or_the_kubernetes_index_names_the_cell() {
        assert_eq!(cell_index(Some(3), env(&[]), 10).unwrap(), Some(3));
        assert_eq!(cell_index(None, env(&[("SLURM_ARRAY_TASK_ID", "7")]), 10).unwrap(), Some(7));
        assert_eq!(cell_index(None, env(&[("JOB_COMPLETION_INDEX", "0")]), 10).unwrap(), Some(0));
        assert_eq!(cell_index(None, env(&[]), 10).unwrap(), None);
        // Slurm first when both are set (a Slurm job inside a pod keeps its own index).
        let both = [("SLURM_ARRAY_TASK_ID", "2"), ("JOB_COMPLETION_INDEX", "5")];
        assert_eq!(cell_index(None, env(&both), 10).unwrap(), Some(2));
        assert_eq!(cell_index(Some(2), env(&both), 10).unwrap(), Some(2));
    }

    #[test]
    fn indices_past_the_last_cell_or_in_conflict_are_refused() {
        let e = cell_index(None, env(&[("SLURM_ARRAY_TASK_ID", "10")]), 10).unwrap_err().to_string();
        assert!(e.contains("cell 10 does not exist") && e.contains("0..=9"), "{e}");
        let e = cell_index(Some(1), env(&[("JOB_COMPLETION_INDEX", "4")]), 10).unwrap_err().to_string();
        assert!(e.contains("--cell 1 disagrees with JOB_COMPLETION_INDEX=4"), "{e}");
        let e = cell_index(None, env(&[("SLURM_ARRAY_TASK_ID", "x")]), 10).unwrap_err().to_string();
        assert!(e.contains("SLURM_ARRAY_TASK_ID=x is not a cell index"), "{e}");
    }
}
