# Sourced by experiments/scripts/table1.sh and experiments/scripts/recipe-ablation.sh: trains variants of a base recipe
# and scores each on one split of the dataset, JOBS variants side by side.
#
# The caller sets BIN, DATASET, OUT, SPLIT and JOBS, then calls variants_setup, queue_variant
# NAME CONFIG [TRAIN-ARGUMENT...] for each variant (resumable: a variant whose
# $OUT/NAME/$SPLIT.md exists is skipped, a stopped one goes on from its checkpoint) and
# variants_finish.

variants_setup() {
    mkdir -p "$OUT"
    [ -f "$DATASET/manifest.json" ] || { echo "$0: no finished dataset at $DATASET" >&2; exit 1; }
    # Absolute: the variants' configurations live in $OUT, and a relative path from there
    # breaks when out/ is a symbolic link (`..` follows the link's target, not the path).
    DATASET_ABS="$(cd "$DATASET" && pwd -P)"
    THREADS=$(( $(nproc) / JOBS )); [ "$THREADS" -ge 1 ] || THREADS=1
    running=0
    failed=0
}

# A base configuration with the dataset, thread count and steps of this run: base_config BASE
# STEPS [SED-EXPRESSION...] > CONFIG.
base_config() {
    local base="$1" steps="$2"
    shift 2
    local args=(-e "s|^dataset = .*|dataset = \"$DATASET_ABS\"|"
                -e "s/^threads = .*/threads = $THREADS/" -e "s/^steps = .*/steps = $steps/")
    for e in "$@"; do [ -n "$e" ] && args+=(-e "$e"); done
    sed "${args[@]}" "$base"
}

run_variant() {
    local name="$1" cfg="$2"
    shift 2
    local log="$OUT/$name.log"
    if [ ! -f "$OUT/$name/$SPLIT.md" ]; then
        "$BIN" train --config "$cfg" "$@" --out "$OUT/$name" > "$log" 2>&1 ||
            { echo "$name: FAILED: $(tail -n 1 "$log")" >&2; return 1; }
        # `train --model baseline` names its weights baseline.safetensors.
        local weights="$OUT/$name/procnet.safetensors"
        [ -f "$weights" ] || weights="$OUT/$name/baseline.safetensors"
        "$BIN" eval segmentation --weights "$weights" \
            --dataset "$DATASET_ABS" --split "$SPLIT" --backend "${WORKCELL_EVAL_BACKEND:-flex}" \
            --threads "$THREADS" --out "$OUT/$name/$SPLIT.md" >> "$log" 2>&1 ||
            { echo "$name: FAILED: $(tail -n 1 "$log")" >&2; return 1; }
    fi
    echo "$name: forearm Dice loss $(col "$OUT/$name/$SPLIT.md" all "Dice loss") on the $SPLIT split"
}

queue_variant() {
    run_variant "$@" &
    running=$((running + 1))
    if [ "$running" -ge "$JOBS" ]; then
        wait -n || failed=1
        running=$((running - 1))
    fi
}

variants_finish() {
    while [ "$running" -gt 0 ]; do
        wait -n || failed=1
        running=$((running - 1))
    done
    [ "$failed" -eq 0 ] || { echo "$0: a variant failed (its log is in $OUT); rerun to resume" >&2; exit 1; }
}

# A cell of `eval segmentation`'s forearm table, the first table whose header starts
# `| group |` (the loss breakdown below it repeats the group names), found by the group and the
# column's header, so that a column added to the table moves nothing:
# col FILE GROUP COLUMN, e.g. col test.md all "class mean Dice". Empty when either is missing.
col() {
    awk -F'|' -v group="$2" -v column="$3" '
        function trim(x) { gsub(/^ +| +$/, "", x); return x }
        !index_of && trim($2) == "group" {
            for (i = 1; i <= NF; i++) if (trim($i) == column) index_of = i
            if (!index_of) exit
            next
        }
        index_of && trim($2) == group { print trim($index_of); exit }
    ' "$1"
}
