#!/usr/bin/env bash
# Set up (if needed) and run the demo, offline, on the shipped model.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export MUJOCO_GL="${MUJOCO_GL:-egl}"
exec .venv/bin/pushtoknow demo "$@"
