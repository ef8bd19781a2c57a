#!/usr/bin/env bash
# The paper's Table 1 at CPU scale on the default dataset: hGRU, ConvLSTM and conv cells, with
# and without the prediction loss, and hGRU with the axonal delay; each trained by the base
# recipe (default configs/train-64.toml: seed, losses, schedule, channels, 64x64) for the same
# STEPS steps (default: the recipe's), then evaluated on the test split. Writes
# out/table1/<variant>/ (a resumable run folder each: stop any time, the same command goes
# on) and out/table1/table1.md.
#
#   experiments/scripts/table1.sh [STEPS]        (needs out/dataset and a release build; tch recipe)
#
# WORKCELL_TABLE1_JOBS (default 2) variants train side by side at one thread each: on two
# cores two one-thread runs of the 64x64 recipe make 1.14 times the steps of one two-thread
# run (0.62 and 0.75 s a step for ProcNet and the baseline side by side, against 0.36 and 0.42
# alone; experiments/perception.md). WORKCELL_TABLE1_BASE picks another base recipe and
# WORKCELL_TABLE1_OUT another folder (a run folder refuses a configuration other than its
# own, so a changed base needs one), e.g. the shipped recipe's peak learning rate:
#
#   sed 's/^lr = .*/lr = 4e-3/' configs/train-64.toml > out/train-64-lr4e-3.toml
#   WORKCELL_TABLE1_BASE=out/train-64-lr4e-3.toml WORKCELL_TABLE1_OUT=out/table1-lr4e-3 \
#       experiments/scripts/table1.sh 3000
#
# WORKCELL_TABLE1_VARIANTS (space-separated CELL:PREDICTION:DELAY, e.g. "conv:true:false
# convlstm:true:false") trains only those rows, in that order; the table then lists every row
# whose test-split score exists and names the rows still missing.
set -euo pipefail
cd "$(dirname "$0")/.."
BASE="${WORKCELL_TABLE1_BASE:-configs/train-64.toml}"
STEPS="${1:-$(sed -n 's/^steps = \([0-9]*\).*/\1/p' "$BASE")}"
JOBS="${WORKCELL_TABLE1_JOBS:-2}"
BIN="${WORKCELL_BIN:-target/release/workcell}"
DATASET="${WORKCELL_DATASET:-out/dataset}"
OUT="${WORKCELL_TABLE1_OUT:-out/table1}"
SPLIT=test
. experiments/scripts/lib/variants.sh
variants_setup
VARIANTS=(hgru:true:false hgru:false:false hgru:true:true convlstm:true:false convlstm:false:false
          conv:true:false conv:false:false)
if [ -n "${WORKCELL_TABLE1_VARIANTS:-}" ]; then
    read -r -a TRAIN <<< "$WORKCELL_TABLE1_VARIANTS"
    for v in "${TRAIN[@]}"; do
        [[ " ${VARIANTS[*]} " == *" $v "* ]] ||
            { echo "$0: unknown variant $v (one of: ${VARIANTS[*]})" >&2; exit 1; }
    done
else
    TRAIN=("${VARIANTS[@]}")
fi
for v in "${TRAIN[@]}"; do
    IFS=: read -r cell pred delay <<< "$v"
    name="${cell}-pred-${pred}-delay-${delay}"
    base_config "$BASE" "$STEPS" "s/^cell = .*/cell = \"$cell\"/" \
        "s/^prediction_loss = .*/prediction_loss = $pred/" \
        "s/^axonal_delay = .*/axonal_delay = $delay/" > "$OUT/$name.toml"
    queue_variant "$name" "$OUT/$name.toml"
done
variants_finish
{
    echo "| cell | prediction loss | axonal delay | forearm Dice loss | heavy occlusion | medium | light | five-class mean | x 29/50 |"
    echo "|---|---|---|---|---|---|---|---|---|"
    for v in "${VARIANTS[@]}"; do
        IFS=: read -r cell pred delay <<< "$v"
        f="$OUT/${cell}-pred-${pred}-delay-${delay}/test.md"
        if [ ! -f "$f" ]; then
            echo "$0: no score yet for $v ($f)" >&2
            continue
        fi
        dice() { col "$f" "$1" "Dice loss"; }
        mean=$(col "$f" all "class mean Dice")
        scaled=$(python3 -c "import sys; print(f'{float(sys.argv[1]) * 29 / 50:.4f}')" "$mean" ||
                 echo -)
        echo "| $cell | $pred | $delay | $(dice all) | $(dice 'occlusion heavy') |" \
             "$(dice 'occlusion medium') | $(dice 'occlusion light') | $mean | $scaled |"
    done
} | tee "$OUT/table1.md"
