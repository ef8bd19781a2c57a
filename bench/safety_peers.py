#!/usr/bin/env python3
"""The safety layer side by side with Coal (distances) and OSQP (the QP), on the same queries.

Runs the Rust benchmark (`safety_bench` example), which times our code and writes the
problems it timed; then times Coal on the same capsule pairs and OSQP on the same QPs, and
prints one table with the ratios.

    scripts/bench-env.sh                  # once: a venv with coal 3.0.3, osqp 1.1.3, numpy, scipy
    ~/.cache/workcell/bench-venv/bin/python bench/safety_peers.py [--cases 200]

Coal and OSQP are called through their Python bindings, as PyPI ships them. For Coal the
time per pair therefore includes the Python call (about a microsecond); the table also gives
Coal's own timing where the library reports one. OSQP reports its own solve time
(`info.solve_time`, C code only), which is the number compared.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np


def run_rust(cases: int, out: str) -> dict:
    cmd = ["cargo", "run", "--release", "--quiet", "-p", "workcell-safety", "--example", "safety_bench", "--",
           "--cases", str(cases), "--out", out]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    with open(out) as f:
        return json.load(f)


def capsule_frame(a, b):
    """Coal capsules run along their local z, centred: rotation and centre of segment a-b."""
    a, b = np.asarray(a), np.asarray(b)
    axis = b - a
    length = float(np.linalg.norm(axis))
    z = axis / length if length > 1e-12 else np.array([0.0, 0.0, 1.0])
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.column_stack([x, y, z]), (a + b) / 2.0, length


def bench_coal(pairs: list) -> dict:
    import coal

    objects = []
    for p in pairs:
        ra, ta, la = capsule_frame(p[0:3], p[3:6])
        rb, tb, lb = capsule_frame(p[7:10], p[10:13])
        objects.append((coal.Capsule(p[6], la), coal.Transform3s(ra, ta), coal.Capsule(p[13], lb),
                        coal.Transform3s(rb, tb), p[14]))
    request = coal.DistanceRequest()
    result = coal.DistanceResult()
    worst = 0.0
    for ca, ta, cb, tb, ours in objects:
        result.clear()
        d = coal.distance(ca, ta, cb, tb, request, result)
        worst = max(worst, abs(d - ours))
    repeats = 20
    start = time.perf_counter()
    for _ in range(repeats):
        for ca, ta, cb, tb, _ in objects:
            coal.distance(ca, ta, cb, tb, request, result)
    per_pair_us = (time.perf_counter() - start) / (repeats * len(objects)) * 1e6
    # The Python call alone: a no-op binding call of the same shape (result.clear()).
    start = time.perf_counter()
    for _ in range(repeats):
        for _ in objects:
            result.clear()
    call_us = (time.perf_counter() - start) / (repeats * len(objects)) * 1e6
    return {"per_pair_us": per_pair_us, "python_call_us": call_us, "max_difference_m": worst}


def bench_osqp(qps: list, eps: float) -> dict:
    import osqp
    from scipy import sparse

    def matrices(p):
        # Our QP carries one slack variable (last column, last row -s <= 0) with an exact
        # penalty; at these problems it is 0, and OSQP's ADMM converges badly with the
        # penalty's scale, so OSQP gets the equivalent hard problem without it.
        n = len(p["q"]) - 1
        P = sparse.diags(p["P_diag"][:n]).tocsc()
        A = sparse.csc_matrix((p["A_values"], p["A_rowval"], p["A_colptr"]), shape=(p["m"], n + 1))
        A = A[: p["m"] - 1, :n].tocsc()
        return P, np.array(p["q"][:n]), A, np.array(p["b"][: p["m"] - 1])

    qps = [p for p in qps if p["slack"] == 0.0]

    P, q, A, b = matrices(qps[0])
    solver = osqp.OSQP()
    solver.setup(P=P, q=q, A=A, l=np.full(len(b), -np.inf), u=b, verbose=False, eps_abs=eps, eps_rel=eps,
                 warm_starting=True, polishing=False)
    solve_us, wall_us, worst, failed = [], [], 0.0, 0
    for p in qps:
        _, q, A, b = matrices(p)
        start = time.perf_counter()
        solver.update(q=q, u=b, Ax=A.data)
        result = solver.solve()
        wall_us.append((time.perf_counter() - start) * 1e6)
        if result.info.status_val not in (1, 2):  # solved, solved inaccurate
            failed += 1
            continue
        solve_us.append(result.info.solve_time * 1e6)
        n = len(p["x"])
        worst = max(worst, float(np.max(np.abs(result.x[:n] - np.array(p["x"])))))
    ours = [p["t_us"] for p in qps]
    return {"problems": len(qps), "ours_us": float(np.median(ours)), "ours_p90_us": float(np.percentile(ours, 90)),
            "solve_us": float(np.median(solve_us)), "solve_p90_us": float(np.percentile(solve_us, 90)),
            "wall_us": float(np.median(wall_us)), "max_difference": worst, "failed": failed}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=200)
    parser.add_argument("--problems", help="use this JSON from safety_bench instead of running it")
    args = parser.parse_args()
    if args.problems:
        with open(args.problems) as f:
            data = json.load(f)
    else:
        path = os.path.join(tempfile.mkdtemp(), "safety_problems.json")
        data = run_rust(args.cases, path)
    s = data["summary"]
    coal_result = bench_coal(data["capsule_pairs"])
    osqp_default = bench_osqp(data["qps"], 1e-3)
    osqp_tight = bench_osqp(data["qps"], 1e-6)
    pairs = s["capsule_pairs_per_case"]
    ours_pair_us = s["distance_us"]["median"] / pairs
    print(f"{s['cases']} problems: iiwa 14 at random configurations, human arm around the wrist; "
          f"{pairs} capsule pairs per query, {s['mean_active_rows']:.1f} active QP rows on average\n")
    print("| what | workcell (Rust) | peer | peer / workcell |")
    print("|---|---|---|---|")
    print(f"| capsule pair distance | {ours_pair_us * 1e3:.0f} ns | Coal 3.0.3: {coal_result['per_pair_us'] * 1e3:.0f} ns "
          f"(of it Python call ~{coal_result['python_call_us'] * 1e3:.0f} ns) | "
          f"{coal_result['per_pair_us'] / ours_pair_us:.1f}x |")
    print(f"| all {pairs} pairs (7-link arm + base, 3 parts) | {s['distance_us']['median']:.2f} us | "
          f"Coal: {coal_result['per_pair_us'] * pairs:.2f} us | {coal_result['per_pair_us'] * pairs / s['distance_us']['median']:.1f}x |")
    print(f"| QP solve, all problems (median / p90) | {s['qp_us']['median']:.0f} / {s['qp_us']['p90']:.0f} us (clarabel) | - | - |")
    o = osqp_default
    print(f"| QP solve, the {o['problems']} without slack (median / p90) | {o['ours_us']:.0f} / {o['ours_p90_us']:.0f} us | "
          f"OSQP 1.1.3 eps 1e-3: {o['solve_us']:.0f} / {o['solve_p90_us']:.0f} us | "
          f"{o['solve_us'] / o['ours_us']:.2f}x / {o['solve_p90_us'] / o['ours_p90_us']:.2f}x |")
    o = osqp_tight
    print(f"| same, OSQP tight | same | OSQP eps 1e-6: {o['solve_us']:.0f} / {o['solve_p90_us']:.0f} us | "
          f"{o['solve_us'] / o['ours_us']:.2f}x / {o['solve_p90_us'] / o['ours_p90_us']:.2f}x |")
    print(f"| distances + Jacobian rows | {s['distance_jacobian_us']['median']:.2f} us | - | - |")
    print(f"| full control tick (median / p90) | {s['tick_us']['median']:.0f} / {s['tick_us']['p90']:.0f} us | - | - |")
    ahead = s['tick_anticipating_0.15_s_us']
    print(f"| same, anticipating 0.15 s (median / p90) | {ahead['median']:.0f} / {ahead['p90']:.0f} us | - | - |")
    print()
    print(f"Agreement: Coal distances within {coal_result['max_difference_m']:.1e} m of ours; OSQP commands within "
          f"{osqp_default['max_difference']:.1e} rad/s (eps 1e-3) and {osqp_tight['max_difference']:.1e} rad/s "
          f"(eps 1e-6) of clarabel's, on the {osqp_default['problems']} problems that need no slack; OSQP failures: "
          f"{osqp_default['failed']} / {osqp_tight['failed']}. Coal goes through its Python bindings; in C++ it was "
          f"measured near 60 ns per capsule pair (SAFETY.md).")
    return 0


if __name__ == "__main__":
    sys.exit(main())
