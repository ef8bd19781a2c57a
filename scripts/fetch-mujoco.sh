#!/usr/bin/env bash
# Takes the MuJoCo library (libmujoco.so.3.17.0, which needs only libc and libm) and its
# headers out of the PyPI wheel mujoco==3.17.0 and puts them in .mujoco/ at the repository
# root, where `.cargo/config.toml` points mujoco-rs (feature `mujoco`). The wheel is cached
# under ~/.cache/workcell/wheels; nothing is installed system-wide. Prints the library folder.
set -euo pipefail
cd "$(dirname "$0")/.."
version="3.17.0"
cache="${WORKCELL_CACHE:-$HOME/.cache/workcell}"
dest=".mujoco"
lib="$dest/lib/libmujoco.so.$version"
if [ ! -f "$lib" ]; then
  mkdir -p "$cache/wheels"
  wheel=$(ls "$cache"/wheels/mujoco-"$version"-cp311-*manylinux*x86_64.whl 2>/dev/null | head -n 1 || true)
  if [ -z "$wheel" ]; then
    python3 -m pip download --quiet --no-deps --only-binary=:all: \
      --platform manylinux_2_28_x86_64 --python-version 3.11 --implementation cp \
      -d "$cache/wheels" "mujoco==$version" >&2
    wheel=$(ls "$cache"/wheels/mujoco-"$version"-cp311-*manylinux*x86_64.whl | head -n 1)
  fi
  rm -rf "$dest.partial"
  python3 - "$wheel" "$dest.partial" "$version" <<'PY'
import os, shutil, sys, zipfile
wheel, out, version = sys.argv[1:]
with zipfile.ZipFile(wheel) as z:
    names = z.namelist()
    so = f"mujoco/libmujoco.so.{version}"
    if so not in names:
        sys.exit(f"{wheel} holds no {so}: is it the mujoco {version} wheel?")
    os.makedirs(f"{out}/lib")
    with z.open(so) as src, open(f"{out}/lib/libmujoco.so.{version}", "wb") as dst:
        shutil.copyfileobj(src, dst)
    for name in names:
        if name.startswith("mujoco/include/mujoco/") and not name.endswith("/"):
            target = os.path.join(out, "include", os.path.relpath(name, "mujoco/include"))
            os.makedirs(os.path.dirname(target), exist_ok=True)
            with z.open(name) as src, open(target, "wb") as dst:
                shutil.copyfileobj(src, dst)
PY
  # mujoco-rs links against a file named exactly libmujoco.so.
  ln -s "libmujoco.so.$version" "$dest.partial/lib/libmujoco.so"
  rm -rf "$dest"
  mv "$dest.partial" "$dest"
fi
echo "$PWD/$dest/lib"
