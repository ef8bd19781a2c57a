#!/usr/bin/env python3
"""ProcNet speed, side by side: the Rust backends (flex, tch) and PyTorch, one run, same config.

    python3 bench/procnet_bench.py [--preset cpu] [--threads 2] [--iters 5] [--rounds 3] [--binary PATH]

Runs `workcell bench` (release build, with feature tch when it was built so) and
`bench/procnet.py bench` on the same weights (the preset's seeded initialisation), one after
the other on an otherwise idle machine, and prints a Markdown table with the ratios to PyTorch.
With several rounds (the backends take turns in each), the table gives each backend's median
and the range of the per-round ratios: on a shared machine one run of each can be off by 20 %.
Workload: a training step is batch 4 x 10 frames, Dice + prediction-error loss, backward,
clipping, AdamW; inference is one frame, batch 1, with the recurrent state carried.
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))


def run_json_lines(cmd, env=None):
    out = subprocess.run(cmd, check=True, capture_output=True, text=True, env=env).stdout
    return [json.loads(l) for l in out.splitlines() if l.startswith("{")]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--preset", default="cpu")
    ap.add_argument("--input-size", type=int, default=None, help="override the preset's input size")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--iters", type=int, default=5)
    ap.add_argument("--backends", default="flex,tch")
    ap.add_argument("--binary", default=os.path.join(HERE, "..", "target", "release", "workcell"))
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()

    env = dict(os.environ, OMP_NUM_THREADS=str(args.threads), MKL_NUM_THREADS=str(args.threads))
    rounds = []
    with tempfile.TemporaryDirectory() as tmp:
        weights = os.path.join(tmp, "bench.safetensors")
        common = ["--threads", str(args.threads), "--iters", str(args.iters)]
        size = ["--input-size", str(args.input_size)] if args.input_size else []
        run_json_lines([args.binary, "bench", "--preset", args.preset, "--backends", "",
                        "--write-weights", weights] + size, env)
        for _ in range(max(1, args.rounds)):
            rows = []
            for b in args.backends.split(","):
                try:
                    rows += run_json_lines([args.binary, "bench", "--weights", weights, "--backends", b] + common, env)
                except subprocess.CalledProcessError as e:
                    print(f"backend {b}: {e.stderr.strip()}", file=sys.stderr)
            rows += run_json_lines([sys.executable, os.path.join(HERE, "procnet.py"), "bench", "--weights", weights]
                                   + common, env)
            rounds.append({r["backend"]: r for r in rows})
    names = list(rounds[0])
    torch_name = next(n for n in names if n.startswith("pytorch"))
    median = lambda xs: statistics.median(xs)

    def column(name, key):
        return [r[name][key] for r in rounds if name in r]

    def ratios(name, key):
        return [r[name][key] / r[torch_name][key] for r in rounds if name in r]

    def cell_ratio(name, key):
        if name == torch_name:
            return "1.00"
        rs = ratios(name, key)
        text = f"{median(column(name, key)) / median(column(torch_name, key)):.2f}"
        return text if len(rs) == 1 else f"{text} ({min(rs):.2f}-{max(rs):.2f})"

    print(f"ProcNet `{args.preset}` preset, {args.threads} threads; training step: batch 4 x 10 frames; "
          f"inference: 1 frame, batch 1; median of {len(rounds)} rounds (range of the per-round ratios)\n")
    print("| backend | training step (s) | x PyTorch | inference per frame (ms) | x PyTorch | frames/s |")
    print("|---|---|---|---|---|---|")
    for n in names:
        step, frame = median(column(n, "train_step_s")), median(column(n, "infer_frame_s"))
        print(f"| {n} | {step:.3f} | {cell_ratio(n, 'train_step_s')} "
              f"| {1e3 * frame:.2f} | {cell_ratio(n, 'infer_frame_s')} | {1 / frame:.0f} |")

if __name__ == "__main__":
    main()
