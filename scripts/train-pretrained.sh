#!/usr/bin/env bash
# Reproduce the shipped model src/pushtoknow/pretrained/vt-addf from scratch, on the CPU:
# generate its training data (400 catalogue-train objects × 4 pushes, seed 1) and train it
# (configs/pretrained-vt-addf.yaml, seed 0). ~4 min of simulation + ~10 min of training on
# 2 cores. Usage: bash scripts/train-pretrained.sh [WORKDIR]   (default: runs/pretrained)
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export MUJOCO_GL="${MUJOCO_GL:-egl}"
WORK="${1:-runs/pretrained}"
mkdir -p "$WORK"
.venv/bin/pushtoknow simulate --out "$WORK/data" --objects 400 --pushes 4 --seed 1 \
    --workers 2 --objects-from catalogue-train
.venv/bin/pushtoknow train --data "$WORK/data" --out "$WORK/vt-addf" --variant vt-addf \
    --config configs/pretrained-vt-addf.yaml --seed 0
DEST=src/pushtoknow/pretrained/vt-addf
mkdir -p "$DEST"
cp "$WORK"/vt-addf/{model.pt,config.yaml,training.json,*.csv} "$DEST"/
echo "shipped model updated in $DEST"
