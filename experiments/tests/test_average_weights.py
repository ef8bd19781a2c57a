"""experiments/scripts/average_weights.py against hand-computed means, on safetensors files written here
byte by byte (standard library only)."""

import array
import contextlib
import importlib.util
import io
import json
import os
import struct
import tempfile
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
SPEC = importlib.util.spec_from_file_location(
    "average_weights", os.path.join(HERE, "..", "scripts", "average_weights.py")
)
average_weights = importlib.util.module_from_spec(SPEC)
SPEC.loader.exec_module(average_weights)

CONFIG = json.dumps({"input_size": 64, "cell": "hgru"})


def safetensors(path, tensors, config=CONFIG, fmt="workcell-procnet/1", dtype="F32"):
    """A safetensors file of little-endian float32 `tensors` ({name: (shape, values)})."""
    header = {"__metadata__": {"format": fmt, "config": config}}
    data = b""
    for name, (shape, values) in tensors.items():
        raw = struct.pack(f"<{len(values)}f", *values)
        header[name] = {"dtype": dtype, "shape": shape, "data_offsets": [len(data), len(data) + len(raw)]}
        data += raw
    text = json.dumps(header).encode()
    with open(path, "wb") as f:
        f.write(struct.pack("<Q", len(text)) + text + data)


def f32(x):
    return struct.unpack("<f", struct.pack("<f", x))[0]


class Average(unittest.TestCase):
    def setUp(self):
        self.dir = tempfile.TemporaryDirectory()
        self.path = lambda name: os.path.join(self.dir.name, name)

    def tearDown(self):
        self.dir.cleanup()

    def run_script(self, *args):
        with contextlib.redirect_stdout(io.StringIO()):
            average_weights.main(list(args))

    def refused(self, message, *args):
        with self.assertRaises(SystemExit) as e, contextlib.redirect_stdout(io.StringIO()):
            average_weights.main(list(args))
        self.assertIn(message, str(e.exception))

    def test_the_mean_of_each_tensor(self):
        safetensors(self.path("a"), {"w": ([2, 2], [1, 2, 3, 4]), "b": ([1], [0.1])})
        safetensors(self.path("b"), {"b": ([1], [0.2]), "w": ([2, 2], [3, 4, 7, -4])})
        safetensors(self.path("c"), {"w": ([2, 2], [2, 0, 2, 3]), "b": ([1], [0.3])})
        self.run_script(self.path("a"), self.path("b"), self.path("c"), "--out", self.path("m"))
        meta, mean = average_weights.read(self.path("m"))
        self.assertEqual(mean["w"][0], [2, 2])
        self.assertEqual(list(mean["w"][1]), [2.0, 2.0, 4.0, 1.0])
        # Summed in double precision from the stored float32 values, rounded once.
        expected = f32((f32(0.1) + f32(0.2) + f32(0.3)) / 3.0)
        self.assertEqual(mean["b"][1][0], expected)
        self.assertEqual(json.loads(meta["config"]), json.loads(CONFIG))
        self.assertEqual(
            json.loads(meta["averaged_from"]), [self.path("a"), self.path("b"), self.path("c")]
        )
        # The data section starts 8-byte aligned.
        with open(self.path("m"), "rb") as f:
            (n,) = struct.unpack("<Q", f.read(8))
        self.assertEqual(n % 8, 0)

    def test_files_that_do_not_match_are_refused(self):
        safetensors(self.path("a"), {"w": ([2], [1, 2])})
        safetensors(self.path("shape"), {"w": ([1, 2], [1, 2])})
        safetensors(self.path("names"), {"v": ([2], [1, 2])})
        safetensors(self.path("config"), {"w": ([2], [1, 2])}, config=json.dumps({"cell": "gru"}))
        safetensors(self.path("format"), {"w": ([2], [1, 2])}, fmt="other/1")
        safetensors(self.path("dtype"), {"w": ([2], [1, 2])}, dtype="F16")
        out = ["--out", self.path("m")]
        self.refused("tensor w is [1, 2], not [2]", self.path("a"), self.path("shape"), *out)
        self.refused("other tensors", self.path("a"), self.path("names"), *out)
        self.refused("another model configuration", self.path("a"), self.path("config"), *out)
        self.refused("not 'workcell-procnet/1'", self.path("a"), self.path("format"), *out)
        self.refused("is F16, not F32", self.path("a"), self.path("dtype"), *out)
        self.refused("at least two", self.path("a"), *out)
        self.refused("is also an input", self.path("a"), self.path("a"), "--out", self.path("a"))
        self.refused("cannot read", self.path("a"), self.path("missing"), *out)
        safetensors(self.path("noconfig"), {"w": ([2], [1, 2])}, config="{not json")
        self.refused("no model configuration", self.path("a"), self.path("noconfig"), *out)
        with open(self.path("bad"), "wb") as f:
            text = json.dumps({"__metadata__": {"format": "workcell-procnet/1"}, "w": {"dtype": "F32"}})
            f.write(struct.pack("<Q", len(text)) + text.encode())
        self.refused("tensor w has no shape or byte range", self.path("a"), self.path("bad"), *out)
        with open(self.path("short"), "wb") as f:
            f.write(struct.pack("<Q", 1000) + b"{}")
        self.refused("a header of 1000 bytes", self.path("a"), self.path("short"), *out)
        self.assertFalse(os.path.exists(self.path("m")))


if __name__ == "__main__":
    unittest.main()
