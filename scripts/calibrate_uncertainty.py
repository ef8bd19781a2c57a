#!/usr/bin/env python3
"""Calibrates the articulated fit's uncertainty for one source of masks.

The fit reports, per frame, a radius `scale * sigma + floor` (sigma: the curvature of its
score, mapped to metres at the forearm's centre and wrist; the farther hypothesis when the
masks leave a mirror). This script reads the per-frame CSV of

    workcell eval pose --split validation [--masks procnet] [--depth] --out DIR

(written with the shipped scale 1 and floor 0, so that its `uncertainty_m` column is sigma,
or the hypotheses' spread where that is larger) and, for each scale on a grid, finds the
smallest floor that puts the coverage target of the frames' forearm centre and wrist
(`ends_cm`) within the radius. It prints the table and the pair with the smallest mean
radius; given a second CSV (the test split) it reports the coverage there too, which is the
honest figure: the pair was chosen on the first.

    scripts/calibrate_uncertainty.py VALIDATION.csv [TEST.csv] [--target 0.99]

Standard library only.
"""

import argparse
import csv
import statistics
import sys

SCALES = [0.0, 0.5, 1.0, 2.0, 3.0, 5.0, 8.0, 10.0, 15.0, 20.0]


def load(path):
    """(error m, reported sigma m) of every frame with a pose."""
    try:
        with open(path, newline="") as f:
            rows = list(csv.DictReader(f))
    except OSError as e:
        sys.exit(f"{path}: {e}")
    missing = {"no_pose", "ends_cm", "uncertainty_m"} - set(rows[0] if rows else {})
    if missing:
        sys.exit(f"{path}: not a pose_frames.csv of `workcell eval pose` (no {sorted(missing)})")
    return [
        (float(r["ends_cm"]) / 100.0, float(r["uncertainty_m"]))
        for r in rows
        if r["no_pose"] == "" and r["ends_cm"] != ""
    ]


def quantile(sorted_values, q):
    return sorted_values[min(len(sorted_values) - 1, int(q * len(sorted_values)))]


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("validation")
    parser.add_argument("test", nargs="?")
    parser.add_argument("--target", type=float, default=0.99)
    args = parser.parse_args()
    if not 0.0 < args.target < 1.0:
        sys.exit("--target is a fraction in (0, 1)")
    val = load(args.validation)
    test = load(args.test) if args.test else None
    if not val:
        sys.exit(f"{args.validation}: no frame with a pose")
    errors = sorted(e for e, _ in val)
    print(
        f"{args.validation}: {len(val)} frames with a pose; error median "
        f"{100 * quantile(errors, 0.5):.2f} cm, 99th percentile {100 * quantile(errors, 0.99):.2f} cm"
    )
    print("| scale | floor (cm) | mean radius (cm) | 95th pct radius (cm) |"
          + (" test coverage |" if test else ""))
    print("|---|---|---|---|" + ("---|" if test else ""))
    best = None
    for a in SCALES:
        need = sorted(e - a * u for e, u in val)
        floor = max(0.0, quantile(need, args.target))
        radii = sorted(a * u + floor for _, u in val)
        mean = statistics.mean(radii)
        row = f"| {a:g} | {100 * floor:.2f} | {100 * mean:.2f} | {100 * quantile(radii, 0.95):.2f} |"
        if test:
            covered = sum(1 for e, u in test if e <= a * u + floor) / len(test)
            row += f" {100 * covered:.2f} % of {len(test)} |"
        print(row)
        if best is None or mean < best[2]:
            best = (a, floor, mean)
    a, floor, mean = best
    print(f"\nsmallest mean radius: scale {a:g}, floor {floor:.4f} m (mean {100 * mean:.2f} cm)")


if __name__ == "__main__":
    main()
