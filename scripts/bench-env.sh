#!/usr/bin/env bash
# A Python environment with the peers of the safety benchmark (bench/safety_peers.py):
# Coal 3.0.3 (distances) and OSQP 1.1.3 (QP), from PyPI, cached outside the repository.
# Prints the path of its python.
set -euo pipefail
VENV="${WORKCELL_BENCH_VENV:-$HOME/.cache/workcell/bench-venv}"
if ! "$VENV/bin/python" -c 'import coal, osqp, scipy' >/dev/null 2>&1; then
    python3 -m venv "$VENV" >&2
    "$VENV/bin/pip" install -q coal==3.0.3 osqp==1.1.3 numpy scipy >&2
fi
echo "$VENV/bin/python"
