#!/usr/bin/env python3
"""ProcNet speed, side by side: the Rust backends (flex, tch) and PyTorch, one run, same config.

    python3 bench/procnet_bench.py [--preset cpu] [--threads 2] [--iters 5] [--binary PATH]

Runs `workcell bench` (release build, with feature tch when it was built so) and
`bench/procnet.py bench` on the same weights (the preset's seeded initialisation), one after
the other on an otherwise idle machine, and prints a Markdown table with the ratios to PyTorch.
Workload: a training step is batch 4 x 10 frames, Dice + prediction-error loss, backward,
clipping, AdamW; inference is one frame, batch 1, with the recurrent state carried.
"""

import argparse
import json
import os
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
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--iters", type=int, default=5)
    ap.add_argument("--backends", default="flex,tch")
    ap.add_argument("--binary", default=os.path.join(HERE, "..", "target", "release", "workcell"))
    args = ap.parse_args()

    env = dict(os.environ, OMP_NUM_THREADS=str(args.threads), MKL_NUM_THREADS=str(args.threads))
    with tempfile.TemporaryDirectory() as tmp:
        weights = os.path.join(tmp, "bench.safetensors")
        common = ["--threads", str(args.threads), "--iters", str(args.iters)]
        rows = run_json_lines([args.binary, "bench", "--preset", args.preset, "--backends", "",
                               "--write-weights", weights], env)
        for b in args.backends.split(","):
            try:
                rows += run_json_lines([args.binary, "bench", "--weights", weights, "--backends", b] + common, env)
            except subprocess.CalledProcessError as e:
                print(f"backend {b}: {e.stderr.strip()}", file=sys.stderr)
        rows += run_json_lines([sys.executable, os.path.join(HERE, "procnet.py"), "bench", "--weights", weights]
                               + common, env)
    torch = next(r for r in rows if r["backend"].startswith("pytorch"))
    print(f"ProcNet `{args.preset}` preset, {args.threads} threads; training step: batch 4 x 10 frames; "
          "inference: 1 frame, batch 1\n")
    print("| backend | training step (s) | x PyTorch | inference per frame (ms) | x PyTorch | frames/s |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['backend']} | {r['train_step_s']:.3f} | {r['train_step_s'] / torch['train_step_s']:.2f} "
              f"| {1e3 * r['infer_frame_s']:.2f} | {r['infer_frame_s'] / torch['infer_frame_s']:.2f} "
              f"| {1 / r['infer_frame_s']:.0f} |")


if __name__ == "__main__":
    main()
