"""Prints the campaign table of docs/reliability.md from AFL++ output folders.

Usage: python3 fuzz/table.py TARGET=OUT_DIR [TARGET=OUT_DIR ...]

Each OUT_DIR is an afl-fuzz output folder (its `default/fuzzer_stats` and `plot_data`). The
edge coverage at three quarters of the run against its end says whether the run had reached
a plateau: a run still finding new edges in its last quarter had not.
"""

import os
import sys


def stats(folder):
    values = {}
    with open(os.path.join(folder, "default", "fuzzer_stats")) as f:
        for line in f:
            key, _, value = line.partition(":")
            values[key.strip()] = value.strip()
    return values


def edges(folder):
    """(relative time s, edges found) of every plot_data line."""
    path = os.path.join(folder, "default", "plot_data")
    with open(path) as f:
        header = [h.strip() for h in f.readline().lstrip("# ").split(",")]
        t, e = header.index("relative_time"), header.index("edges_found")
        rows = [line.split(",") for line in f if line.strip()]
    return [(int(r[t]), int(r[e])) for r in rows]


def main(pairs):
    print(
        "| target | run s | executions | exec/s | corpus kept | edges | edges gained in the "
        "last quarter | crashes | hangs |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    here = os.path.dirname(os.path.abspath(__file__))
    for pair in pairs:
        target, _, folder = pair.partition("=")
        s = stats(folder)
        series = edges(folder)
        end = series[-1][0] if series else 0
        at = [e for t, e in series if t <= 0.75 * end]
        quarter = at[-1] if at else 0
        final = series[-1][1] if series else 0
        gained = 100.0 * (final - quarter) / max(final, 1)
        kept = len(os.listdir(os.path.join(here, "corpus", target)))
        run = int(s["last_update"]) - int(s["start_time"])
        print(
            f"| {target} | {run} | {int(s['execs_done']):,} | {float(s['execs_per_sec']):,.0f} | "
            f"{kept:,} | {final:,} | {gained:.1f}% | {s['saved_crashes']} | {s['saved_hangs']} |"
        )


if __name__ == "__main__":
    main(sys.argv[1:])
