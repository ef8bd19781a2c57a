"""Unit tests of the sweep driver's plan (scripts/sweep.py): the grid's points and flags, and
clear refusals of bad sweep files. Run: python -m unittest discover -s tests/sweeps"""

import importlib.util
import tempfile
import unittest
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
spec = importlib.util.spec_from_file_location("sweep", REPO / "scripts/sweep.py")
sweep = importlib.util.module_from_spec(spec)
spec.loader.exec_module(sweep)


class Plan(unittest.TestCase):
    def write(self, text: str) -> Path:
        folder = Path(tempfile.mkdtemp())
        (folder / "eval.toml").write_text("")
        path = folder / "sweep.toml"
        path.write_text(text)
        return path

    def refused(self, text: str, expected: str) -> None:
        with self.assertRaises(SystemExit) as caught:
            sweep.plan(self.write(text))
        self.assertIn(expected, str(caught.exception))

    def test_every_combination_is_a_point_with_its_flags(self):
        p = sweep.plan(self.write(
            'evaluation = "eval.toml"\nepisodes = 8\nshards = 2\n[grid]\nfilter = ["qp", "ssm"]\n'
            '"safety.d_min_m" = [0.1, 0.15, 0.2]\n"perception.kind" = ["noisy"]\n'))
        self.assertEqual(len(p["points"]), 6)
        self.assertEqual(p["points"][0]["flags"], [
            "--filter", "qp", "--set", "safety.d_min_m=0.1", "--set", 'perception.kind="noisy"'])
        self.assertEqual(p["points"][5]["name"], "point-06")
        self.assertEqual(p["points"][5]["values"]["filter"], "ssm")
        self.assertTrue(Path(p["evaluation"]).is_absolute())
        args = sweep.evaluate_args(p, p["points"][1], 2)
        self.assertEqual(args[-2:], ["--shard", "2/2"])
        self.assertIn("--seed", args)

    def test_the_plan_changes_with_the_files_it_reads(self):
        # A resumed sweep must not mix shards of another cell: the plan holds the evaluation
        # file's and its cell file's contents (SHA-256), and a change to either changes it.
        path = self.write('evaluation = "eval.toml"\nepisodes = 2\n')
        (path.parent / "eval.toml").write_text('cell = "cell.toml"\n')
        cell = path.parent / "cell.toml"
        cell.write_text('[[cameras]]\neye = [0.6, 2.3, 1.8]\n')
        first = sweep.plan(path)
        self.assertIn(str(cell.resolve()), first["inputs"])
        self.assertEqual(sweep.plan(path), first)
        cell.write_text('[[cameras]]\neye = [1.0, 2.9, 2.1]\n')
        self.assertNotEqual(sweep.plan(path)["inputs"], first["inputs"])
        (path.parent / "eval.toml").write_text('cell = "cell.toml"\ntask_s = 2.0\n')
        self.assertNotEqual(sweep.plan(path)["inputs"][str((path.parent / "eval.toml").resolve())],
                            first["inputs"][str((path.parent / "eval.toml").resolve())])

    def test_values_are_written_as_toml(self):
        self.assertEqual(sweep.toml_value(True), "true")
        self.assertEqual(sweep.toml_value(4), "4")
        self.assertEqual(sweep.toml_value(0.1), "0.1")
        self.assertEqual(sweep.toml_value('a "b"'), '"a \\"b\\""')
        self.assertEqual(sweep.toml_value([1.0, 2.0]), "[1.0, 2.0]")

    def test_bad_sweep_files_are_refused_with_the_reason(self):
        self.refused('episodes = 3\n', "`evaluation` (the evaluation file) is required")
        self.refused('evaluation = "nowhere.toml"\n', "is not a file")
        self.refused('evaluation = "eval.toml"\nepisods = 3\n', "unknown keys ['episods']")
        self.refused('evaluation = "eval.toml"\nepisodes = 0\n', "episodes must be an integer >= 1")
        self.refused('evaluation = "eval.toml"\nepisodes = 2\nshards = 3\n', "leave some shard without one")
        self.refused('evaluation = "eval.toml"\n[grid]\nfilter = []\n', "non-empty list")
        self.refused('evaluation = "eval.toml"\nepisodes = = 3\n', "sweep.toml")


if __name__ == "__main__":
    unittest.main()
