#!/usr/bin/env python3
"""How the Vicon task clips' arms bend, under each way of reading them.

Reads every BVH clip of data/mocap/hrc-task-clips (standard library only; every `--step`-th
frame), forward kinematics as the BVH convention has it (each joint's rotations in the order
its CHANNELS line lists them, degrees), and variants: the rotations composed in reverse order,
the angles about some axes negated, the three values as angles about fixed axes z, x, y (the
source converter's, what the `hrc` preset of mocap/src/bvh.rs reads), the hierarchy's sides
swapped (what the preset did before 2026-12-07). Per variant, over both arms of every sampled frame, in the torso frame
(y from the right shoulder to the left, z from the hip to the neck, x = y x z):

- hyperextended: the elbow bent backwards by more than 10 degrees (the forearm turned about +y
  relative to the upper arm: (u x f) . y > sin 10 deg); an elbow bends so at most a few degrees;
- hands ahead / behind: the wrist more than 10 cm in front of / behind its shoulder along x;
- head ahead: the head joint in front of the neck joint.

    python3 experiments/scripts/bvh_elbow_bend.py [--step 25]
"""

import argparse
import glob
import gzip
import math
import os

ROOT = os.path.join(os.path.dirname(__file__), "..", "..")
SIN_10 = math.sin(math.radians(10.0))


def parse(path):
    toks = gzip.open(path, "rt").read().split()
    i, joints, stack, channels = 0, [], [], 0
    while toks[i] != "MOTION":
        t = toks[i]
        if t in ("ROOT", "JOINT"):
            joints.append({"name": toks[i + 1], "parent": stack[-1] if stack else None, "ch": []})
            i += 2
        elif t == "End":
            joints.append({"name": "end", "parent": stack[-1], "ch": []})
            i += 2
        elif t == "{":
            stack.append(len(joints) - 1)
            i += 1
        elif t == "}":
            stack.pop()
            i += 1
        elif t == "OFFSET":
            joints[-1]["off"] = [float(x) for x in toks[i + 1:i + 4]]
            i += 4
        elif t == "CHANNELS":
            n = int(toks[i + 1])
            joints[-1]["ch"], joints[-1]["first"] = toks[i + 2:i + 2 + n], channels
            channels += n
            i += 2 + n
        else:
            i += 1
    frames = int(toks[i + 2])  # MOTION Frames: N Frame Time: dt, then the values
    return joints, channels, frames, [float(x) for x in toks[i + 6:]]


def rot(axis, a):
    c, s = math.cos(a), math.sin(a)
    return {"X": [[1, 0, 0], [0, c, -s], [0, s, c]],
            "Y": [[c, 0, s], [0, 1, 0], [-s, 0, c]],
            "Z": [[c, -s, 0], [s, c, 0], [0, 0, 1]]}[axis]


def mm(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)] for i in range(3)]


def mv(a, v):
    return [sum(a[i][k] * v[k] for k in range(3)) for i in range(3)]


def sub(a, b):
    return [x - y for x, y in zip(a, b)]


def dot(a, b):
    return sum(x * y for x, y in zip(a, b))


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def unit(a):
    n = math.sqrt(dot(a, a))
    return [x / n for x in a] if n > 1e-9 else a


def positions(clip, f, reverse, negated):
    joints, channels, _, values = clip
    v = values[f * channels:(f + 1) * channels]
    R, P, out = [None] * len(joints), [None] * len(joints), {}
    for j, joint in enumerate(joints):
        t, r, rs = list(joint["off"]), [[1, 0, 0], [0, 1, 0], [0, 0, 1]], []
        for k, c in enumerate(joint["ch"]):
            x = v[joint["first"] + k]
            if c.endswith("position"):
                t["XYZ".index(c[0])] += x
            else:
                rs.append((c[0], math.radians(-x if c[0] in negated else x)))
        if reverse == "fixed_zxy" and len(rs) == 3:
            # The source's converter (scipy's extrinsic 'zxy'): the three values in the
            # file's order are angles about the fixed z, x and y axes, whatever the header
            # lists: R = R_y R_x R_z.
            rs = [("Y", rs[2][1]), ("X", rs[1][1]), ("Z", rs[0][1])]
        elif reverse is True:
            rs = rs[::-1]
        for axis, a in rs:
            r = mm(r, rot(axis, a))
        p = joint["parent"]
        if p is None:
            R[j], P[j] = r, t
        else:
            R[j], P[j] = mm(R[p], r), [a + b for a, b in zip(P[p], mv(R[p], t))]
        out[joint["name"]] = P[j]
    return out


def measure(clips, step, reverse, negated, swap):
    right, left = ("left", "right") if swap else ("right", "left")
    hyper = ahead = behind = head = arms = frames = 0
    for clip in clips:
        for f in range(0, clip[2], step):
            p = positions(clip, f, reverse, negated)
            rs, ls = p[right + "_upper_arm"], p[left + "_upper_arm"]
            y = unit(sub(ls, rs))
            up = sub(p["neck"], p["hip"])
            z = unit(sub(up, [c * dot(up, y) for c in y]))
            x = cross(y, z)
            for side, s in ((right, rs), (left, ls)):
                u = unit(sub(p[side + "_forearm"], s))
                fo = unit(sub(p[side + "_hand"], p[side + "_forearm"]))
                hyper += dot(cross(u, fo), y) > SIN_10
                hx = dot(sub(p[side + "_hand"], s), x)
                ahead += hx > 100.0
                behind += hx < -100.0
                arms += 1
            head += dot(sub(p["head"], p["neck"]), x) > 0.0
            frames += 1
    return hyper / arms, ahead / arms, behind / arms, head / frames


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--step", type=int, default=25)
    args = ap.parse_args()
    folder = os.path.join(ROOT, "data", "mocap", "hrc-task-clips")
    with open(os.path.join(folder, "DUPLICATES")) as f:
        duplicates = {line.split(":")[0] for line in f if ".bvh.gz:" in line}
    paths = [p for p in sorted(glob.glob(os.path.join(folder, "*", "*.bvh.gz")))
             if os.path.relpath(p, folder) not in duplicates]
    clips = [parse(p) for p in paths]
    print(f"{len(paths)} clips, every {args.step}th frame")
    print("| reading | elbows hyperextended > 10 deg | hands > 10 cm ahead | hands > 10 cm behind | head ahead of neck |")
    print("|---|---:|---:|---:|---:|")
    for reverse in (False, True, "fixed_zxy"):
        for negated in ("", "X", "Y", "Z", "XY", "XZ", "YZ", "XYZ") if reverse != "fixed_zxy" else ("",):
            for swap in (True, False):
                h, a, b, hd = measure(clips, args.step, reverse, negated, swap)
                name = (f"{dict([(False, 'listed order'), (True, 'reversed order'), ('fixed_zxy', 'z, x, y about fixed axes (the source converter)')])[reverse]}"
                        f"{', negated ' + negated if negated else ''}"
                        f"{', sides swapped' if swap else ', names as written'}")
                print(f"| {name} | {h:.2f} | {a:.2f} | {b:.2f} | {hd:.2f} |")


if __name__ == "__main__":
    main()
