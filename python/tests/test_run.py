"""schrl.load_planner and schrl.evaluate on a run trained by the CLI (a tiny budget):
the evaluation equals `schrl eval`'s, plans start at the start and are deterministic."""

import subprocess

import numpy as np
import pytest

import schrl
from cli import schrl_cli


def test_evaluate_equals_the_cli(cli_run):
    ours = schrl.evaluate(str(cli_run), groups=2, per_group=20)
    out = subprocess.run([schrl_cli(), "eval", "--ckpt", str(cli_run), "--groups", "2", "--per-group", "20"],
                         check=True, capture_output=True, text=True).stdout
    line = next(l for l in out.splitlines() if l.startswith("satisfaction:"))
    mean, std = (float(x) for x in line.split(":")[1].split("±"))
    assert len(ours["satisfaction"]) == 2
    assert ours["satisfaction_mean"] == pytest.approx(mean, abs=5e-4)
    assert ours["satisfaction_std"] == pytest.approx(std, abs=5e-4)
    failures = next(l for l in out.splitlines() if l.startswith("failures:"))
    assert f"{ours['collisions']} collisions" in failures and f"{ours['timeouts']} time-outs" in failures


def test_plans_start_at_the_start_and_are_deterministic(cli_run):
    planner = schrl.load_planner(str(cli_run))
    assert planner.task == "seq" and planner.robot == "point"
    start = [1.5, -1.5]
    path = planner.plan(start)
    assert path.ndim == 2 and path.shape[1] == 2 and path.shape[0] >= 2
    np.testing.assert_allclose(path[0], start, atol=1e-6)
    np.testing.assert_array_equal(path, planner.plan(start))
    with pytest.raises(ValueError, match="expected 2 finite numbers"):
        planner.plan([0.0])
    with pytest.raises(ValueError, match="not one of network"):
        schrl.evaluate(str(cli_run), planner="mip")
    with pytest.raises(ValueError):
        schrl.load_planner(str(cli_run / "nowhere"))
