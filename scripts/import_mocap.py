#!/usr/bin/env python3
"""Brings the recorded motion of ../shared/mocap (or SOURCE) into data/mocap in the compact
form the repository keeps: BVH motion values rounded to 0.01 (degrees, millimetres: 0.05 mm
at the end of a 0.3 m bone), joint-position tables to 0.1 mm, gzipped with a fixed
timestamp so that the same source gives the same bytes. The hierarchy, the frame count
and rate, every clip's file name, the licences and the source commits are kept as they are.
A clip whose motion is another's (the same frames, at least 95 % of its values within 0.05
of the other's) is left out and named in the collection's DUPLICATES file: the source ships
eight clips twice, under two tasks (three of the copies differ in one channel, a hand's
rotation, which moves no joint the project reads).

Run: python3 scripts/import_mocap.py [SOURCE] [DEST]   (defaults ../shared/mocap data/mocap)
"""

import gzip
import shutil
import sys
from pathlib import Path


def compact_number(text: str, decimals: int) -> str:
    v = round(float(text), decimals)
    if v == 0:
        return "0"
    s = f"{v:.{decimals}f}".rstrip("0").rstrip(".")
    return s


def compact_bvh(text: str) -> str:
    head, sep, motion = text.partition("MOTION")
    if not sep:
        raise SystemExit("not a BVH file: no MOTION section")
    lines = motion.strip("\n").split("\n")
    # "Frames: N" and "Frame Time: T" stay as they are.
    out = [lines[0], lines[1]]
    for line in lines[2:]:
        if line.strip():
            out.append(" ".join(compact_number(w, 2) for w in line.split()))
    return head + "MOTION\n" + "\n".join(out) + "\n"


def compact_table(text: str) -> str:
    out = []
    for line in text.splitlines():
        if line.strip():
            out.append(" ".join(w if w.lower() == "nan" else compact_number(w, 4) for w in line.split()))
    return "\n".join(out) + "\n"


def write_gz(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as f, gzip.GzipFile(fileobj=f, mode="wb", compresslevel=9, mtime=0, filename="") as g:
        g.write(text.encode())


def main() -> None:
    source = Path(sys.argv[1] if len(sys.argv) > 1 else "../shared/mocap")
    dest = Path(sys.argv[2] if len(sys.argv) > 2 else "data/mocap")
    for collection, pattern, compact in [
        ("hrc-task-clips", "*.bvh.gz", compact_bvh),
        ("human-assembly-data", "*.txt.gz", compact_table),
    ]:
        root = source / collection
        if not root.is_dir():
            raise SystemExit(f"{root}: no such folder")
        count = 0
        seen: dict[Path, list[float]] = {}
        duplicates = []
        for clip in sorted(root.rglob(pattern)):
            relative = clip.relative_to(root)
            text = compact(gzip.decompress(clip.read_bytes()).decode())
            values = [float(w) for w in (text.partition("Frame Time:")[2] or text).split()[1:]]
            twin = next((r for r, v in seen.items() if len(v) == len(values)
                         and sum(abs(a - b) > 0.05 for a, b in zip(v, values)) <= 0.05 * len(v)), None)
            if twin is not None:
                duplicates.append(f"{relative}: the motion of {twin}")
                continue
            seen[relative] = values
            write_gz(dest / collection / relative, text)
            count += 1
        if duplicates:
            (dest / collection / "DUPLICATES").write_text(
                "Clips of the source left out: their motion is another clip's.\n"
                + "".join(f"{d}\n" for d in duplicates))
            print(f"{collection}: {len(duplicates)} duplicates left out")
        for name in ["LICENSE", "SOURCE_COMMIT"]:
            shutil.copyfile(root / name, dest / collection / name)
        print(f"{collection}: {count} clips")


if __name__ == "__main__":
    main()
