#!/usr/bin/env python3
"""Run a sweep of closed-loop safety evaluations as Ray tasks.

A sweep file (TOML) names an evaluation file, how many episodes each point runs and from
which seed, how many shards each point is cut into, and a grid of values:

    evaluation = "evaluate.toml"        # relative to the sweep file
    episodes = 100
    seed = 1
    shards = 4
    gltf = 0                            # 3D replays of each point's worst episodes
    [grid]
    filter = ["qp", "ssm"]              # --filter
    perception = ["noisy"]              # --perception
    "safety.d_min_m" = [0.10, 0.15]     # any other key: --set KEY=VALUE

Every combination of the grid's values is a point. Each shard of each point is one Ray task
that runs `workcell evaluate --shard K/N` (the work stays in the Rust binary) and returns its
run record; the driver merges each point's shards (`workcell report merge`) and tabulates the
sweep (`workcell report sweep`). Output, under --out:

    shards/point-NN/shard-K/   run records (a rerun skips the shards already there, unless
                               the plan or what it reads changed: the evaluation file, its
                               cell file, the shipped weights, the workcell binary)
    points/point-NN/           each point's merged report (summary.md, plots, violations)
    sweep.md, sweep.csv, sweep.png   violations and task time per point
    plan.json                  the points and their flags
    timing.json                wall times: the sweep, every shard, Ray's overhead per shard

Local: `python scripts/sweep.py configs/sweep.toml --out out/sweep` starts Ray on this
machine's CPUs. A cluster: `--address auto` on a node of it (or `ray://HEAD:10001`); every
node needs the workcell binary and the evaluation's files at the same paths as here (a
shared filesystem, or the same checkout and `cargo build --release` on each node).
`--check` also runs every point in one process and requires the merged report to equal it.
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import itertools
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
# The record and replay files a shard returns to the driver.
KEEP_SUFFIXES = (".json", ".glb")


def toml_value(value) -> str:
    """A grid value as the TOML text `--set KEY=VALUE` takes."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    raise SystemExit(f"sweep: grid value {value!r} is not a TOML number, string, bool or list")


def plan(sweep_path: Path) -> dict:
    """The sweep file as a list of points with their command-line flags."""
    try:
        sweep = tomllib.loads(sweep_path.read_text())
    except (OSError, tomllib.TOMLDecodeError) as e:
        raise SystemExit(f"{sweep_path}: {e}")
    known = {"evaluation", "episodes", "seed", "shards", "gltf", "grid"}
    unknown = sorted(set(sweep) - known)
    if unknown:
        raise SystemExit(f"{sweep_path}: unknown keys {unknown} (known: {sorted(known)})")
    if "evaluation" not in sweep:
        raise SystemExit(f"{sweep_path}: `evaluation` (the evaluation file) is required")
    evaluation = (sweep_path.parent / sweep["evaluation"]).resolve()
    if not evaluation.is_file():
        raise SystemExit(f"{sweep_path}: evaluation {evaluation} is not a file")
    episodes = sweep.get("episodes", 10)
    shards = sweep.get("shards", 1)
    seed = sweep.get("seed", 1)
    gltf = sweep.get("gltf", 0)
    for key, v, lo in [("episodes", episodes, 1), ("shards", shards, 1), ("seed", seed, 0), ("gltf", gltf, 0)]:
        if not isinstance(v, int) or isinstance(v, bool) or v < lo:
            raise SystemExit(f"{sweep_path}: {key} must be an integer >= {lo}, got {v!r}")
    if shards > episodes:
        raise SystemExit(f"{sweep_path}: {shards} shards of {episodes} episodes leave some shard without one")
    grid = sweep.get("grid", {})
    for key, values in grid.items():
        if not isinstance(values, list) or not values:
            raise SystemExit(f"{sweep_path}: grid.{key} must be a non-empty list of values")
    points = []
    for i, combo in enumerate(itertools.product(*grid.values()), start=1):
        flags = []
        for key, value in zip(grid.keys(), combo):
            if key in ("filter", "perception"):
                flags += [f"--{key}", str(value)]
            else:
                flags += ["--set", f"{key}={toml_value(value)}"]
        points.append({"name": f"point-{i:02d}", "values": dict(zip(grid.keys(), combo)), "flags": flags})
    return {
        "evaluation": str(evaluation),
        "inputs": inputs(evaluation),
        "episodes": episodes,
        "seed": seed,
        "shards": shards,
        "gltf": gltf,
        "points": points,
    }


def sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def inputs(evaluation: Path) -> dict:
    """The SHA-256 of the files a point's results depend on besides its flags: the evaluation
    file, the cell file it names, and the shipped weights (read when the evaluation names
    none). A shard run with other contents is another experiment, not one to resume."""
    files = [evaluation]
    try:
        cell = tomllib.loads(evaluation.read_text()).get("cell")
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        cell = None  # workcell itself refuses the file with the reason
    if isinstance(cell, str) and (evaluation.parent / cell).is_file():
        files.append((evaluation.parent / cell).resolve())
    weights = REPO / "procnet" / "weights"
    if weights.is_dir():
        files += sorted(f for f in weights.iterdir() if f.is_file())
    return {str(f): sha256(f) for f in files}


