#!/usr/bin/env bash
# Reproduce the shipped model src/pushtoknow/pretrained/vt-addf from scratch, on the CPU:
# generate its training data (1000 objects, alternately from the catalogue's training split and
# continuous-parameter objects of the catalogue shapes, × 4 pushes of random constant or release
# profile, seed 3) and train the physics-structured VT-ADDF on it
# (configs/pretrained-vt-addf.yaml, seed 0). Measured times in docs/TRAINING.md.
# Usage: bash scripts/train-pretrained.sh [WORKDIR]   (default: runs/pretrained)
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export MUJOCO_GL="${MUJOCO_GL:-egl}"
WORK="${1:-runs/pretrained}"
mkdir -p "$WORK"
.venv/bin/pushtoknow simulate --out "$WORK/data" --objects 1000 --pushes 4 --seed 3 \
    --workers 2 --objects-from catalogue-train+continuous --profiles constant,release
.venv/bin/pushtoknow train --data "$WORK/data" --out "$WORK/vt-addf" --variant vt-addf \
    --config configs/pretrained-vt-addf.yaml --seed 0
DEST=src/pushtoknow/pretrained/vt-addf
mkdir -p "$DEST"
cp "$WORK"/vt-addf/{model.pt,config.yaml,training.json,*.csv} "$DEST"/
echo "shipped model updated in $DEST"
