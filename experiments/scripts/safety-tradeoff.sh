#!/usr/bin/env bash
# The QP filter's trade-off between separation and throughput: the default evaluation with
# d_min and gamma swept, N episodes each (seeds 1..N), one table row per pair. Resumes: a
# pair whose report exists is not run again.
#
#   experiments/scripts/safety-tradeoff.sh [EPISODES] [OUT]      (defaults: 100, out/tradeoff)
#
# detection_m is the larger of 0.6 m and d_min + 2 / gamma + 0.05 m (a pair must enter the
# filter while its row still allows ISO 13855's 2 m/s approach).
set -euo pipefail
cd "$(dirname "$0")/.."
episodes="${1:-100}"
out="${2:-out/tradeoff}"
bin=target/release/workcell
cargo build --release --locked --quiet
mkdir -p "$out"
echo "| d_min (m) | gamma (1/s) | detection (m) | episodes | min separation (m) | episodes with violation | task time / unfiltered | peak approach, upper arm / forearm / hand (m/s) |"
echo "|---|---|---|---|---|---|---|---|"
for d_min in 0.05 0.10 0.15; do
    for gamma in 2 4 8; do
        detection=$(python3 -c "print(round(max(0.6, $d_min + 2 / $gamma + 0.05), 3))")
        dir="$out/d${d_min}-g${gamma}"
        if [ ! -f "$dir/metrics.csv" ]; then
            "$bin" evaluate configs/evaluate.toml --episodes "$episodes" --seed 1 --filter qp \
                --perception noisy --set "safety.d_min_m=$d_min" --set "safety.gamma_per_s=$gamma" \
                --set "safety.detection_m=$detection" --out "$dir" --force >/dev/null
        fi
        python3 - "$dir/metrics.csv" "$d_min" "$gamma" "$detection" <<'PY'
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
ratios = [float(r["task_ratio"]) for r in rows if r["task_ratio"]]
peaks = " / ".join(
    "{:.2f}".format(max(float(r["peak_approach_" + part + "_m_s"]) for r in rows))
    for part in ("upper_arm", "forearm", "hand"))
print("| {} | {} | {} | {} | {:.4f} | {} | {:.3f} | {} |".format(
    sys.argv[2], sys.argv[3], sys.argv[4], len(rows),
    min(float(r["min_separation_m"]) for r in rows),
    sum(1 for r in rows if int(r["violations"]) > 0),
    sum(ratios) / len(ratios) if ratios else float("nan"), peaks))
PY
    done
done