def evaluate_args(p: dict, point: dict, shard: int | None) -> list[str]:
    args = ["evaluate", p["evaluation"], "--episodes", str(p["episodes"]), "--seed", str(p["seed"])]
    args += point["flags"]
    if p["gltf"]:
        args += ["--gltf", str(p["gltf"])]
    if shard is not None:
        args += ["--shard", f"{shard}/{p['shards']}"]
    return args


def run_workcell(binary: str, args: list[str], threads: int | None, keep_all: bool = False) -> dict:
    """Runs one evaluation into a fresh folder; returns its exit status, the tail of its
    error output, the record and replay files (every file with `keep_all`), the folder it
    ran in, and the seconds it took."""
    env = dict(os.environ)
    if threads is not None:
        # One Ray CPU, one thread: N shards on N CPUs, not N x N threads.
        env["RAYON_NUM_THREADS"] = str(threads)
    entered = time.time()
    with tempfile.TemporaryDirectory(prefix="workcell-shard-") as tmp:
        out = Path(tmp) / "out"
        started = time.perf_counter()
        proc = subprocess.run(
            [binary, *args, "--out", str(out)], capture_output=True, text=True, env=env, cwd=REPO
        )
        seconds = time.perf_counter() - started
        files = {}
        if proc.returncode == 0:
            for f in sorted(out.rglob("*")):
                if f.is_file() and (keep_all or f.suffix in KEEP_SUFFIXES):
                    files[str(f.relative_to(out))] = f.read_bytes()
        return {"rc": proc.returncode, "stderr": proc.stderr[-4000:], "files": files, "seconds": seconds,
                "out": str(out), "entered": entered, "left": time.time()}


def write_files(folder: Path, files: dict) -> None:
    staging = folder.with_name(folder.name + ".partial")
    shutil.rmtree(staging, ignore_errors=True)
    staging.mkdir(parents=True)
    for name, data in files.items():
        (staging / name).parent.mkdir(parents=True, exist_ok=True)
        (staging / name).write_bytes(data)
    shutil.rmtree(folder, ignore_errors=True)
    staging.rename(folder)


def workcell(binary: str, *args: str) -> None:
    proc = subprocess.run([binary, *args], cwd=REPO, capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"workcell {' '.join(args)} failed:\n{proc.stderr}")


