#!/usr/bin/env python3
"""Splits the pose target's misses by the side from which the camera sees the human.

    experiments/scripts/misses_by_view.py DATASET CSV [CSV ...]

DATASET is the dataset the evaluation read (`workcell dataset generate`'s folder); each CSV
is `workcell eval pose`'s pose_frames.csv of it. For every frame the view angle is the angle
between the torso's forward axis (the human model's x, `robots/urdf/generate.py`) and the
direction from the torso to the camera, both from the frame's labels (the torso's `X_CP`):
0 deg sees the human from the front, 180 deg from behind. Frames are binned front (below
60 deg), side (60-120 deg) and back (120 deg and more). For each file: the pose target's
frames (at least 34 % of the forearm visible, i.e. occlusion <= 0.66) and misses (no pose)
per bin, and the sequences that hold the misses with their view angle.

Standard-library Python.
"""

import argparse
import csv
import json
import math
import os
import sys
from collections import Counter

# The pose target asks for a pose in every frame showing at least this share of the forearm.
MIN_VISIBLE = 0.34
BINS = (("front", 60.0), ("side", 120.0), ("back", 180.0 + 1e-9))


def rotate(q, v):
    """v rotated by the unit quaternion q = (x, y, z, w)."""
    x, y, z, w = q
    # t = 2 q_vec x v; v' = v + w t + q_vec x t
    tx = 2.0 * (y * v[2] - z * v[1])
    ty = 2.0 * (z * v[0] - x * v[2])
    tz = 2.0 * (x * v[1] - y * v[0])
    return (
        v[0] + w * tx + (y * tz - z * ty),
        v[1] + w * ty + (z * tx - x * tz),
        v[2] + w * tz + (x * ty - y * tx),
    )


def view_angle_deg(labels):
    """The angle between the torso's forward axis and the torso-to-camera direction."""
    torso = next((p for p in labels.get("parts", []) if p.get("class") == "torso"), None)
    if torso is None:
        return None
    pose = torso["X_CP"]
    t = pose["xyz_m"]
    forward = rotate(pose["quaternion_xyzw"], (1.0, 0.0, 0.0))
    to_camera = (-t[0], -t[1], -t[2])  # the camera's origin, seen from the torso
    n = math.hypot(*to_camera) * math.hypot(*forward)
    if n == 0.0:
        return None
    c = sum(a * b for a, b in zip(forward, to_camera)) / n
    return math.degrees(math.acos(max(-1.0, min(1.0, c))))


def view_bin(angle):
    return next(name for name, upper in BINS if angle < upper)


class Views:
    """View angles of a dataset's frames, read on demand."""

    def __init__(self, root):
        self.root = root
        try:
            with open(os.path.join(root, "manifest.json")) as f:
                manifest = json.load(f)
        except OSError as e:
            raise SystemExit(f"{root}: not a dataset ({e.strerror} reading manifest.json)")
        except json.JSONDecodeError as e:
            raise SystemExit(f"{root}/manifest.json: {e}")
        self.dirs = {s["index"]: s["dir"] for s in manifest.get("sequences", [])}
        self.cache = {}

    def angle(self, sequence, frame):
        key = (sequence, frame)
        if key not in self.cache:
            d = self.dirs.get(sequence)
            if d is None:
                raise SystemExit(f"{self.root}: has no sequence {sequence}")
            path = os.path.join(self.root, d, f"frame_{frame:03d}.json")
            try:
                with open(path) as f:
                    self.cache[key] = view_angle_deg(json.load(f))
            except (OSError, json.JSONDecodeError) as e:
                raise SystemExit(f"{path}: {e}")
        return self.cache[key]


def tally(views, path):
    """Target frames and misses per bin, and each missing sequence's misses and angle."""
    frames, misses, by_sequence = Counter(), Counter(), {}
    try:
        f = open(path, newline="")
    except OSError as e:
        raise SystemExit(f"{path}: cannot read: {e.strerror}")
    with f:
        reader = csv.DictReader(f)
        need = {"sequence", "frame", "occlusion", "no_pose"}
        if not need <= set(reader.fieldnames or []):
            raise SystemExit(f"{path}: not a pose_frames.csv (needs {sorted(need)})")
        for line, r in enumerate(reader, start=2):
            try:
                s, k, occlusion = int(r["sequence"]), int(r["frame"]), float(r["occlusion"])
            except ValueError as e:
                raise SystemExit(f"{path}:{line}: {e}")
            if occlusion > 1.0 - MIN_VISIBLE + 1e-9:  # 0.66 itself is a target frame
                continue
            angle = views.angle(s, k)
            if angle is None:
                continue
            b = view_bin(angle)
            frames[b] += 1
            if r["no_pose"].strip():
                misses[b] += 1
                n, a = by_sequence.get(s, (0, angle))
                by_sequence[s] = (n + 1, a)
    return frames, misses, by_sequence


def report(path, frames, misses, by_sequence):
    cells = []
    for name, _ in BINS:
        if frames[name]:
            share = 100.0 * misses[name] / frames[name]
            cells.append(f"{name} {misses[name]} of {frames[name]} ({share:.1f} %)")
    worst = sorted(by_sequence.items(), key=lambda kv: (-kv[1][0], kv[0]))
    named = ", ".join(f"{s}: {n} at {a:.0f} deg" for s, (n, a) in worst)
    return f"{path}: target misses by view: {'; '.join(cells)}" + (f" [{named}]" if named else "")


def main(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("dataset", help="the dataset the evaluation read")
    p.add_argument("csv", nargs="+", help="pose_frames.csv files of `workcell eval pose`")
    a = p.parse_args(argv)
    views = Views(a.dataset)
    for path in a.csv:
        print(report(path, *tally(views, path)))


if __name__ == "__main__":
    main(sys.argv[1:])
