#!/usr/bin/env bash
# Speed-profile ablation from scratch, on the CPU: data with a speed profile drawn
# per push from {constant, release} (400 catalogue-train objects × 4 pushes, seed 1), a VT-ADDF
# trained on it (configs/profiles-vt-addf.yaml, VisNet reused from the shipped model), then
# `pushtoknow ablate-profiles` on 44 held-out objects: uniform and active-entropy, each with and
# without release pushes, and the shipped model as reference. ~5 + 8 + 25 min on 2 cores.
# Usage: bash scripts/ablate-profiles.sh [WORKDIR]   (default: runs/profiles)
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export MUJOCO_GL="${MUJOCO_GL:-egl}"
WORK="${1:-runs/profiles}"
PTK=.venv/bin/pushtoknow
$PTK simulate --out "$WORK/data" --objects 400 --pushes 4 --seed 1 --workers 2 \
    --objects-from catalogue-train --profiles constant,release
if [ ! -f "$WORK/vt-addf/model.pt" ]; then
    $PTK train --data "$WORK/data" --out "$WORK/vt-addf" --variant vt-addf \
        --config configs/profiles-vt-addf.yaml --seed 0 --visnet-from src/pushtoknow/pretrained/vt-addf
fi
$PTK ablate-profiles --model "$WORK/vt-addf" --out "$WORK/ablation" --objects 44 --seed 0 \
    --reference pretrained --workers 2 --markdown "$WORK/ablation/section.md"