def same_report(single: Path, single_out: str, merged: Path) -> list[str]:
    """The files in which a merged report differs from the one-process report written into
    `single_out` and copied to `single` (the timing columns, the command line, and the
    folder named in replay commands aside)."""
    differ = []

    def rows(folder: Path) -> list[list[str]]:
        table = list(csv.reader((folder / "metrics.csv").read_text().splitlines()))
        timing = {i for i, name in enumerate(table[0] if table else []) if name in ("wall_s", "setup_s")}
        return [[cell for i, cell in enumerate(row) if i not in timing] for row in table]

    if rows(single) != rows(merged):
        differ.append("metrics.csv")
    for name in ["evaluation.toml", "separation.svg", "speed_scaling.svg", "perception_error.svg"]:
        if (single / name).read_bytes() != (merged / name).read_bytes():
            differ.append(name)
    if (single / "violations.txt").read_text().replace(single_out, str(merged)) != (
        merged / "violations.txt"
    ).read_text():
        differ.append("violations.txt")

    def verdict(folder: Path) -> list[str]:
        lines = (folder / "summary.md").read_text().splitlines()
        start = next(i for i, line in enumerate(lines) if line.startswith("## Verdict"))
        return lines[start : start + 5]

    if verdict(single) != verdict(merged):
        differ.append("summary.md (verdict)")
    for f in single.glob("replays/*.glb"):
        other = merged / "replays" / f.name
        if not other.is_file() or f.read_bytes() != other.read_bytes():
            differ.append(f"replays/{f.name}")
    return differ


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("sweep", type=Path, help="the sweep file (TOML)")
    parser.add_argument("--out", type=Path, default=Path("out/sweep"), help="output folder")
    parser.add_argument("--address", default=None, help="Ray cluster address (default: start Ray locally)")
    parser.add_argument("--num-cpus", type=int, default=None, help="CPUs of a local Ray (default: all)")
    parser.add_argument(
        "--workcell",
        default=os.environ.get("WORKCELL_BIN", str(REPO / "target/release/workcell")),
        help="the workcell binary (default: $WORKCELL_BIN or target/release/workcell)",
    )
    parser.add_argument("--force", action="store_true", help="start over when the plan changed")
    parser.add_argument("--check", action="store_true", help="also run every point in one process and compare")
    args = parser.parse_args()

    binary = str(Path(args.workcell).resolve())
    if not os.access(binary, os.X_OK):
        raise SystemExit(f"{binary}: no workcell binary there (cargo build --release, or --workcell PATH)")
    p = plan(args.sweep)
    p["workcell"] = {binary: sha256(Path(binary))}
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    plan_file = out / "plan.json"
    if plan_file.exists() and json.loads(plan_file.read_text()) != p:
        if not args.force:
            raise SystemExit(f"{plan_file}: a different sweep is in {out}; pass --force to start over")
        shutil.rmtree(out / "shards", ignore_errors=True)
    plan_file.write_text(json.dumps(p, indent=2) + "\n")

    import ray  # the `ray` package from PyPI: scripts/ray-env.sh

    started = time.perf_counter()
    ray.init(address=args.address, num_cpus=args.num_cpus if args.address is None else None,
             include_dashboard=False, log_to_driver=False)
    ray_started = time.perf_counter() - started
    remote = ray.remote(num_cpus=1)(run_workcell)

    pending = {}
    skipped = 0
    for point in p["points"]:
        for k in range(1, p["shards"] + 1):
            folder = out / "shards" / point["name"] / f"shard-{k}"
            if (folder / "run.json").is_file():
                skipped += 1
                continue
            ref = remote.remote(binary, evaluate_args(p, point, k), 1)
            pending[ref] = (point["name"], k, folder, time.time(), len(pending))
    total = len(pending) + skipped
    cpus = int(ray.cluster_resources().get("CPU", 0))
    print(f"sweep: {len(p['points'])} points x {p['shards']} shards of {p['episodes']} episodes "
          f"({total} Ray tasks, {skipped} already done) on {cpus} CPUs", flush=True)
    timings = []
    done = skipped
    while pending:
        ready, _ = ray.wait(list(pending), num_returns=1)
        for ref in ready:
            name, k, folder, submitted, order = pending.pop(ref)
            result = ray.get(ref)
            received = time.time()
            if result["rc"] != 0:
                ray.shutdown()
                raise SystemExit(f"{name} shard {k}/{p['shards']} failed (status {result['rc']}):\n{result['stderr']}")
            write_files(folder, result["files"])
            done += 1
            timings.append({
                "point": name,
                "shard": k,
                "process_s": result["seconds"],
                # Ray's share of a shard: from submission to the task's start (only for the
                # tasks that found a CPU free, the first `cpus`; the others queued), and from
                # the task's end to the driver holding its result.
                "start_latency_s": result["entered"] - submitted if order < cpus else None,
                "return_latency_s": received - result["left"],
                "task_s": result["left"] - result["entered"],
            })
            print(f"[{done}/{total}] {name} shard {k}/{p['shards']}: {result['seconds']:.1f} s", flush=True)

    check_results = {}
    if args.check:
        # The same points in one process each, as Ray tasks too (one CPU each, one thread).
        refs = {remote.remote(binary, evaluate_args(p, point, None), 1, True): point["name"] for point in p["points"]}
        for ref, name in refs.items():
            result = ray.get(ref)
            if result["rc"] != 0:
                raise SystemExit(f"{name} in one process failed:\n{result['stderr']}")
            check_results[name] = result
    ray.shutdown()
    sweep_s = time.perf_counter() - started

    points_dir = out / "points"
    for point in p["points"]:
        shards = sorted((out / "shards" / point["name"]).glob("shard-*"))
        workcell(binary, "report", "merge", *map(str, shards), "--out", str(points_dir / point["name"]), "--force")
    workcell(binary, "report", "sweep", *[str(points_dir / q["name"]) for q in p["points"]],
             "--out", str(out), "--force")
    print((out / "sweep.md").read_text())

    def mean(values):
        values = [v for v in values if v is not None]
        return sum(values) / len(values) if values else None

    timing = {
        "sweep_s": sweep_s,
        "ray_init_s": ray_started,
        "cpus": cpus,
        "shards_run": len(timings),
        "process_s_total": sum(t["process_s"] for t in timings),
        "start_latency_s": mean(t["start_latency_s"] for t in timings),
        "return_latency_s": mean(t["return_latency_s"] for t in timings),
        # Inside the task but outside the workcell process: the temporary folder, reading the
        # files back.
        "in_task_s": mean(t["task_s"] - t["process_s"] for t in timings),
        "shards": timings,
    }
    (out / "timing.json").write_text(json.dumps(timing, indent=2) + "\n")
    if timings:
        overhead = sum(timing[k] or 0.0 for k in ("start_latency_s", "return_latency_s", "in_task_s"))
        print(f"sweep: {sweep_s:.1f} s wall (Ray start {ray_started:.1f} s), {timing['process_s_total']:.1f} s "
              f"in workcell processes on {cpus} CPUs; Ray's overhead per shard {overhead * 1e3:.0f} ms "
              f"(start {(timing['start_latency_s'] or 0) * 1e3:.0f}, return {timing['return_latency_s'] * 1e3:.0f}, "
              f"in the task {timing['in_task_s'] * 1e3:.0f})")

    failed = False
    for name, result in check_results.items():
        single = out / "check" / name
        write_files(single, result["files"])
        differ = same_report(single, result["out"], points_dir / name)
        if differ:
            failed = True
            print(f"check: {name}: the merged report differs from one process in {', '.join(differ)}")
        else:
            print(f"check: {name}: the merged report of {p['shards']} shards equals one process's")
    print(f"sweep table: {out / 'sweep.md'}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
