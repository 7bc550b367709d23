#!/usr/bin/env bash
# Installs what the `highs` cargo feature (HiGHS as the MIP planner's solver) needs to
# build: cmake and a C++ compiler for HiGHS itself, libclang for its bindings. Debian
# or Ubuntu, as root or with sudo. Idempotent: installs nothing already there.
#
# Then: cargo build --release -p schrl-cli --features highs
set -euo pipefail

missing=()
command -v cmake > /dev/null || missing+=(cmake)
command -v c++ > /dev/null || missing+=(g++)
ldconfig -p 2> /dev/null | grep -qE 'libclang(-[0-9.]+)?\.so' || missing+=(libclang-dev)
if [[ ${#missing[@]} -eq 0 ]]; then
    echo "setup-highs: cmake, a C++ compiler and libclang are already installed"
    exit 0
fi
if ! command -v apt-get > /dev/null; then
    echo "setup-highs: install ${missing[*]} with your package manager (no apt-get here)" >&2
    exit 1
fi
SUDO=""
if [[ $(id -u) -ne 0 ]]; then
    SUDO=sudo
fi
echo "setup-highs: installing ${missing[*]}"
$SUDO apt-get update -qq
DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${missing[@]}" > /dev/null
echo "setup-highs: done"
