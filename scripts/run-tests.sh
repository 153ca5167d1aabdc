#!/usr/bin/env bash
# Set up (if needed, with the test tools) and run the whole test suite, slow tests included.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh --dev
export MUJOCO_GL="${MUJOCO_GL:-egl}"
.venv/bin/ruff check src tests
.venv/bin/ruff format --check src tests
.venv/bin/mypy src/pushtoknow/filters src/pushtoknow/models  # the typed functional core
exec .venv/bin/python -m pytest -n 2 --dist loadfile --durations=15 "$@"
