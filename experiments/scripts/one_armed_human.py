#!/usr/bin/env python3
"""Writes the catalogue's `human` without its left arm: the one-armed body of the figures
measured before the left arm existed (the same as `RobotModel::one_armed_human()`), as a
URDF an evaluation file's `human_model` can name.

    experiments/scripts/one_armed_human.py OUT.urdf

An evaluation then plays it beside the two-armed default with
`--set human_model='"/abs/path/OUT.urdf"'`: the right arm, the trunk and the head as on
`human`, a recorded clip's other arm placed beside it as before 2026-12-08. Standard
library only.
"""

import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
HUMAN = os.path.join(HERE, "..", "..", "robots", "urdf", "human", "human.urdf")


def one_armed(text):
    """`text` (the catalogue's human.urdf) without the `left_*` links and joints."""
    kept, end = [], None
    for line in text.splitlines(keepends=True):
        trimmed = line.strip()
        if end is not None:
            if trimmed.startswith(end):
                end = None
            continue
        if trimmed.startswith('<link name="left_'):
            if not trimmed.endswith("/>"):
                end = "</link>"
            continue
        if trimmed.startswith('<joint name="left_'):
            end = "</joint>"
            continue
        kept.append(line)
    return "".join(kept)


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    with open(HUMAN) as f:
        text = one_armed(f.read())
    with open(sys.argv[1], "w") as f:
        f.write(text)


if __name__ == "__main__":
    main()
