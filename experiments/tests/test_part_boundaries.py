"""experiments/scripts/part_boundaries.py against hand-computed answers (standard library only)."""

import contextlib
import importlib.util
import io
import json
import math
import os
import shutil
import sys
import tempfile
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
SPEC = importlib.util.spec_from_file_location(
    "part_boundaries", os.path.join(HERE, "..", "scripts", "part_boundaries.py")
)
part_boundaries = importlib.util.module_from_spec(SPEC)
SPEC.loader.exec_module(part_boundaries)

HEADER = (
    "sequence,frame,camera,occlusion,forearm_px,forearm_dice,forearm_dice_thresholded,"
    "input_ceiling,forearm_luma,forearm_dice_parts_right\n"
)


class PartBoundaries(unittest.TestCase):
    def setUp(self):
        self.dir = tempfile.mkdtemp()
        self.dataset = os.path.join(self.dir, "dataset")

    def tearDown(self):
        shutil.rmtree(self.dir)

    def frame(self, sequence, frame, elbow_deg):
        d = os.path.join(self.dataset, f"seq_{sequence:05}")
        os.makedirs(d, exist_ok=True)
        with open(os.path.join(d, f"frame_{frame:03}.json"), "w") as f:
            json.dump({"human_q": [0.1, 0.5, math.radians(elbow_deg)]}, f)

    def run_csv(self, text, *extra):
        """Runs the script on a --frames CSV holding `text`; returns what it prints."""
        path = os.path.join(self.dir, "frames.csv")
        with open(path, "w") as f:
            f.write(text)
        out, argv = io.StringIO(), sys.argv
        sys.argv = ["part_boundaries.py", path, "--dataset", self.dataset, *extra]
        try:
            with contextlib.redirect_stdout(out):
                part_boundaries.main()
        finally:
            sys.argv = argv
        return out.getvalue()

    def run_rows(self, rows, *extra):
        """rows: (sequence, frame, elbow flexion in degrees, thresholded loss, parts right)."""
        text = HEADER
        for sequence, frame, elbow, loss, right in rows:
            self.frame(sequence, frame, elbow)
            text += f"{sequence},{frame},short,light,10,{loss},{loss},0.02,0.3,{right}\n"
        return self.run_csv(text, *extra)

    def test_bands_split_the_loss_at_the_elbow_and_wrist(self):
        text = self.run_rows(
            [
                # Straight arm (5 deg): 0.4 thresholded, 0.1 with the parts right, two frames
                # of one sequence.
                (7, 1, 5.0, 0.4, 0.1),
                (7, 2, 5.0, 0.4, 0.1),
                # Bent (60 deg): 0.2 and 0.15, two sequences.
                (8, 1, 60.0, 0.2, 0.15),
                (9, 1, 60.0, 0.2, 0.15),
            ]
        )
        self.assertIn("| 0-10 deg | 2 | 1 | 0.4000 | 0.1000 | 0.3000 | 75% |", text)
        self.assertIn("| >= 40 deg | 2 | 2 | 0.2000 | 0.1500 | 0.0500 | 25% |", text)
        # All four frames: 0.3 and 0.125, a difference of 0.175 (58 % of 0.3).
        self.assertIn("| all | 4 | 3 | 0.3000 | 0.1250 | 0.1750 | 58% |", text)
        # Bands without frames are left out.
        self.assertNotIn("10-20 deg", text)

    def test_a_band_edge_belongs_to_the_band_above(self):
        self.assertEqual(part_boundaries.band_of(9.999, [10.0, 20.0]), 0)
        self.assertEqual(part_boundaries.band_of(10.0, [10.0, 20.0]), 1)
        self.assertEqual(part_boundaries.band_of(25.0, [10.0, 20.0]), 2)
        self.assertEqual(part_boundaries.band_names([10.0, 20.0]),
                         ["0-10 deg", "10-20 deg", ">= 20 deg"])

    def test_edges_must_increase(self):
        with contextlib.redirect_stderr(io.StringIO()), self.assertRaises(SystemExit):
            self.run_rows([(1, 1, 5.0, 0.4, 0.1)], "--edges-deg", "20,10")

    def test_a_csv_of_an_older_eval_is_refused_by_name(self):
        with self.assertRaises(SystemExit) as stop:
            self.run_csv("sequence,frame,forearm_dice_thresholded\n1,1,0.5\n")
        self.assertIn("no forearm_dice_parts_right column", str(stop.exception))

    def test_a_missing_frame_label_is_an_error_not_a_traceback(self):
        with self.assertRaises(SystemExit) as stop:
            self.run_csv(HEADER + "3,1,short,light,10,0.5,0.5,0.02,0.3,0.2\n")
        self.assertIn("frame_001.json", str(stop.exception))


if __name__ == "__main__":
    unittest.main()
