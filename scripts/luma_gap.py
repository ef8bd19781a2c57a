#!/usr/bin/env python3
"""How much worse a dark forearm is segmented than a lighter one, with an interval.

Reads the per-frame CSV of `workcell eval segmentation --frames FILE.csv` and prints, per luma
band (the bands of `eval segmentation`: dark below 0.08, light from 0.35), the sequences,
frames and mean forearm Dice loss, then the gap between the dark band and the rest with a 95 %
bootstrap interval that resamples whole sequences (frames of one sequence are not
independent). Standard library only.

    python3 scripts/luma_gap.py out/train/test_frames.csv [--resamples 4000] [--seed 0]
"""

import argparse
import csv
import random
import sys
from collections import defaultdict

DARK_BELOW = 0.08
LIGHT_FROM = 0.35


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


def rest_of(bands: dict) -> list:
    """The frames outside the dark band, one group per sequence (a sequence whose forearm is
    mid in some frames and light in others is still one unit of the resampling)."""
    rest: dict = defaultdict(list)
    for name in ("mid", "light"):
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
    for name in ("dark", "mid", "light"):
        seqs = list(bands[name].values())
        if seqs:
            print(f"| {name} | {len(seqs)} | {sum(map(len, seqs))} | {frame_mean(seqs):.4f} |")
    dark = list(bands["dark"].values())
    rest = rest_of(bands)
    if not dark or not rest:
        sys.exit("no gap to measure: a band is empty")
    rng = random.Random(args.seed)
    gaps = sorted(
        frame_mean(rng.choices(dark, k=len(dark))) - frame_mean(rng.choices(rest, k=len(rest)))
        for _ in range(args.resamples)
    )
    lo, hi = gaps[int(0.025 * len(gaps))], gaps[int(0.975 * len(gaps)) - 1]
    gap = frame_mean(dark) - frame_mean(rest)
    print(
        f"\ndark - rest: {gap:+.4f}, 95 % interval [{lo:+.4f}, {hi:+.4f}] "
        f"({args.resamples} resamples of whole sequences)"
    )


if __name__ == "__main__":
    main()
