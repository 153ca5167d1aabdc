#!/usr/bin/env bash
# Train the ablation variants VT-JDF and V-DDF on the shipped model's data (recipe of
# scripts/train-pretrained.sh: 400 catalogue-train objects × 4 pushes, data seed 1), with the
# shipped model's recipe without its (ineffective) end-to-end stage, configs/variants.yaml, and
# its VisNet, so the three variants differ only in the filter.
# ~8 min each on 2 cores. Usage: bash scripts/train-variants.sh [WORKDIR] (default runs/pretrained)
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export MUJOCO_GL="${MUJOCO_GL:-egl}"
WORK="${1:-runs/pretrained}"
# simulate skips the shards already written (same settings), so this is cheap when done
.venv/bin/pushtoknow simulate --out "$WORK/data" --objects 400 --pushes 4 --seed 1 \
    --workers 2 --objects-from catalogue-train
for v in vt-jdf v-ddf; do
    if [ ! -f "$WORK/$v/model.pt" ]; then
        .venv/bin/pushtoknow train --data "$WORK/data" --out "$WORK/$v" --variant "$v" \
            --config configs/variants.yaml --seed 0 \
            --visnet-from src/pushtoknow/pretrained/vt-addf
    fi
done
