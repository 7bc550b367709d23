"""schrl.train: the same run as `schrl train` from the same settings, progress through
the callback, runs refused, resumed or replaced as on the command line, settings
checked by name, and a stopped run saved and resumable."""

import json
import os
import signal

import pytest

import schrl
from conftest import TINY

# What an iteration measured that does not depend on the clock.
MEASURED = ["iteration", "env_steps", "satisfaction", "plan_satisfaction", "plan_rho", "lambda",
            "low_level_reward", "steps_to_reach"]


def train(out, general, **kw):
    return schrl.train(task="seq", out=str(out), controller=str(general), **{**TINY, "eval_groups": 0, **kw})


def test_train_makes_the_clis_run(general, cli_run, tmp_path):
    events = []
    result = train(tmp_path / "run", general, progress=events.append)
    cli = [json.loads(line) for line in (cli_run / "metrics.jsonl").read_text().splitlines()]
    assert len(result["history"]) == len(cli) == result["iterations"] > 0
    for ours, theirs in zip(result["history"], cli):
        assert {k: ours[k] for k in MEASURED} == {k: theirs[k] for k in MEASURED}
    assert result["env_steps"] >= TINY["steps"] and result["stop"] == "steps"
    assert result["evaluation"] is None
    assert [os.path.basename(p) for p in result["pictures"]] == ["training_curve.png"]
    assert all(os.path.getsize(p) > 0 for p in result["pictures"])
    stages = [e["stage"] for e in events]
    assert "pretrain" in stages and "joint" in stages and "controller" not in stages  # warm-started
    joint = [e for e in events if e["stage"] == "joint"]
    assert [e["done"] for e in joint] == [m["env_steps"] for m in result["history"]]
    assert all(e["total"] == TINY["steps"] and 0 <= e["satisfaction"] <= 1 for e in joint)


def test_evaluation_after_training_is_schrl_evaluate(general, tmp_path):
    result = train(tmp_path / "run", general, eval_groups=1)
    evaluation = result["evaluation"]
    assert len(evaluation["satisfaction"]) == 1
    assert evaluation == schrl.evaluate(str(tmp_path / "run"), groups=1)
    assert [os.path.basename(p) for p in result["pictures"]] == ["training_curve.png", "episodes.png"]


def test_a_selecting_run_deploys_its_best_validated_checkpoint(general, tmp_path):
    result = train(
        tmp_path / "run", general, eval_groups=1, select_every=max(1, TINY["steps"] // 2), select_rule="one-se"
    )
    chosen = result["selected"]
    assert chosen is not None and 0 <= chosen["iteration"] <= result["iterations"]
    assert 0 <= chosen["satisfaction"] <= 1
    assert (tmp_path / "run" / "best" / "manifest.json").exists()
    assert json.loads((tmp_path / "run" / "manifest.json").read_text())["settings"]["select_rule"] == "one-se"
    # What the run evaluated is what schrl.evaluate loads: the deployed checkpoint.
    assert result["evaluation"] == schrl.evaluate(str(tmp_path / "run"), groups=1)
    assert train(tmp_path / "plain", general)["selected"] is None


def test_existing_runs_are_refused_resumed_or_replaced(general, tmp_path):
    out = tmp_path / "run"
    first = train(out, general)
    with pytest.raises(FileExistsError, match="force=True"):
        train(out, general)
    with pytest.raises(ValueError, match="plan_batch, seed differ from the saved run"):
        schrl.train(out=str(out), resume=True, seed=1, plan_batch=16)
    longer = schrl.train(out=str(out), resume=True, steps=2 * TINY["steps"], eval_groups=0)
    assert longer["env_steps"] >= 2 * TINY["steps"] > first["env_steps"]
    assert longer["history"][: first["iterations"]] == first["history"]
    again = train(out, general, force=True)
    assert again["history"] == first["history"]
    with pytest.raises(ValueError, match="pass one"):
        schrl.train(task="seq", out=str(out), force=True, resume=True)


@pytest.mark.parametrize("kw, message", [
    ({"plan_batch": 0}, "plan_batch must be at least 1"),
    ({"runs_per_start": 3}, "runs_per_start must divide the plan batch"),
    ({"target": 2.0}, r"target must be a fraction in \[0, 1\]"),
    ({"semantics": "bogus"}, "semantics: "),
    ({"method": "sgd"}, "method: unknown method 'sgd'"),
    ({"task": "nope"}, "task: nope: .*or a task file ending in .toml"),
    ({"task": None}, "task is required for a new run"),
    ({"robot": "boat"}, "robot: "),
    ({"anchor_weight": -1.0}, "anchor_weight must be a non-negative number"),
    ({"anchor_on": "knees"}, "anchor_on: unknown anchor 'knees'"),
    ({"anchor_weight": 1.0, "planner": "mlp"}, "anchor_weight must be 0 with the mlp planner"),
    ({"plan_step_limit": -0.1}, "plan_step_limit must be a non-negative number of metres"),
    ({"plan_step_limit": 0.05, "planner": "mlp"}, "plan_step_limit must be 0 with the mlp planner"),
    ({"select_rule": "fastest"}, "select_rule: 'fastest' is not most-satisfying or one-se"),
])
def test_bad_settings_are_named(tmp_path, kw, message):
    with pytest.raises(ValueError, match=message):
        schrl.train(**{"task": "seq", "out": str(tmp_path / "run"), **kw})
    assert not (tmp_path / "run").exists()


def test_unknown_and_mistyped_keywords_are_type_errors(tmp_path):
    with pytest.raises(TypeError, match="unexpected keyword argument 'plan_bach'; the settings are steps, target"):
        schrl.train(task="seq", out=str(tmp_path / "run"), plan_bach=16)
    with pytest.raises(TypeError, match="plan_batch: expected a whole number, got 8.5"):
        schrl.train(task="seq", out=str(tmp_path / "run"), plan_batch=8.5)
    assert not (tmp_path / "run").exists()


def test_a_raising_callback_stops_after_saving_and_the_run_resumes(general, tmp_path):
    out = tmp_path / "run"

    def stop_at_the_second_iteration(event):
        if event["stage"] == "joint" and event["iteration"] == 2:
            raise RuntimeError("enough")

    with pytest.raises(RuntimeError, match="enough"):
        train(out, general, progress=stop_at_the_second_iteration)
    resumed = schrl.train(out=str(out), resume=True)
    whole = train(tmp_path / "whole", general)
    assert resumed["history"] == whole["history"]


def test_ctrl_c_saves_and_says_how_to_continue(general, tmp_path):
    def interrupt(event):
        if event["stage"] == "joint":
            os.kill(os.getpid(), signal.SIGINT)

    with pytest.raises(KeyboardInterrupt, match="continue with resume=True"):
        train(tmp_path / "run", general, progress=interrupt)
    assert schrl.train(out=str(tmp_path / "run"), resume=True)["stop"] == "steps"


def test_a_run_stopped_while_pretraining_goes_on_from_its_last_candidate(general, tmp_path):
    out = tmp_path / "run"

    def stop_in_pretraining(event):
        if event["stage"] == "pretrain":
            raise RuntimeError("enough")

    with pytest.raises(RuntimeError, match="enough"):
        train(out, general, progress=stop_in_pretraining)
    # Saved after the candidate in training, before any joint checkpoint.
    assert (out / "pretrain" / "manifest.json").exists()
    assert json.loads((out / "manifest.json").read_text())["generation"] is None
    resumed = schrl.train(out=str(out), resume=True)
    whole = train(tmp_path / "whole", general)
    assert resumed["history"] == whole["history"]
