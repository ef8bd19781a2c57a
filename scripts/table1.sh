#!/usr/bin/env bash
# The paper's Table 1 at CPU scale: hGRU, ConvLSTM and conv cells, with and without the
# prediction loss, each trained by configs/train.toml's recipe (seed, losses, schedule) for
# STEPS steps (default 1000) at half the cpu preset's channels (8, 16, 32), and evaluated on
# the test split. Writes out/table1/<variant>/ and out/table1/table1.md.
#   scripts/table1.sh [STEPS]        (needs out/dataset-paper and a release build)
set -euo pipefail
cd "$(dirname "$0")/.."
STEPS="${1:-1000}"
BIN="${WORKCELL_BIN:-target/release/workcell}"
OUT=out/table1
mkdir -p "$OUT"
ROWS=()
for cell in hgru convlstm conv; do
    for pred in true false; do
        name="${cell}-pred-${pred}"
        cfg="$OUT/$name.toml"
        sed -e "s/^cell = .*/cell = \"$cell\"/" \
            -e "s/^prediction_loss = .*/prediction_loss = $pred/" \
            -e "s|^dataset = .*|dataset = \"../dataset-paper\"|" \
            -e "s/^steps = .*/steps = $STEPS/" \
            -e "s/^repr_channels = .*/repr_channels = [8, 16, 32]/" \
            -e "s/^input_channels = .*/input_channels = [3, 8, 16]/" configs/train.toml > "$cfg"
        "$BIN" train --config "$cfg" --out "$OUT/$name" | tail -3
        "$BIN" eval segmentation --weights "$OUT/$name/procnet.safetensors" --dataset out/dataset-paper \
            --split test --out "$OUT/$name/test.md" > /dev/null
        ROWS+=("$name")
    done
done
{
    echo "| cell | prediction loss | forearm Dice loss, all | heavy occlusion | medium | light |"
    echo "|---|---|---|---|---|---|"
    for name in "${ROWS[@]}"; do
        f="$OUT/$name/test.md"
        all=$(grep -E '^\| [0-9]+ \| all \|' "$f" | cut -d'|' -f4 | tr -d ' ')
        heavy=$(grep -E '\| occlusion heavy \|' "$f" | cut -d'|' -f4 | tr -d ' ')
        medium=$(grep -E '\| occlusion medium \|' "$f" | cut -d'|' -f4 | tr -d ' ')
        light=$(grep -E '\| occlusion light \|' "$f" | cut -d'|' -f4 | tr -d ' ')
        cell="${name%%-pred-*}"; pred="${name##*-pred-}"
        echo "| $cell | $pred | $all | $heavy | $medium | $light |"
    done
} | tee "$OUT/table1.md"
