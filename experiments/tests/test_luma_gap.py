"""experiments/scripts/luma_gap.py against hand-computed answers (standard library only)."""

import contextlib
import importlib.util
import io
import os
import sys
import tempfile
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
SPEC = importlib.util.spec_from_file_location(
    "luma_gap", os.path.join(HERE, "..", "scripts", "luma_gap.py")
)
luma_gap = importlib.util.module_from_spec(SPEC)
SPEC.loader.exec_module(luma_gap)

HEADER = "sequence,frame,camera,occlusion,forearm_px,forearm_dice,forearm_dice_thresholded,input_ceiling,forearm_luma\n"


def frames_csv(rows):
    """A --frames CSV of (sequence, forearm Dice loss, luma or '') rows."""
    f = tempfile.NamedTemporaryFile("w", suffix=".csv", delete=False)
    f.write(HEADER)
    for k, (seq, dice, luma) in enumerate(rows):
        ceiling = "" if luma == "" else "0.02"
        f.write(f"{seq},{k + 1},short,light,10,{dice},{dice},{ceiling},{luma}\n")
    f.close()
    return f.name


def run(path, *extra):
    out = io.StringIO()
    argv = sys.argv
    sys.argv = ["luma_gap.py", path, *extra]
    try:
        with contextlib.redirect_stdout(out):
            luma_gap.main()
    finally:
        sys.argv = argv
    return out.getvalue()


def run_rows(rows, *extra):
    """`run` on a --frames CSV of `rows` (as `frames_csv`), removed afterwards."""
    path = frames_csv(rows)
    try:
        return run(path, *extra)
    finally:
        os.unlink(path)


class LumaGap(unittest.TestCase):
    def test_bands_match_eval_segmentations_bounds(self):
        # The same bounds as LumaBand in procnet/src/eval.rs: dark below 0.2, light from 0.5.
        self.assertEqual(luma_gap.band(0.1999), "dark")
        self.assertEqual(luma_gap.band(0.2), "mid")
        self.assertEqual(luma_gap.band(0.4999), "mid")
        self.assertEqual(luma_gap.band(0.5), "light")

    def test_the_gap_of_uniform_sequences_is_exact_and_its_interval_collapses(self):
        # Two dark sequences at 0.3 a frame, a mid and a light one at 0.1; a frame without a
        # forearm (empty luma) counts in no band.
        rows = [(1, 0.3, 0.05), (1, 0.3, 0.01), (2, 0.3, 0.07), (3, 0.1, 0.2), (4, 0.1, 0.5),
                (4, 1.0, "")]
        text = run_rows(rows, "--resamples", "200")
        self.assertIn("| dark | 2 | 3 | 0.3000 |", text)
        self.assertIn("| mid | 1 | 1 | 0.1000 |", text)
        self.assertIn("| light | 1 | 1 | 0.1000 |", text)
        self.assertIn("dark - rest: +0.2000, 95 % interval [+0.2000, +0.2000]", text)
        # The light sequence (0.1) against the three dark frames and the mid one, frame by
        # frame: 0.1 - (0.3 * 3 + 0.1) / 4.
        self.assertIn("light - rest: -0.1500, 95 % interval", text)

    def test_a_sequence_in_two_lighter_bands_is_one_unit_of_the_resampling(self):
        # The rest is one sequence, mid in one frame (0.1) and light in another (0.3): every
        # resample draws that sequence whole, so the interval collapses onto the gap.
        text = run_rows([(1, 0.5, 0.01), (2, 0.1, 0.2), (2, 0.3, 0.6)], "--resamples", "200")
        self.assertIn("dark - rest: +0.3000, 95 % interval [+0.3000, +0.3000]", text)

    def test_a_band_with_no_rest_is_not_measured_and_all_of_them_is_an_error(self):
        # Only dark and mid frames: the light gap has no side to measure, the dark one has.
        text = run_rows([(1, 0.5, 0.01), (2, 0.1, 0.3)], "--resamples", "50")
        self.assertIn("dark - rest: +0.4000", text)
        self.assertIn("light - rest: not measured, a side is empty", text)
        # Only mid frames: neither gap can be measured.
        with self.assertRaises(SystemExit) as stop:
            run_rows([(1, 0.5, 0.3), (2, 0.1, 0.3)], "--resamples", "50")
        self.assertIn("no gap to measure", str(stop.exception))

    def test_no_resamples_is_refused(self):
        with contextlib.redirect_stderr(io.StringIO()), self.assertRaises(SystemExit):
            run_rows([(1, 0.5, 0.01), (2, 0.1, 0.2)], "--resamples", "0")

    def test_frames_weigh_by_number_not_by_sequence(self):
        # Sequence 1 has three frames at 0.4, sequence 2 one at 0.0: frame-weighted 0.3.
        groups = [[0.4, 0.4, 0.4], [0.0]]
        self.assertAlmostEqual(luma_gap.frame_mean(groups), 0.3)

    def test_a_csv_without_the_luma_column_is_refused(self):
        f = tempfile.NamedTemporaryFile("w", suffix=".csv", delete=False)
        f.write("sequence,frame,forearm_dice\n1,1,0.5\n")
        f.close()
        try:
            with self.assertRaises(SystemExit) as stop:
                run(f.name)
        finally:
            os.unlink(f.name)
        self.assertIn("no forearm_luma column", str(stop.exception))


if __name__ == "__main__":
    unittest.main()
