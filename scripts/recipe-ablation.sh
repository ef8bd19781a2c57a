#!/usr/bin/env bash
# What each choice of configs/train.toml's recipe is worth: the recipe and one change at a time
# (the decoder reading half resolution as the paper's does, per-frame Dice instead of batch
# Dice, both Dice terms, no class weights, no random crops), each trained for the same STEPS
# steps (default 1500) with the same seed, then scored on the validation split (the test split
# stays for the final figures). Writes out/ablation/<variant>/ (resumable run folders: stop any
# time, the same command goes on) and out/ablation/ablation.md.
#   scripts/recipe-ablation.sh [STEPS] [SEED]   (needs out/dataset and a release build; tch recipe)
set -euo pipefail
cd "$(dirname "$0")/.."
STEPS="${1:-1500}"
SEED="${2:-1}"
BIN="${WORKCELL_BIN:-target/release/workcell}"
DATASET="${WORKCELL_DATASET:-out/dataset}"
OUT=out/ablation
mkdir -p "$OUT"
# name|sed expressions applied to configs/train.toml
VARIANTS=(
    "recipe|"
    "decoder-half-resolution|s/^decoder_full_resolution = .*/decoder_full_resolution = false/"
    "frame-dice|s/^dice = .*/dice = 1.0/;s/^batch_dice = .*/batch_dice = 0.0/"
    "both-dice|s/^dice = .*/dice = 1.0/"
    "no-class-weights|s/^class_weights = .*/class_weights = {}/"
    "no-crop|s/^min_crop = .*/min_crop = 1.0/"
)
for v in "${VARIANTS[@]}"; do
    name="${v%%|*}-seed-$SEED"
    expr="${v#*|}"
    cfg="$OUT/$name.toml"
    sed -e "s|^dataset = .*|dataset = \"../../$DATASET\"|" -e "s/^steps = .*/steps = $STEPS/" \
        -e "s/^seed = .*/seed = $SEED/" ${expr:+-e "$expr"} configs/train.toml > "$cfg"
    if [ ! -f "$OUT/$name/validation.md" ]; then
        "$BIN" train --config "$cfg" --out "$OUT/$name" | tail -3
        "$BIN" eval segmentation --weights "$OUT/$name/procnet.safetensors" --dataset "$DATASET" \
            --split validation --backend "${WORKCELL_EVAL_BACKEND:-flex}" \
            --out "$OUT/$name/validation.md" > /dev/null
    fi
done
# | group | sequences | frames | Dice loss | batch Dice loss | IoU | focal loss | ceiling | class mean Dice |
# The first row of a group is the forearm table's (the loss breakdown below it repeats the names).
col() { grep -m1 -E "^\| $2 \|" "$1" | cut -d'|' -f"$3" | tr -d ' '; }
{
    echo "| variant (seed $SEED, $STEPS steps) | forearm Dice loss | batch Dice loss | IoU | heavy occlusion | distance large | five-class mean |"
    echo "|---|---|---|---|---|---|---|"
    for v in "${VARIANTS[@]}"; do
        name="${v%%|*}-seed-$SEED"
        f="$OUT/$name/validation.md"
        echo "| ${v%%|*} | $(col "$f" all 5) | $(col "$f" all 6) | $(col "$f" all 7) |" \
             "$(col "$f" 'occlusion heavy' 5) | $(col "$f" 'distance large' 5) | $(col "$f" all 10) |"
    done
} | tee "$OUT/ablation-seed-$SEED.md"
