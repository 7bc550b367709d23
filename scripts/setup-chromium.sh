#!/usr/bin/env bash
# Installs Debian's Chromium for the report page test (crates/cli/tests/report_cli.rs),
# which opens `schrl report`'s HTML page headless. Idempotent; needs apt-get and root
# (or sudo). The test finds the browser as $CHROMIUM, else `chromium` on PATH.
set -euo pipefail
if command -v "${CHROMIUM:-chromium}" > /dev/null 2>&1; then
    echo "setup-chromium: $(command -v "${CHROMIUM:-chromium}") already installed"
    exit 0
fi
sudo=()
if [[ $(id -u) != 0 ]]; then sudo=(sudo); fi
"${sudo[@]}" apt-get update -q
DEBIAN_FRONTEND=noninteractive "${sudo[@]}" apt-get install -y -q --no-install-recommends chromium
chromium --version
