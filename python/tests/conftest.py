"""Runs trained by the `schrl` command line on a tiny budget, shared by the tests that
compare the Python calls with it."""

import subprocess

import pytest

from cli import schrl_cli

# `schrl train` settings small enough for a test: a few joint iterations after a short
# pre-training of one planner candidate.
TINY = {"steps": 20000, "pretrain_updates": 20, "pretrain_candidates": 1}


def flags(settings):
    """`schrl train` flags for Python keywords."""
    return [x for k, v in settings.items() for x in (f"--{k.replace('_', '-')}", str(v))]


@pytest.fixture(scope="session")
def general(tmp_path_factory):
    """A Point controller trained briefly on random goals (`schrl control train`)."""
    out = tmp_path_factory.mktemp("general") / "run"
    subprocess.run([schrl_cli(), "control", "train", "--robot", "point", "--steps", "20000",
                    "--eval-episodes", "0", "--out", str(out)], check=True, capture_output=True)
    return out


@pytest.fixture(scope="session")
def cli_run(general, tmp_path_factory):
    """Point Seq trained by `schrl train` with TINY, warm-started from `general`."""
    out = tmp_path_factory.mktemp("cli") / "run"
    subprocess.run([schrl_cli(), "train", "--task", "seq", *flags(TINY), "--eval-groups", "0",
                    "--controller", str(general), "--out", str(out)], check=True, capture_output=True)
    return out
