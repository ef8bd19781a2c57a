#!/usr/bin/env python3
"""How much of the forearm's loss is where the elbow and the wrist are drawn, by how bent the
elbow is.

Reads the per-frame CSV of `workcell eval segmentation --frames FILE.csv` (the thresholded
forearm Dice loss, and the same with every pixel that is arm in both truth and prediction given
its true part) and each frame's elbow flexion from the dataset's frame labels (`human_q`, joint
order of the catalogue's `human_arm`: shoulder abduction, shoulder flexion, elbow flexion; 0 is
a straight arm). Prints, per band of elbow flexion, the frames, the sequences, both losses and
their difference: the part of the loss that a network placing the elbow and the wrist right
would remove. A straight arm in one skin or one sleeve marks its elbow by nothing but its
proportions. Standard library only.

    python3 experiments/scripts/part_boundaries.py out/train/test_frames.csv --dataset out/dataset \
        [--edges-deg 10,20,40]
"""

import argparse
import csv
import json
import math
import os
import sys
from collections import defaultdict

ELBOW = 2  # index of the elbow flexion in `human_q`


def edges(text: str) -> list:
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError as e:
        raise argparse.ArgumentTypeError(f"comma-separated degrees, got {text!r}") from e
    if not values or any(b <= a for a, b in zip(values, values[1:])) or values[0] <= 0:
        raise argparse.ArgumentTypeError(f"increasing positive degrees, got {text!r}")
    return values


def band_names(edges_deg: list) -> list:
    bounds = [0.0, *edges_deg]
    names = [f"{a:g}-{b:g} deg" for a, b in zip(bounds, bounds[1:])]
    return [*names, f">= {edges_deg[-1]:g} deg"]


def band_of(flexion_deg: float, edges_deg: list) -> int:
    return sum(flexion_deg >= e for e in edges_deg)


def elbow_flexion_deg(dataset: str, sequence: int, frame: int) -> float:
    path = os.path.join(dataset, f"seq_{sequence:05}", f"frame_{frame:03}.json")
    try:
        with open(path) as f:
            q = json.load(f).get("human_q", [])
    except (OSError, ValueError) as e:
        sys.exit(f"{path}: {e}")
    if len(q) <= ELBOW or not isinstance(q[ELBOW], (int, float)):
        sys.exit(f"{path}: no elbow flexion in human_q")
    return math.degrees(abs(q[ELBOW]))


def read(path: str, dataset: str, edges_deg: list) -> dict:
    """{band: [(sequence, thresholded loss, loss with the parts right)]}."""
    needed = {"sequence", "frame", "forearm_dice_thresholded", "forearm_dice_parts_right"}
    bands: dict = defaultdict(list)
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        missing = needed - set(reader.fieldnames or [])
        if missing:
            sys.exit(f"{path}: no {', '.join(sorted(missing))} column (eval segmentation --frames)")
        for row in reader:
            sequence, frame = int(row["sequence"]), int(row["frame"])
            band = band_of(elbow_flexion_deg(dataset, sequence, frame), edges_deg)
            bands[band].append(
                (
                    sequence,
                    float(row["forearm_dice_thresholded"]),
                    float(row["forearm_dice_parts_right"]),
                )
            )
    return bands


def table(bands: dict, edges_deg: list) -> str:
    lines = [
        "| elbow flexion | frames | sequences | Dice loss, thresholded "
        "| with the elbow and wrist right | at the elbow and wrist | share of the loss |",
        "|---|---|---|---|---|---|---|",
    ]
    everything = [r for rows in bands.values() for r in rows]
    names = band_names(edges_deg)
    for name, rows in [*((names[b], bands[b]) for b in sorted(bands)), ("all", everything)]:
        n = len(rows)
        if n == 0:
            continue
        loss = sum(r[1] for r in rows) / n
        right = sum(r[2] for r in rows) / n
        share = f"{(loss - right) / loss:.0%}" if loss > 0 else "-"
        sequences = len({r[0] for r in rows})
        lines.append(
            f"| {name} | {n} | {sequences} | {loss:.4f} | {right:.4f} | {loss - right:.4f} | {share} |"
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("frames_csv")
    parser.add_argument("--dataset", default="out/dataset")
    parser.add_argument("--edges-deg", type=edges, default=[10.0, 20.0, 40.0])
    args = parser.parse_args()
    bands = read(args.frames_csv, args.dataset, args.edges_deg)
    if not bands:
        sys.exit(f"{args.frames_csv}: no frames")
    print(table(bands, args.edges_deg))


if __name__ == "__main__":
    main()
