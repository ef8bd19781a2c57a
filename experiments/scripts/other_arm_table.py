#!/usr/bin/env python3
"""The violations an evaluation of a one-armed human cannot see, as a Markdown table.

    experiments/scripts/other_arm_table.py RUN [RUN ...] [--seeds N] [--d-min 0.1]

Each RUN is a `workcell evaluate --out` folder of recorded clips (its `metrics.csv` has the
columns `other_arm_min_separation_m` and `other_arm_violation_s`). One row per run: the
episodes (those with seed <= N when given: one per clip where N is the number of clips),
how many came below d_min with the modelled human, with the other arm, with the other arm
only (the hidden ones), with either, and the other arm's contacts and closest approach.
Standard library only.
"""

import argparse
import csv
import math
import os
import sys


def number(text):
    try:
        v = float(text)
    except (TypeError, ValueError):
        return math.nan
    return v


def row(rows, d_min):
    """The table's counts over `rows` (dicts of one run's metrics.csv)."""
    seen = [r for r in rows if number(r["violations"]) > 0]
    other = [number(r["other_arm_min_separation_m"]) for r in rows]
    played = [d for d in other if not math.isnan(d)]
    below_other = {r["seed"] for r, d in zip(rows, other) if d < d_min}
    below_seen = {r["seed"] for r in seen}
    return {
        "episodes": len(rows),
        "with_other_arm": len(played),
        "seen": len(below_seen),
        "other": len(below_other),
        "hidden": len(below_other - below_seen),
        "either": len(below_other | below_seen),
        "other_contacts": sum(1 for d in played if d <= 0.0),
        "other_closest_m": min(played) if played else math.nan,
        "other_below_s": sum(
            number(r["other_arm_violation_s"]) for r in rows if r["seed"] in below_other
        ),
    }


def load(folder, seeds):
    path = os.path.join(folder, "metrics.csv")
    try:
        with open(path, newline="") as f:
            rows = list(csv.DictReader(f))
    except OSError as e:
        sys.exit(f"{path}: {e}")
    if rows and "other_arm_min_separation_m" not in rows[0]:
        sys.exit(f"{path}: no other_arm_min_separation_m column (a run from before it)")
    return [r for r in rows if seeds is None or int(r["seed"]) <= seeds]


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", nargs="+")
    parser.add_argument("--seeds", type=int, help="only the episodes of seeds 1 to N")
    parser.add_argument("--d-min", type=float, default=0.1, help="d_min, m (0.1)")
    args = parser.parse_args()
    print(
        "| run | episodes | below d_min, the modelled human | the other arm | the other arm only (hidden) "
        "| either | other arm touching | other arm closest (m) | other arm below d_min (s) |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for run in args.runs:
        r = row(load(run, args.seeds), args.d_min)
        print(
            f"| {run} | {r['episodes']} | {r['seen']} | {r['other']} | {r['hidden']} | "
            f"{r['either']} | {r['other_contacts']} | {r['other_closest_m']:.3f} | "
            f"{r['other_below_s']:.1f} |"
        )


if __name__ == "__main__":
    main()
