"""experiments/scripts/misses_by_view.py against view angles of known rotations and hand-counted misses
(standard library only)."""

import contextlib
import csv
import importlib.util
import io
import json
import math
import os
import tempfile
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
SPEC = importlib.util.spec_from_file_location(
    "misses_by_view", os.path.join(HERE, "..", "scripts", "misses_by_view.py")
)
misses_by_view = importlib.util.module_from_spec(SPEC)
SPEC.loader.exec_module(misses_by_view)

S = math.sqrt(0.5)
# The torso's rotation in the camera frame (x, y, z, w), 5 m in front of the camera (+z).
FACING_CAMERA = (0.0, S, 0.0, S)  # +90 deg about y: the torso's x points along -z
SIDEWAYS = (0.0, 0.0, 0.0, 1.0)  # its x along the camera's x
AWAY = (0.0, -S, 0.0, S)  # -90 deg about y: its x along +z, away from the camera


def labels(q, xyz=(0.0, 0.0, 5.0)):
    pose = {"xyz_m": list(xyz), "quaternion_xyzw": list(q)}
    return {"parts": [{"class": "robot", "X_CP": pose}, {"class": "torso", "X_CP": pose}]}


class ViewAngle(unittest.TestCase):
    def test_rotate_a_quarter_turn(self):
        for q, v, want in [
            ((0.0, 0.0, S, S), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0)),  # +90 deg about z
            (FACING_CAMERA, (1.0, 0.0, 0.0), (0.0, 0.0, -1.0)),
            (AWAY, (1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
            ((0.0, 0.0, 0.0, 1.0), (0.3, -2.0, 5.0), (0.3, -2.0, 5.0)),
        ]:
            for a, b in zip(misses_by_view.rotate(q, v), want):
                self.assertAlmostEqual(a, b, msg=str(q))

    def test_front_side_and_back(self):
        self.assertAlmostEqual(misses_by_view.view_angle_deg(labels(FACING_CAMERA)), 0.0)
        self.assertAlmostEqual(misses_by_view.view_angle_deg(labels(SIDEWAYS)), 90.0)
        self.assertAlmostEqual(misses_by_view.view_angle_deg(labels(AWAY)), 180.0)
        # Off the optical axis: the torso at (5, 0, 5) facing -z sees the camera at 45 deg.
        self.assertAlmostEqual(
            misses_by_view.view_angle_deg(labels(FACING_CAMERA, (5.0, 0.0, 5.0))), 45.0
        )
        self.assertIsNone(misses_by_view.view_angle_deg({"parts": []}))
        self.assertEqual(
            [misses_by_view.view_bin(a) for a in (0.0, 59.9, 60.0, 119.9, 120.0, 180.0)],
            ["front", "front", "side", "side", "back", "back"],
        )


class Tally(unittest.TestCase):
    def setUp(self):
        self.dir = tempfile.TemporaryDirectory()
        self.addCleanup(self.dir.cleanup)
        self.root = os.path.join(self.dir.name, "data")
        sequences = []
        for index, q in [(1, FACING_CAMERA), (2, SIDEWAYS), (3, AWAY)]:
            d = f"seq_{index:05d}"
            os.makedirs(os.path.join(self.root, d))
            for frame in range(2):
                with open(os.path.join(self.root, d, f"frame_{frame:03d}.json"), "w") as f:
                    json.dump(labels(q), f)
            sequences.append({"index": index, "dir": d, "frames": 2})
        with open(os.path.join(self.root, "manifest.json"), "w") as f:
            json.dump({"sequences": sequences}, f)

    def csv(self, name, rows):
        """rows: (sequence, frame, occlusion, missed)."""
        path = os.path.join(self.dir.name, name)
        with open(path, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["sequence", "frame", "occlusion", "no_pose", "position_cm"])
            for s, k, o, missed in rows:
                w.writerow([s, k, o, "no pose fits the mask" if missed else "", "" if missed else 1.0])
        return path

    def test_misses_are_counted_by_view(self):
        # Front: one target miss. Side: none. Back: two misses, one of them with 70 % of the
        # forearm hidden (outside the target), so one target miss in two target frames.
        path = self.csv(
            "a.csv",
            [(1, 0, 0.1, True), (1, 1, 0.2, False), (2, 0, 0.0, False), (2, 1, 0.5, False),
             (3, 0, 0.66, True), (3, 1, 0.70, True)],
        )
        views = misses_by_view.Views(self.root)
        frames, misses, by_sequence = misses_by_view.tally(views, path)
        self.assertEqual(frames, {"front": 2, "side": 2, "back": 1})
        self.assertEqual(misses, {"front": 1, "back": 1})
        self.assertEqual(set(by_sequence), {1, 3})
        self.assertEqual(by_sequence[3][0], 1)
        self.assertAlmostEqual(by_sequence[3][1], 180.0)
        out = io.StringIO()
        with contextlib.redirect_stdout(out):
            misses_by_view.main([self.root, path])
        self.assertEqual(
            out.getvalue().strip(),
            f"{path}: target misses by view: front 1 of 2 (50.0 %); side 0 of 2 (0.0 %); "
            "back 1 of 1 (100.0 %) [1: 1 at 0 deg, 3: 1 at 180 deg]",
        )

    def test_bad_input_is_refused_with_a_message(self):
        good = self.csv("good.csv", [(1, 0, 0.1, False)])
        bad = os.path.join(self.dir.name, "bad.csv")
        with open(bad, "w") as f:
            f.write("sequence,frame,occlusion,no_pose\n1,0,half,\n")
        for argv, words in [
            ([os.path.join(self.dir.name, "none"), good], "not a dataset"),
            ([self.root, self.csv("other.csv", [(9, 0, 0.1, True)])], "no sequence 9"),
            ([self.root, self.csv("late.csv", [(1, 5, 0.1, True)])], "frame_005.json"),
            ([self.root, bad], "bad.csv:2"),
            ([self.root, os.path.join(self.dir.name, "none.csv")], "cannot read"),
        ]:
            with self.assertRaises(SystemExit) as e:
                misses_by_view.main(argv)
            self.assertIn(words, str(e.exception), argv)
        with open(os.path.join(self.dir.name, "head.csv"), "w") as f:
            f.write("sequence,frame\n")
        with self.assertRaises(SystemExit) as e:
            misses_by_view.main([self.root, os.path.join(self.dir.name, "head.csv")])
        self.assertIn("not a pose_frames.csv", str(e.exception))


if __name__ == "__main__":
    unittest.main()
