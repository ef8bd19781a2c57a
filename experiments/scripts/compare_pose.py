#!/usr/bin/env python3
"""Compares pose evaluations (`workcell eval pose`'s pose_frames.csv) of the same frames.

    experiments/scripts/compare_pose.py BASELINE.csv [CANDIDATE.csv ...] [--draws 2000] [--seed 1]

For each file: frames, frames without a pose, the pose target's misses (frames without a
pose in which at least 34 % of the forearm is visible, i.e. occlusion <= 0.66) with the
sequences that hold them, and the average, 99th percentile and count of errors above 10 cm
over the frames with a pose (one file alone: that line only). For every file after the first: the difference of its average
error to the first's, with a 95 % interval from resampling whole sequences (each draw takes
as many sequences as there are, with replacement, and recomputes both averages over the
frames each posed in them). A difference whose interval holds zero is inside the noise
between sequences.

Standard-library Python. The files must hold the same sequences; their frames may differ
slightly (the tracker's crops of two networks can each leave a few frames' forearm out of
view), and each average is over the frames that file posed.
"""

import argparse
import csv
import random
import sys
from collections import Counter, defaultdict

# The pose target asks for a pose in every frame showing at least this share of the forearm.
MIN_VISIBLE = 0.34


class Run:
    """One pose_frames.csv: per sequence, the errors of its posed frames and its misses."""

    def __init__(self, path):
        self.path = path
        self.no_pose = 0
        self.misses = Counter()  # sequence -> target misses
        self.errors = defaultdict(list)  # sequence -> position errors (cm) of posed frames
        self.keys = set()
        try:
            with open(path, newline="") as f:
                rows = list(csv.DictReader(f))
        except OSError as e:
            raise SystemExit(f"{path}: cannot read: {e.strerror}")
        need = {"sequence", "frame", "occlusion", "no_pose", "position_cm"}
        if not rows or not need <= set(rows[0]):
            raise SystemExit(f"{path}: not a pose_frames.csv (needs the columns {sorted(need)})")
        for line, r in enumerate(rows, start=2):
            try:
                seq, frame = int(r["sequence"]), int(r["frame"])
                occlusion = float(r["occlusion"])
                posed = not r["no_pose"].strip()
                error = float(r["position_cm"]) if posed else None
            except (TypeError, ValueError) as e:
                raise SystemExit(f"{path}:{line}: {e}")
            if (seq, frame) in self.keys:
                raise SystemExit(f"{path}:{line}: sequence {seq} frame {frame} twice")
            self.keys.add((seq, frame))
            self.errors.setdefault(seq, [])
            if posed:
                self.errors[seq].append(error)
            else:
                self.no_pose += 1
                if occlusion <= 1.0 - MIN_VISIBLE + 1e-9:
                    self.misses[seq] += 1

    @property
    def frames(self):
        return len(self.keys)

    def posed(self):
        return sorted(e for errs in self.errors.values() for e in errs)

    def average(self, sequences=None):
        seqs = self.errors if sequences is None else sequences
        total = sum(sum(self.errors[s]) for s in seqs)
        count = sum(len(self.errors[s]) for s in seqs)
        return total / count if count else float("nan")


def percentile(sorted_values, q):
    """The value below which a share q of the values lie (nearest rank)."""
    if not sorted_values:
        return float("nan")
    return sorted_values[min(len(sorted_values) - 1, int(q * len(sorted_values)))]


def resampled_differences(base, other, draws, seed):
    """`draws` differences of the two runs' averages over resampled sequences, sorted."""
    sequences = sorted(base.errors)
    rng = random.Random(seed)
    diffs = []
    while len(diffs) < draws:
        pick = [rng.choice(sequences) for _ in sequences]
        d = other.average(pick) - base.average(pick)
        # A draw of sequences that one run posed in no frame has no average: draw again.
        if d == d:
            diffs.append(d)
    return sorted(diffs)


def bootstrap_difference(base, other, draws, seed):
    """(difference of averages, 2.5th and 97.5th percentile over sequence resamples)."""
    diffs = resampled_differences(base, other, draws, seed)
    low = diffs[int(0.025 * (draws - 1))]
    high = diffs[int(round(0.975 * (draws - 1)))]
    return other.average() - base.average(), low, high


def summary(run):
    posed = run.posed()
    top = ", ".join(f"{s}: {n}" for s, n in run.misses.most_common(5))
    return (
        f"{run.frames} frames, {run.no_pose} without a pose, "
        f"{sum(run.misses.values())} target misses ({top or 'none'}); "
        f"average {run.average():.2f} cm, 99th percentile {percentile(posed, 0.99):.1f} cm, "
        f"{sum(e > 10.0 for e in posed)} above 10 cm"
    )


def main(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument(
        "csv", nargs="+", help="pose_frames.csv files; the others are compared with the first"
    )
    p.add_argument("--draws", type=int, default=2000, help="bootstrap resamples (default 2000)")
    p.add_argument("--seed", type=int, default=1, help="bootstrap seed (default 1)")
    a = p.parse_args(argv)
    if a.draws < 40:
        p.error("--draws: at least 40, for a 95 % interval")
    runs = [Run(path) for path in a.csv]
    for run in runs:
        if not run.posed():
            raise SystemExit(f"{run.path}: no frame has a pose; there is no average to compare")
    base = runs[0]
    for run in runs[1:]:
        if set(run.errors) != set(base.errors):
            only = len(set(run.errors) ^ set(base.errors))
            raise SystemExit(
                f"{run.path} and {base.path} hold different sequences ({only} in one only)"
            )
    print(f"{base.path}: {summary(base)}")
    for run in runs[1:]:
        d, low, high = bootstrap_difference(base, run, a.draws, a.seed)
        verdict = "inside the noise" if low <= 0.0 <= high else "beyond the noise"
        print(f"{run.path}: {summary(run)}")
        if run.keys != base.keys:
            # The tracker's crops of another network can leave a frame's forearm out of view.
            print(f"  {len(run.keys ^ base.keys)} frames are in only one of the two files")
        print(
            f"  average against the first: {d:+.2f} cm, 95 % interval {low:+.2f} to {high:+.2f} "
            f"({len(base.errors)} sequences, {a.draws} resamples): {verdict}"
        )


if __name__ == "__main__":
    main(sys.argv[1:])
