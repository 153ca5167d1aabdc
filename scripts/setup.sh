#!/usr/bin/env bash
# Installs everything pushtoknow needs on a fresh Debian/Ubuntu machine (idempotent):
#   - Debian's headless OpenGL libraries for MuJoCo's EGL renderer (needs root or sudo)
#   - a virtual environment in .venv with the pinned CPU build of PyTorch installed FIRST
#     (so pip never resolves a bare `torch` to the multi-GB CUDA build), then the package with
#     its numerical libraries at the versions in scripts/constraints.txt.
# Usage: scripts/setup.sh [--dev]      (--dev adds the test and lint tools)
set -euo pipefail
cd "$(dirname "$0")/.."

GL_PACKAGES="libegl1 libegl-mesa0 libgl1-mesa-dri libopengl0"
TORCH_SPEC="${PUSHTOKNOW_TORCH_SPEC:-torch==2.13.0}"
PYTHON="${PYTHON:-python3}"

missing=""
for p in $GL_PACKAGES; do
  dpkg -s "$p" >/dev/null 2>&1 || missing="$missing $p"
done
if [ -n "$missing" ]; then
  echo "[setup] installing GL libraries:$missing"
  if [ "$(id -u)" = 0 ]; then SUDO=""; elif command -v sudo >/dev/null; then SUDO="sudo"; else
    echo "[setup] need root to install:$missing (apt-get install -y$missing)" >&2; exit 1; fi
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq $missing >/dev/null
fi

if [ ! -x .venv/bin/python ]; then
  echo "[setup] creating .venv"
  "$PYTHON" -m venv .venv
fi
PIP=".venv/bin/python -m pip"
$PIP install -q --disable-pip-version-check --upgrade pip
if ! .venv/bin/python -c "import torch" >/dev/null 2>&1; then
  echo "[setup] installing $TORCH_SPEC (CPU build)"
  $PIP install -q --disable-pip-version-check "$TORCH_SPEC"
fi
extra=""
[ "${1:-}" = "--dev" ] && extra="[dev]"
echo "[setup] installing pushtoknow$extra"
$PIP install -q --disable-pip-version-check -c scripts/constraints.txt -e ".$extra"
echo "[setup] done"
