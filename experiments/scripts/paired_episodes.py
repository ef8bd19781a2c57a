#!/usr/bin/env python3
"""Compares two closed-loop evaluations of the same seeds, paired by seed.

    experiments/scripts/paired_episodes.py RUN_A RUN_B [--column perception_error_m] ...

RUN_A and RUN_B are `workcell evaluate --out` folders (their `metrics.csv`). For each column
it prints the mean of B - A over the seeds where both have a finite value, the 95 %
bootstrap interval of that mean (4,000 resamples of the seeds, fixed seed), and in how many
seeds B is the lower. An unfinished episode has no task ratio and drops out of that column.
Standard library only.
"""

import argparse
import csv
import math
import os
import random
import statistics
import sys


def load(folder):
    path = os.path.join(folder, "metrics.csv")
    try:
        with open(path, newline="") as f:
            return {r["seed"]: r for r in csv.DictReader(f)}
    except OSError as e:
        sys.exit(f"{path}: {e}")


def number(text):
    try:
        v = float(text)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("a")
    parser.add_argument("b")
    parser.add_argument("--column", action="append",
                        help="a metrics.csv column (default: perception_error_m, task_ratio)")
    args = parser.parse_args()
    a, b = load(args.a), load(args.b)
    rng = random.Random(1)
    for column in args.column or ["perception_error_m", "task_ratio"]:
        d = []
        for seed in sorted(set(a) & set(b), key=int):
            x, y = number(a[seed].get(column)), number(b[seed].get(column))
            if x is not None and y is not None:
                d.append(y - x)
        if not d:
            print(f"{column}: no seed with a value in both")
            continue
        means = sorted(statistics.mean(rng.choice(d) for _ in d) for _ in range(4000))
        print(
            f"{column}: B - A = {statistics.mean(d):+.4f} (95 % {means[100]:+.4f} to "
            f"{means[3899]:+.4f}), {len(d)} seeds, B lower in {sum(v < 0 for v in d)}"
        )


if __name__ == "__main__":
    main()
