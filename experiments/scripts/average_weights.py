#!/usr/bin/env python3
"""Averages ProcNet weight files of one model configuration, tensor by tensor.

Networks fine-tuned from the same weights stay close to one another, and the mean of their
weights is again a network of the same size and speed (one file, one pass per frame), often
better than each (weight averaging: stochastic weight averaging, 2018; "model soups", 2022).
experiments/perception.md ("A fourth cycle, and means of the cycles' weights") measures it on
ProcNet.

    experiments/scripts/average_weights.py A.safetensors B.safetensors [...] --out MEAN.safetensors

Every file must be a `workcell-procnet/1` safetensors file with the same configuration in its
metadata and the same tensors (names, shapes, float32). The output keeps the first file's
metadata and records its sources under `averaged_from`. Standard library only.
"""

import argparse
import array
import json
import os
import struct
import sys

FORMAT = "workcell-procnet/1"


def fail(message):
    sys.exit(f"average_weights: {message}")


def read(path):
    """(metadata, {name: (shape, array of float32)}) of a safetensors file."""
    try:
        with open(path, "rb") as f:
            blob = f.read()
    except OSError as e:
        fail(f"{path}: cannot read: {e}")
    if len(blob) < 8:
        fail(f"{path}: not a safetensors file (shorter than its header length)")
    (n,) = struct.unpack("<Q", blob[:8])
    if 8 + n > len(blob):
        fail(f"{path}: a header of {n} bytes in a file of {len(blob)}")
    try:
        header = json.loads(blob[8 : 8 + n])
    except ValueError as e:
        fail(f"{path}: the header is not JSON: {e}")
    if not isinstance(header, dict):
        fail(f"{path}: the header is not a JSON object")
    meta = header.pop("__metadata__", {}) or {}
    if not isinstance(meta, dict):
        fail(f"{path}: the metadata is not a JSON object")
    if meta.get("format") != FORMAT:
        fail(f"{path}: format {meta.get('format')!r}, not {FORMAT!r}")
    data = blob[8 + n :]
    tensors = {}
    for name, t in header.items():
        if not isinstance(t, dict):
            fail(f"{path}: tensor {name} has no description")
        if t.get("dtype") != "F32":
            fail(f"{path}: tensor {name} is {t.get('dtype')}, not F32")
        offsets, shape = t.get("data_offsets"), t.get("shape")
        whole = lambda xs, k=None: (
            isinstance(xs, list)
            and (k is None or len(xs) == k)
            and all(isinstance(x, int) and x >= 0 for x in xs)
        )
        if not whole(offsets, 2) or not whole(shape):
            fail(f"{path}: tensor {name} has no shape or byte range")
        start, end = offsets
        count = 1
        for d in shape:
            count *= d
        if end - start != 4 * count or end > len(data):
            fail(f"{path}: tensor {name}'s bytes do not match its shape {t['shape']}")
        values = array.array("f")
        values.frombytes(data[start:end])
        if sys.byteorder != "little":
            values.byteswap()
        tensors[name] = (t["shape"], values)
    return meta, tensors


def configuration(path, meta):
    """The model configuration a file's metadata records."""
    try:
        return json.loads(meta["config"])
    except (KeyError, TypeError, ValueError):
        fail(f"{path}: no model configuration in the metadata")


def write(path, meta, tensors):
    header = {"__metadata__": meta}
    offset = 0
    for name in sorted(tensors):
        shape, values = tensors[name]
        header[name] = {
            "dtype": "F32",
            "shape": shape,
            "data_offsets": [offset, offset + 4 * len(values)],
        }
        offset += 4 * len(values)
    text = json.dumps(header, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 8)  # the data section starts 8-byte aligned
    tmp = f"{path}.tmp"
    with open(tmp, "wb") as f:
        f.write(struct.pack("<Q", len(text)))
        f.write(text)
        for name in sorted(tensors):
            values = tensors[name][1]
            if sys.byteorder != "little":
                values = array.array("f", values)
                values.byteswap()
            f.write(values.tobytes())
    os.replace(tmp, path)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("inputs", nargs="+", help="weight files of one configuration")
    parser.add_argument("--out", required=True, help="the averaged weight file to write")
    args = parser.parse_args(argv)
    if len(args.inputs) < 2:
        fail("give at least two weight files")
    if os.path.abspath(args.out) in map(os.path.abspath, args.inputs):
        fail(f"{args.out} is also an input")
    meta, first = read(args.inputs[0])
    # Sums in double precision, rounded to float32 once.
    mean = {name: (shape, [float(v) for v in values]) for name, (shape, values) in first.items()}
    config = configuration(args.inputs[0], meta)
    for path in args.inputs[1:]:
        other_meta, other = read(path)
        if configuration(path, other_meta) != config:
            fail(f"{path}: another model configuration than {args.inputs[0]}")
        if sorted(other) != sorted(mean):
            fail(f"{path}: other tensors than {args.inputs[0]}")
        for name, (shape, values) in other.items():
            if shape != mean[name][0]:
                fail(f"{path}: tensor {name} is {shape}, not {mean[name][0]}")
            acc = mean[name][1]
            for i, v in enumerate(values):
                acc[i] += v
    k = float(len(args.inputs))
    for name, (shape, acc) in mean.items():
        mean[name] = (shape, array.array("f", (v / k for v in acc)))
    meta = dict(meta)
    meta["averaged_from"] = json.dumps(args.inputs)
    write(args.out, meta, mean)
    n = sum(len(v) for _, v in mean.values())
    print(f"{args.out}: the mean of {len(args.inputs)} files, {len(mean)} tensors, {n} values")


if __name__ == "__main__":
    main()
