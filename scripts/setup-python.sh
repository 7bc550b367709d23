#!/usr/bin/env bash
# Builds and installs the `schrl` Python package (python/, a maturin project) with its
# test dependencies into a virtual environment, `.venv/` at the repository root
# (git-ignored): `pip install ./python[test]` fetches maturin from PyPI for the build
# and compiles the Rust extension (release profile) with cargo. Then
#   .venv/bin/python -m pytest python/tests
# Needs: python3 ≥ 3.9 with venv and pip, and cargo. PYTHON picks the interpreter.
# SCHRL_PYTHON_FEATURES=mujoco builds the Doggo in (run scripts/setup-mujoco.sh first).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
PYTHON=${PYTHON:-python3}
if [[ ! -x .venv/bin/python ]]; then
    "$PYTHON" -m venv .venv
fi
.venv/bin/python -m pip install -q --upgrade pip
if [[ -n "${SCHRL_PYTHON_FEATURES:-}" ]]; then
    export MATURIN_PEP517_ARGS="--features ${SCHRL_PYTHON_FEATURES}"
fi
.venv/bin/python -m pip install -q "./python[test]"
.venv/bin/python -c "import schrl.envs; print('setup-python: schrl installed in .venv; robots:', ', '.join(schrl.envs.ROBOTS))"
