#!/usr/bin/env bash
# Prints the environment for the Ray sweep driver (scripts/sweep.py): the PyPI `ray` 2.60.0
# in a virtual environment under ~/.cache/workcell/ray-venv, installed the first time.
# Use: eval "$(scripts/ray-env.sh)"
set -euo pipefail
VENV="${WORKCELL_RAY_VENV:-$HOME/.cache/workcell/ray-venv}"
if ! "$VENV/bin/python" -c 'import ray; assert ray.__version__ == "2.60.0"' 2>/dev/null; then
    python3 -m venv "$VENV" >&2
    "$VENV/bin/pip" install -q "ray==2.60.0" >&2
fi
echo "export PATH=\"$VENV/bin:\$PATH\""
