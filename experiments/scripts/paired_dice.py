#!/usr/bin/env python3
"""Two networks' forearm Dice loss on the same frames, by the source of the motion, paired.

Reads two per-frame CSVs of `workcell eval segmentation --frames FILE.csv` made on one
dataset, and that dataset's manifest (a sequence with a `clip` plays a recorded person), and
prints per source (recorded people, the generator's motion) the sequences, frames, each
network's mean loss per frame and the difference B - A with its 95 % interval: the mean of
the per-sequence differences +- 1.96 standard errors (frames of one sequence are not
independent, so the sequence is the unit). Standard library only.

    python3 experiments/scripts/paired_dice.py DATASET A.csv B.csv [--names A B]
"""

import argparse
import csv
import json
import math
import sys
from collections import defaultdict


def read(path: str) -> dict:
    """{(sequence, frame): forearm Dice loss} for the frames that show a forearm."""
    frames = {}
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        if reader.fieldnames is None or "forearm_dice" not in reader.fieldnames:
            sys.exit(f"{path}: no forearm_dice column (written by eval segmentation --frames)")
        for row in reader:
            if row["forearm_dice"] in ("", "NaN", "nan"):
                continue
            frames[(int(row["sequence"]), int(row["frame"]))] = float(row["forearm_dice"])
    return frames


def sources(dataset: str) -> dict:
    """{sequence index: "recorded people" or "the generator's motion"}."""
    try:
        with open(f"{dataset}/manifest.json") as f:
            manifest = json.load(f)
    except (OSError, ValueError) as e:
        sys.exit(f"{dataset}/manifest.json: {e}")
    return {
        s["index"]: "recorded people" if s.get("clip") else "the generator's motion"
        for s in manifest["sequences"]
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dataset")
    parser.add_argument("a")
    parser.add_argument("b")
    parser.add_argument("--names", nargs=2, default=["A", "B"])
    args = parser.parse_args()
    a, b = read(args.a), read(args.b)
    source_of = sources(args.dataset)
    # {source: {sequence: [(loss A, loss B) per frame both scored]}}
    pairs: dict = defaultdict(lambda: defaultdict(list))
    for key in sorted(a.keys() & b.keys()):
        source = source_of.get(key[0])
        if source is None:
            sys.exit(f"sequence {key[0]} is not in {args.dataset}'s manifest")
        pairs[source][key[0]].append((a[key], b[key]))
    name_a, name_b = args.names
    print(f"| source | sequences (frames) | {name_a} | {name_b} | difference |")
    print("|---|---:|---:|---:|---:|")
    for source in sorted(pairs):
        sequences = pairs[source]
        frames = [p for s in sequences.values() for p in s]
        mean_a = sum(p[0] for p in frames) / len(frames)
        mean_b = sum(p[1] for p in frames) / len(frames)
        diffs = [sum(q[1] - q[0] for q in s) / len(s) for s in sequences.values()]
        n = len(diffs)
        mean = sum(diffs) / n
        sd = math.sqrt(sum((d - mean) ** 2 for d in diffs) / (n - 1)) if n > 1 else math.nan
        half = 1.96 * sd / math.sqrt(n)
        print(
            f"| {source} | {n} ({len(frames)}) | {mean_a:.3f} | {mean_b:.3f} | "
            f"{mean:+.3f} ± {half:.3f} |"
        )


if __name__ == "__main__":
    main()
