"""experiments/scripts/compare_pose.py against hand-counted misses and averages, and bootstrap intervals
whose answer is known (standard library only)."""

import contextlib
import csv
import importlib.util
import io
import os
import tempfile
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
SPEC = importlib.util.spec_from_file_location(
    "compare_pose", os.path.join(HERE, "..", "scripts", "compare_pose.py")
)
compare_pose = importlib.util.module_from_spec(SPEC)
SPEC.loader.exec_module(compare_pose)

COLUMNS = ["sequence", "frame", "distance_class", "occlusion", "no_pose", "position_cm"]


def write(path, rows):
    """rows: (sequence, frame, occlusion, error in cm or None for no pose)."""
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(COLUMNS)
        for seq, frame, occlusion, error in rows:
            w.writerow(
                [seq, frame, "short", occlusion, "" if error is not None else "true",
                 "" if error is None else error]
            )


# Three sequences of two frames. Sequence 2 misses both frames: one with 66 % of the forearm
# hidden (a target miss, 34 % visible), one with 70 % hidden (outside the target).
BASE = [
    (1, 0, 0.1, 1.0), (1, 1, 0.2, 3.0),
    (2, 0, 0.66, None), (2, 1, 0.70, None),
    (3, 0, 0.0, 2.0), (3, 1, 0.5, 12.0),
]


class ComparePose(unittest.TestCase):
    def setUp(self):
        self.dir = tempfile.TemporaryDirectory()
        self.addCleanup(self.dir.cleanup)

    def path(self, name, rows):
        p = os.path.join(self.dir.name, name)
        write(p, rows)
        return p

    def test_counts_and_averages_by_hand(self):
        run = compare_pose.Run(self.path("a.csv", BASE))
        self.assertEqual(run.frames, 6)
        self.assertEqual(run.no_pose, 2)
        self.assertEqual(dict(run.misses), {2: 1})
        # (1 + 3 + 2 + 12) / 4 posed frames.
        self.assertAlmostEqual(run.average(), 4.5)
        self.assertAlmostEqual(run.average([1, 1]), 2.0)
        self.assertEqual(run.posed(), [1.0, 2.0, 3.0, 12.0])
        self.assertEqual(compare_pose.percentile(run.posed(), 0.5), 3.0)

    def test_identical_runs_differ_by_exactly_zero(self):
        a = compare_pose.Run(self.path("a.csv", BASE))
        b = compare_pose.Run(self.path("b.csv", BASE))
        self.assertEqual(compare_pose.bootstrap_difference(a, b, 200, 3), (0.0, 0.0, 0.0))

    def test_a_constant_offset_is_the_difference_in_every_resample(self):
        a = compare_pose.Run(self.path("a.csv", BASE))
        shifted = [(s, f, o, None if e is None else e + 1.5) for s, f, o, e in BASE]
        b = compare_pose.Run(self.path("b.csv", shifted))
        d, low, high = compare_pose.bootstrap_difference(a, b, 200, 3)
        for v in (d, low, high):
            self.assertAlmostEqual(v, 1.5)

    def test_one_worse_sequence_widens_the_interval_and_stays_inside_it(self):
        # Sequence 3 is 6 cm worse in one run: the resamples that leave it out differ by 0.
        a = compare_pose.Run(self.path("a.csv", BASE))
        worse = [(s, f, o, e + 6.0 if s == 3 else e) for s, f, o, e in BASE]
        b = compare_pose.Run(self.path("b.csv", worse))
        d, low, high = compare_pose.bootstrap_difference(a, b, 400, 5)
        self.assertAlmostEqual(d, 3.0)  # 12 cm more over 4 posed frames
        self.assertAlmostEqual(low, 0.0)
        self.assertGreater(high, d)

    def test_draws_of_sequences_without_a_pose_are_drawn_again(self):
        # Sequence 2 has no posed frame: a draw of it alone has no average, and no NaN may
        # enter the interval.
        a = compare_pose.Run(self.path("a.csv", BASE))
        b = compare_pose.Run(self.path("b.csv", BASE))
        diffs = compare_pose.resampled_differences(a, b, 2000, 11)
        self.assertEqual(len(diffs), 2000)
        self.assertTrue(all(d == 0.0 for d in diffs), "a NaN or a non-zero difference")

    def test_the_report_names_misses_and_the_verdict(self):
        a = self.path("a.csv", BASE)
        b = self.path("b.csv", [(s, f, o, None if e is None else e + 1.0) for s, f, o, e in BASE])
        out = io.StringIO()
        with contextlib.redirect_stdout(out):
            compare_pose.main([a, b, "--draws", "100"])
        text = out.getvalue()
        self.assertIn("1 target misses (2: 1)", text)
        self.assertIn("average 4.50 cm", text)
        self.assertIn("+1.00 cm, 95 % interval +1.00 to +1.00", text)
        self.assertIn("beyond the noise", text)

    def test_one_file_alone_is_summarised(self):
        out = io.StringIO()
        with contextlib.redirect_stdout(out):
            compare_pose.main([self.path("a.csv", BASE)])
        lines = out.getvalue().splitlines()
        self.assertEqual(len(lines), 1, lines)
        # Posed errors 1, 3, 2 and 12 cm; sequence 2's frame at occlusion 0.66 is the miss.
        self.assertTrue(
            lines[0].endswith(
                ": 6 frames, 2 without a pose, 1 target misses (2: 1); average 4.50 cm, "
                "99th percentile 12.0 cm, 1 above 10 cm"
            ),
            lines[0],
        )

    def test_bad_input_is_refused_with_a_message(self):
        a = self.path("a.csv", BASE)
        other = self.path("other.csv", [(9, 0, 0.1, 1.0)])
        bad = os.path.join(self.dir.name, "bad.csv")
        with open(bad, "w") as f:
            f.write("sequence,frame,occlusion,no_pose,position_cm\n1,0,zero,,1.0\n")
        twice = self.path("twice.csv", BASE + [BASE[0]])
        for argv, words in [
            ([a, other], "different sequences"),
            ([a, bad], "bad.csv:2"),
            ([a, twice], "twice"),
            ([a, os.path.join(self.dir.name, "none.csv")], "cannot read"),
            ([a, self.path("empty.csv", [])], "not a pose_frames.csv"),
            ([a, self.path("unposed.csv", [(s, f, o, None) for s, f, o, _ in BASE])], "no frame has a pose"),
        ]:
            with self.assertRaises(SystemExit) as e:
                compare_pose.main(argv)
            self.assertIn(words, str(e.exception), argv)
        with contextlib.redirect_stderr(io.StringIO()), self.assertRaises(SystemExit):
            compare_pose.main([])


if __name__ == "__main__":
    unittest.main()
