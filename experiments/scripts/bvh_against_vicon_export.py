#!/usr/bin/env python3
"""A shipped Vicon task clip's bones against the source's own Vicon export, under two readings.

The source repository of data/mocap/hrc-task-clips (human-robot-animations, at the commit in
SOURCE_COMMIT) keeps, beside some BVH files, the Vicon export they were made from (for
example `CollaborativeHammering/0.csv`: per segment its global rotation vector and position,
mm, z up). This script reads the BVH (a shipped `.bvh.gz`) two ways,
the BVH format's convention (each joint's rotations in its header's order about moving axes)
and the converter's (three values about fixed axes z, x, y: R = R_y R_x R_z), turns the
export into the BVH's axes as the converter does (Rz(90) Ry(90) Rz(-90)), aligns the frames by
the hip's path and prints, per bone, the median and 75th-percentile angle between the two.
Needs numpy and scipy (not the project's: `pip install numpy scipy`).

    python3 experiments/scripts/bvh_against_vicon_export.py \\
        data/mocap/hrc-task-clips/CollaborativeHammering/0.bvh.gz CollaborativeHammering-0.csv
"""

import argparse
import importlib.util
import os

import numpy as np
from scipy.spatial.transform import Rotation as R


def parse_bvh(path):
    """The hierarchy and the frames' values of a gzipped BVH file, by bvh_elbow_bend's parser."""
    spec = importlib.util.spec_from_file_location(
        "bvh_elbow_bend", os.path.join(os.path.dirname(os.path.abspath(__file__)), "bvh_elbow_bend.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    joints, channels, frames, values = module.parse(path)
    for j in joints:
        j["off"] = np.array(j.get("off", [0.0, 0.0, 0.0]), dtype=float)
        j.setdefault("first", 0)
    return joints, np.array(values).reshape(frames, channels)


def positions(joints, v, reading):
    out, poses = {}, []
    for j in joints:
        t, rot = j["off"].copy(), R.identity()
        angles = []
        for k, c in enumerate(j["ch"]):
            if c.endswith("position"):
                t["XYZ".index(c[0])] += v[j["first"] + k]
            else:
                angles.append((c[0].lower(), v[j["first"] + k]))
        if angles and reading == "fixed_zxy":
            rot = R.from_euler("zxy", [a for _, a in angles], degrees=True)
        else:
            for axis, a in angles:
                rot = rot * R.from_euler(axis, a, degrees=True)
        if j["parent"] is None:
            pose = (rot, t)
        else:
            pr, pt = poses[j["parent"]]
            pose = (pr * rot, pt + pr.apply(t))
        poses.append(pose)
        out.setdefault(j["name"], pose[1])
    return out


def read_export(path):
    rows = [line.rstrip("\n").split(",") for line in open(path, encoding="utf-8-sig")]
    names = [rows[2][2 + 6 * k].split(":")[-1] for k in range((len(rows[2]) - 2) // 6)]
    to_bvh = R.from_euler("z", 90, degrees=True) * R.from_euler("y", 90, degrees=True) \
        * R.from_euler("z", -90, degrees=True)
    frames = []
    for r in rows[5:]:
        cells = r[2:2 + 6 * len(names)]
        if len(cells) < 6 * len(names) or any(x == "" for x in cells):
            frames.append(None)
            continue
        frames.append({n: to_bvh.apply([float(x) for x in cells[6 * k + 3:6 * k + 6]])
                       for k, n in enumerate(names)})
    return frames


BONES = [  # (BVH joint, BVH joint, export segment, export segment)
    ("right_upper_arm", "right_forearm", "right_shoulder", "right_elbow"),
    ("right_forearm", "right_hand", "right_elbow", "right_hand"),
    ("left_upper_arm", "left_forearm", "left_shoulder", "left_elbow"),
    ("left_forearm", "left_hand", "left_elbow", "left_hand"),
    ("neck", "head", "collar", "head"),
]


def angle(a, b):
    return np.degrees(np.arccos(np.clip(np.dot(a, b) / np.linalg.norm(a) / np.linalg.norm(b), -1, 1)))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("bvh")
    ap.add_argument("export")
    args = ap.parse_args()
    joints, values = parse_bvh(args.bvh)
    export = read_export(args.export)
    hip = np.array([f["hip"] if f else [np.nan] * 3 for f in export])
    shift = min(range(len(hip) - len(values) + 1),
                key=lambda k: np.nanmean(np.linalg.norm(hip[k:k + len(values)] - values[:, :3], axis=1)))
    print(f"{len(values)} BVH frames; the export's frame f + {shift + 1} (its Frame column) is the BVH's f")
    print("| reading | frames | " + " | ".join(f"{a} -> {b}" for a, b, _, _ in BONES) + " |")
    print("|---|---:|" + "---:|" * len(BONES))
    for reading in ("fixed_zxy", "listed"):
        errors, n = [[] for _ in BONES], 0
        for f in range(len(values)):
            e = export[f + shift] if f + shift < len(export) else None
            if e is None:
                continue
            n += 1
            p = positions(joints, values[f], reading)
            for i, (a, b, ea, eb) in enumerate(BONES):
                errors[i].append(angle(p[b] - p[a], e[eb] - e[ea]))
        cells = " | ".join(f"{np.median(x):.1f} ({np.percentile(x, 75):.1f})" for x in errors)
        print(f"| {reading}: median (75th percentile), degrees | {n} | {cells} |")


if __name__ == "__main__":
    main()
