#!/usr/bin/env bash
# Prints the environment for the `tch` feature (LibTorch from the PyPI torch 2.9.0 wheel that
# burn-tch 0.22 expects), installing the wheel into a virtual environment under
# ~/.cache/workcell/torch-venv the first time. Use: eval "$(scripts/torch-env.sh)"
set -euo pipefail
VENV="${WORKCELL_TORCH_VENV:-$HOME/.cache/workcell/torch-venv}"
if ! "$VENV/bin/python" -c 'import torch, safetensors; assert torch.__version__.startswith("2.9.0")' 2>/dev/null; then
    python3 -m venv "$VENV" >&2
    "$VENV/bin/pip" install -q torch==2.9.0 safetensors >&2
fi
LIB="$("$VENV/bin/python" -c 'import torch, os; print(os.path.join(os.path.dirname(torch.__file__), "lib"))')"
echo "export PATH=\"$VENV/bin:\$PATH\""
echo "export LIBTORCH_USE_PYTORCH=1"
echo "export LD_LIBRARY_PATH=\"$LIB:\${LD_LIBRARY_PATH:-}\""
