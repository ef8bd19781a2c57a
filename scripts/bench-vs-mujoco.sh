#!/usr/bin/env bash
# Steps/s of workcell (rapier3d) and MuJoCo side by side: each catalogue arm alone, holding a
# configuration under gravity at 1 ms. Installs mujoco==3.17.0 into a virtualenv under
# ~/.cache/workcell (outside the repository) on first use. Prints a table with the ratio.
set -euo pipefail
cd "$(dirname "$0")/.."
venv="${WORKCELL_CACHE:-$HOME/.cache/workcell}/mujoco-venv"
if [ ! -x "$venv/bin/python" ]; then
  python3 -m venv "$venv"
  "$venv/bin/pip" install --quiet mujoco==3.17.0
fi
cargo bench -p workcell-sim --bench step -- alone_hold >/dev/null
mujoco_out=$("$venv/bin/python" scripts/bench_mujoco_peer.py)
python3 - "$mujoco_out" <<'PY'
import json, sys
mujoco = {line.split()[0]: float(line.split()[1]) for line in sys.argv[1].splitlines()}
print(f"{'robot (alone, hold, 1 ms)':<28} {'workcell steps/s':>17} {'MuJoCo steps/s':>15} {'MuJoCo / workcell':>18}")
for robot, mj in mujoco.items():
    with open(f"target/criterion/{robot}_alone_hold/1000 steps/new/estimates.json") as f:
        ns_per_1000 = json.load(f)["mean"]["point_estimate"]
    ours = 1000 / (ns_per_1000 * 1e-9)
    print(f"{robot:<28} {ours:>17.0f} {mj:>15.0f} {mj / ours:>18.1f}")
PY
