#!/usr/bin/env bash
# Installs MuJoCo 3.17.0 for the `mujoco` cargo feature (the Doggo robot), inside the
# project: `.mujoco/lib/` (git-ignored) gets the `libmujoco.so.3.17.0` that ships in
# the PyPI wheel `mujoco==3.17.0`, plus the `libmujoco.so` link the linker looks for.
# `.cargo/config.toml` points MUJOCO_DYNAMIC_LINK_DIR there, and the crates that link
# MuJoCo record the folder as an rpath, so nothing needs exporting afterwards.
#
# Idempotent: does nothing when the library is already in place.
# Needs: python3 with pip (to fetch the wheel from PyPI) and unzip or python3's zipfile.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

# mujoco-rs 7.0.0 is built for exactly this version; others fail at start-up.
VERSION=3.17.0
LIB_DIR="$PWD/.mujoco/lib"
LIB="$LIB_DIR/libmujoco.so.$VERSION"

if [[ "$(uname -s)" != Linux || "$(uname -m)" != x86_64 ]]; then
    echo "setup-mujoco: only x86_64 Linux is scripted; for other platforms download MuJoCo $VERSION" >&2
    echo "and point MUJOCO_DYNAMIC_LINK_DIR at its lib/ folder" >&2
    exit 1
fi

if [[ -f "$LIB" && -L "$LIB_DIR/libmujoco.so" ]]; then
    echo "setup-mujoco: MuJoCo $VERSION already in $LIB_DIR"
    exit 0
fi

PYTHON=${PYTHON:-python3}
if ! "$PYTHON" -m pip --version > /dev/null 2>&1; then
    echo "setup-mujoco: '$PYTHON -m pip' is not available; install python3-pip (or set PYTHON)" >&2
    exit 1
fi

TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT

# Any CPython wheel carries the same C library; ask for the one matching the local
# interpreter so pip resolves it without further flags.
echo "setup-mujoco: downloading the mujoco==$VERSION wheel from PyPI"
"$PYTHON" -m pip download --quiet --no-deps --only-binary=:all: "mujoco==$VERSION" -d "$TMP"
WHEEL=$(ls "$TMP"/mujoco-"$VERSION"-*.whl)

mkdir -p "$LIB_DIR"
"$PYTHON" - "$WHEEL" "$TMP/libmujoco.so.$VERSION" "mujoco/libmujoco.so.$VERSION" << 'EOF'
import shutil, sys, zipfile
wheel, dest, member = sys.argv[1:]
with zipfile.ZipFile(wheel) as z, z.open(member) as src, open(dest, "wb") as out:
    shutil.copyfileobj(src, out)
EOF
# Move into place only once complete, so an interrupted run leaves no half library.
mv "$TMP/libmujoco.so.$VERSION" "$LIB"
ln -sfn "libmujoco.so.$VERSION" "$LIB_DIR/libmujoco.so"
echo "setup-mujoco: installed $LIB"
