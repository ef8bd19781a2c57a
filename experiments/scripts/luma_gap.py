#!/usr/bin/env python3
"""How much worse a dark or a light forearm is segmented than the others, with an interval.

Reads the per-frame CSV of `workcell eval segmentation --frames FILE.csv` and prints, per luma
band (the bands of `eval segmentation`: dark below 0.2, light from 0.5, by the forearm's
pixels in view), the sequences, frames and mean forearm Dice loss, then the gap between the
dark band and the rest and between the light band and the rest, each with a 95 % bootstrap
interval that resamples whole sequences (frames of one sequence are not independent).
Standard library only.

    python3 experiments/scripts/luma_gap.py out/train/test_frames.csv [--resamples 4000] [--seed 0]
"""

import argparse
import csv
import random
import sys
from collections import defaultdict

DARK_BELOW = 0.2
LIGHT_FROM = 0.5
BANDS = ("dark", "mid", "light")


def band(luma: float) -> str:
    if luma < DARK_BELOW:
        return "dark"
    return "mid" if luma < LIGHT_FROM else "light"


def read(path: str) -> dict:
    """{band: {sequence: [forearm Dice loss of each frame]}} for frames with a forearm."""
    bands: dict = defaultdict(lambda: defaultdict(list))
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        if reader.fieldnames is None or "forearm_luma" not in reader.fieldnames:
            sys.exit(f"{path}: no forearm_luma column (written by eval segmentation --frames)")
        for row in reader:
            if row["forearm_luma"] == "":
                continue
            bands[band(float(row["forearm_luma"]))][int(row["sequence"])].append(
                float(row["forearm_dice"])
            )
    return bands


def rest_of(bands: dict, band_name: str) -> list:
    """The frames outside band `band_name`, one group per sequence (a sequence whose forearm
    falls in both other bands is still one unit of the resampling)."""
    rest: dict = defaultdict(list)
    for name in BANDS:
        if name == band_name:
            continue
        for sequence, frames in bands[name].items():
            rest[sequence].extend(frames)
    return list(rest.values())


def at_least_one(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"at least 1, got {value}")
    return value


def frame_mean(groups: list) -> float:
    frames = [x for g in groups for x in g]
    return sum(frames) / len(frames)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("frames_csv")
    parser.add_argument("--resamples", type=at_least_one, default=4000)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    bands = read(args.frames_csv)
    print("| forearm | sequences | frames | Dice loss |\n|---|---|---|---|")
    for name in BANDS:
        seqs = list(bands[name].values())
        if seqs:
            print(f"| {name} | {len(seqs)} | {sum(map(len, seqs))} | {frame_mean(seqs):.4f} |")
    rng = random.Random(args.seed)
    measured = 0
    for name in ("dark", "light"):
        groups = list(bands[name].values())
        rest = rest_of(bands, name)
        if not groups or not rest:
            print(f"\n{name} - rest: not measured, a side is empty")
            continue
        gaps = sorted(
            frame_mean(rng.choices(groups, k=len(groups)))
            - frame_mean(rng.choices(rest, k=len(rest)))
            for _ in range(args.resamples)
        )
        lo, hi = gaps[int(0.025 * len(gaps))], gaps[int(0.975 * len(gaps)) - 1]
        gap = frame_mean(groups) - frame_mean(rest)
        print(
            f"\n{name} - rest: {gap:+.4f}, 95 % interval [{lo:+.4f}, {hi:+.4f}] "
            f"({args.resamples} resamples of whole sequences)"
        )
        measured += 1
    if measured == 0:
        sys.exit("no gap to measure: every band or its rest is empty")


if __name__ == "__main__":
    main()
