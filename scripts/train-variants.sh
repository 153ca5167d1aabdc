#!/usr/bin/env bash
# Train the comparison models on the shipped model's data (recipe of scripts/train-pretrained.sh:
# 1000 catalogue-train + continuous objects × 4 constant or release pushes, data seed 3): the
# paper's black-box VT-ADDF, VT-JDF and V-DDF (configs/variants.yaml: black-box models, the
# shipped recipe without its ineffective end-to-end stage) with the shipped model's VisNet, so
# they differ from it only in the model structure and the filter.
# ~8 min each on 2 cores. Usage: bash scripts/train-variants.sh [WORKDIR] (default runs/pretrained)
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export MUJOCO_GL="${MUJOCO_GL:-egl}"
WORK="${1:-runs/pretrained}"
# simulate skips the shards already written (same settings), so this is cheap when done
.venv/bin/pushtoknow simulate --out "$WORK/data" --objects 1000 --pushes 4 --seed 3 \
    --workers 2 --objects-from catalogue-train+continuous --profiles constant,release
for v in vt-addf vt-jdf v-ddf; do
    if [ ! -f "$WORK/$v-black-box/model.pt" ]; then
        .venv/bin/pushtoknow train --data "$WORK/data" --out "$WORK/$v-black-box" --variant "$v" \
            --config configs/variants.yaml --seed 0 \
            --visnet-from src/pushtoknow/pretrained/vt-addf
    fi
done
# the previous shipped model's recipe: quasi-static motion learned by a network
if [ ! -f "$WORK/vt-addf-physics-network/model.pt" ]; then
    .venv/bin/pushtoknow train --data "$WORK/data" --out "$WORK/vt-addf-physics-network" \
        --variant vt-addf --config configs/vt-addf-physics-network.yaml --seed 0 \
        --visnet-from src/pushtoknow/pretrained/vt-addf
fi
