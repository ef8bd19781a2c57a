#!/usr/bin/env bash
# Downloads the example-robot-data wheel from PyPI (vendor URDFs with package:// meshes, DAE
# and STL) into a cache outside the repository and unpacks it. The vendor URDF tests find it
# there, or wherever WORKCELL_EXAMPLE_ROBOT_DATA points. Prints the data folder.
set -euo pipefail
version="${EXAMPLE_ROBOT_DATA_VERSION:-6.0.0}"
cache="${WORKCELL_CACHE:-$HOME/.cache/workcell}"
dest="$cache/example-robot-data-$version"
data="$dest/cmeel.prefix/share/example-robot-data"
if [ ! -d "$data" ]; then
  mkdir -p "$cache/wheels"
  python3 -m pip download --quiet --no-deps --only-binary=:all: -d "$cache/wheels" \
    "example-robot-data==$version" >&2
  wheel=$(ls "$cache"/wheels/example_robot_data-"$version"-*.whl | head -n 1)
  rm -rf "$dest.partial"
  python3 -c 'import sys, zipfile; zipfile.ZipFile(sys.argv[1]).extractall(sys.argv[2])' "$wheel" "$dest.partial"
  mv "$dest.partial" "$dest"
fi
echo "$data"
