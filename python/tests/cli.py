"""The `schrl` command line the Python tests compare with."""

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


def schrl_cli():
    """The `schrl` binary: $SCHRL_BIN, else a build in target/ (CI has one)."""
    for candidate in [os.environ.get("SCHRL_BIN"), REPO / "target/debug/schrl", REPO / "target/release/schrl"]:
        if candidate and Path(candidate).is_file():
            return str(candidate)
    if os.environ.get("CI") == "true":
        pytest.fail("CI needs the schrl binary: build it (cargo build -p schrl-cli) or set SCHRL_BIN")
    pytest.skip("no schrl binary to compare with (cargo build -p schrl-cli)")
