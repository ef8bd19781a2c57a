#!/usr/bin/env python3
"""Calibrates the articulated fit's uncertainty for one source of masks.

The fit reports, per frame, the radius (`Calibration::radius` in perception/src/pose)

    max(scale * sigma + floor, spread)

sigma: the curvature of its score, mapped to metres at the forearm's centre and wrist;
spread: how far apart the hypotheses the masks cannot tell apart put them. This script reads
the per-frame CSV of

    workcell eval pose --split validation [--masks procnet] [--depth] --out DIR

(its `sigma_m`, `spread_m` and `ends_cm` columns: the error to cover is the farther of the
forearm's centre and wrist) and, for each scale on a grid, finds the smallest floor that puts
the coverage target of the frames within the radius. It prints the table and the pair with
the smallest mean radius; given a second CSV (the test split) it reports the coverage there
too, which is the honest figure: the pair was chosen on the first.

    scripts/calibrate_uncertainty.py VALIDATION.csv [TEST.csv] [--target 0.99]

Standard library only.
"""

import argparse
import csv
import statistics
import sys

SCALES = [0.0, 0.5, 1.0, 2.0, 3.0, 5.0, 8.0, 10.0, 15.0, 20.0]


def load(path):
    """(error m, sigma m, spread m) of every frame with a pose."""
    try:
        with open(path, newline="") as f:
            rows = list(csv.DictReader(f))
    except OSError as e:
        sys.exit(f"{path}: {e}")
    missing = {"no_pose", "ends_cm", "sigma_m", "spread_m"} - set(rows[0] if rows else {})
    if missing:
        sys.exit(
            f"{path}: not a pose_frames.csv of `workcell eval pose --method articulated` "
            f"(no {sorted(missing)})"
        )
    return [
        (
            float(r["ends_cm"]) / 100.0,
            float(r["sigma_m"]),
            float(r["spread_m"]),
        )
        for r in rows
        if r["no_pose"] == "" and r["ends_cm"] != ""
    ]


def quantile(sorted_values, q):
    return sorted_values[min(len(sorted_values) - 1, int(q * len(sorted_values)))]


def radius(frame, calibration):
    """The radius the fit reports for `frame` under `calibration` (scale, floor)."""
    _, sigma, spread = frame
    scale, floor = calibration
    return max(scale * sigma + floor, spread)


def smallest_floor(frames, scale, target):
    """The smallest floor with `target` of `frames` within max(scale sigma + floor, spread)."""
    if not frames:
        return 0.0
    # A frame is covered by its spread alone, or needs error - scale * sigma of floor.
    need = sorted(0.0 if e <= s else e - scale * u for e, u, s in frames)
    return max(0.0, quantile(need, target))


def coverage(frames, calibration):
    return sum(1 for f in frames if f[0] <= radius(f, calibration)) / len(frames)


def calibrate(frames, target):
    """Per scale, (scale, floor) and its mean radius; and the row of smallest mean radius."""
    rows = []
    for a in SCALES:
        calibration = (a, smallest_floor(frames, a, target))
        rows.append((calibration, statistics.mean(radius(f, calibration) for f in frames)))
    return rows, min(rows, key=lambda r: r[1])


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
    errors = sorted(f[0] for f in val)
    print(
        f"{args.validation}: {len(val)} frames with a pose; error median "
        f"{100 * quantile(errors, 0.5):.2f} cm, 99th percentile {100 * quantile(errors, 0.99):.2f} cm"
    )
    rows, best = calibrate(val, args.target)
    print(
        "| scale | floor (cm) | mean radius (cm) | 95th pct radius (cm) | validation coverage |"
        + (" test coverage |" if test else "")
    )
    print("|---|---|---|---|---|" + ("---|" if test else ""))
    for calibration, mean in rows:
        a, floor = calibration
        radii = sorted(radius(f, calibration) for f in val)
        row = (
            f"| {a:g} | {100 * floor:.2f} | {100 * mean:.2f} | {100 * quantile(radii, 0.95):.2f} "
            f"| {100 * coverage(val, calibration):.2f} % |"
        )
        if test:
            row += f" {100 * coverage(test, calibration):.2f} % of {len(test)} |"
        print(row)
    (a, floor), mean = best
    print(f"\nsmallest mean radius: scale {a:g}, floor {floor:.4f} m (mean {100 * mean:.2f} cm)")


if __name__ == "__main__":
    main()
