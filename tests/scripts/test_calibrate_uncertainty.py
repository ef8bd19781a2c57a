"""scripts/calibrate_uncertainty.py against hand-computed answers (standard library only)."""

import csv
import importlib.util
import os
import subprocess
import sys
import tempfile
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
SPEC = importlib.util.spec_from_file_location(
    "calibrate_uncertainty",
    os.path.join(HERE, "..", "..", "scripts", "calibrate_uncertainty.py"),
)
calibrate_uncertainty = importlib.util.module_from_spec(SPEC)
SPEC.loader.exec_module(calibrate_uncertainty)


class Calibrate(unittest.TestCase):
    def test_the_fits_radius(self):
        radius = calibrate_uncertainty.radius
        # (error, sigma, spread); (scale, floor): 2 * 0.01 + 0.03.
        self.assertAlmostEqual(radius((0.0, 0.01, 0.0), (2.0, 0.03)), 0.05)
        # The hypotheses' spread wins where it is larger.
        self.assertAlmostEqual(radius((0.0, 0.01, 0.2), (2.0, 0.03)), 0.2)

    def test_a_floor_covers_its_share(self):
        # Errors 1..400 (units of 1e-5 m), no curvature, no spread.
        frames = [(k / 100_000.0, 0.0, 0.0) for k in range(1, 401)]
        # Index int(0.99 * 400) = 396 of the sorted errors: 397e-5 m.
        self.assertAlmostEqual(calibrate_uncertainty.smallest_floor(frames, 0.0, 0.99), 0.00397)
        # Frames the spread covers need no floor.
        covered = [(e, 0.0, 1.0) for e, _, _ in frames]
        self.assertEqual(calibrate_uncertainty.smallest_floor(covered, 0.0, 0.99), 0.0)

    def test_the_curvature_is_used_where_it_tracks_the_error(self):
        # Each frame's error is twice its sigma: scale 2 covers every frame with no floor,
        # scale 0 needs the 99th percentile of the errors.
        frames = [(2 * k / 1000.0, k / 1000.0, 0.0) for k in range(1, 201)]
        rows, best = calibrate_uncertainty.calibrate(frames, 0.99)
        self.assertEqual(best[0], (2.0, 0.0, (0.0, 0.0, 0.0)))
        self.assertEqual(calibrate_uncertainty.coverage(frames, best[0]), 1.0)
        unscaled = [r for r in rows if r[0][0] == 0.0][0]
        # Index int(0.99 * 200) = 198: the 199th error, 0.398 m.
        self.assertAlmostEqual(unscaled[0][1], 0.398)
        self.assertLess(best[1], unscaled[1])

    def test_each_band_of_the_hidden_share_gets_its_own_floor(self):
        # 200 frames barely hidden with errors up to 2 cm, 200 over half hidden with errors
        # up to 20 cm: one floor for all would be about 20 cm.
        seen = [(k / 10_000.0, 0.0, 0.0, 0.1) for k in range(1, 201)]
        hidden = [(k / 1_000.0, 0.0, 0.0, 0.6) for k in range(1, 201)]
        calibration = calibrate_uncertainty.band_floors(seen + hidden, 0.0, 0.99)
        # Index int(0.99 * 200) = 198 of each band's sorted errors: the 199th.
        self.assertAlmostEqual(calibration[1], 0.0199)
        # The band from 25 % has no frames and takes the floor before it; 75 % the 50 %'s.
        self.assertAlmostEqual(calibration[2][0], 0.0199)
        self.assertAlmostEqual(calibration[2][1], 0.199)
        self.assertAlmostEqual(calibration[2][2], 0.199)
        self.assertAlmostEqual(calibrate_uncertainty.radius((0.0, 0.0, 0.0, 0.8), calibration), 0.199)
        self.assertAlmostEqual(calibrate_uncertainty.radius((0.0, 0.0, 0.0, 0.0), calibration), 0.0199)
        for frames in (seen, hidden):
            self.assertGreaterEqual(calibrate_uncertainty.coverage(frames, calibration), 0.99)

    def test_a_less_hidden_bands_floor_is_the_least(self):
        # A more hidden band with smaller errors still gets the floor of the band before.
        frames = [(0.05, 0.0, 0.0, 0.1)] * 100 + [(0.01, 0.0, 0.0, 0.9)] * 100
        calibration = calibrate_uncertainty.band_floors(frames, 0.0, 0.99)
        self.assertEqual(calibration[2], (0.05, 0.05, 0.05))


    def test_pooled_sources_are_calibrated_together_and_reported_apart(self):
        # Source A: 100 frames of 1 cm error; source B: 100 of 10 cm. Pooled, the 99 %
        # floor (index 198 of 200 sorted errors) is 10 cm and covers both; each source's
        # coverage is its own line.
        def write(path, error_cm, n=100):
            with open(path, "w", newline="") as f:
                w = csv.writer(f)
                w.writerow(["no_pose", "ends_cm", "sigma_m", "spread_m", "hidden_share"])
                for _ in range(n):
                    w.writerow(["", error_cm, 0.0, 0.0, 0.0])

        with tempfile.TemporaryDirectory() as tmp:
            paths = {k: os.path.join(tmp, f"{k}.csv") for k in ("av", "at", "bv", "bt")}
            write(paths["av"], 1.0)
            write(paths["at"], 1.0)
            write(paths["bv"], 10.0)
            write(paths["bt"], 20.0)
            script = os.path.join(HERE, "..", "..", "scripts", "calibrate_uncertainty.py")
            out = subprocess.run(
                [sys.executable, script, paths["av"], paths["at"], "--pool", paths["bv"], paths["bt"]],
                capture_output=True, text=True, check=True,
            ).stdout
            self.assertIn("200 frames with a pose", out)
            self.assertIn("smallest mean radius: scale 0, floor 0.1000 m", out)
            self.assertIn(f"{paths['at']}: 100.00 % of 100", out)
            # B's test errors are twice its validation's: none within the bound.
            self.assertIn(f"{paths['bt']}: 0.00 % of 100", out)
            lone = subprocess.run(
                [sys.executable, script, paths["av"], "--pool", paths["bv"], paths["bt"]],
                capture_output=True, text=True,
            )
            self.assertNotEqual(lone.returncode, 0)
            self.assertIn("--pool needs", lone.stderr)

    def test_the_calibration_is_written_beside_the_weights_with_their_hash(self):
        import hashlib
        import math
        import tomllib

        with tempfile.TemporaryDirectory() as d:
            weights = os.path.join(d, "mine.safetensors")
            with open(weights, "wb") as f:
                f.write(b"weights")
            sha = hashlib.sha256(b"weights").hexdigest()
            write = calibrate_uncertainty.write_calibration
            path = write(weights, "with_depth", (1.0, 0.02, [0.03, 0.04, 0.3]), 'val "a"')
            self.assertEqual(path, os.path.join(d, "mine.calibration.toml"))
            write(weights, "without_depth", (0.0, 0.4, [0.0, 0.0, 0.0]), "val b", 0.2, 0.65)
            with open(path, "rb") as f:
                doc = tomllib.load(f)
            self.assertEqual(doc["weights_sha256"], sha)
            self.assertEqual(doc["fitted_on"], "val b")
            # The first section is kept beside the second.
            self.assertEqual(doc["with_depth"]["hidden_floors_m"], [0.03, 0.04, 0.3])
            self.assertTrue(math.isinf(doc["with_depth"]["confirm_min_gain"]))
            self.assertEqual(doc["without_depth"]["floor_m"], 0.4)
            self.assertEqual(doc["without_depth"]["confirmed_floor_m"], 0.65)
            # Other weights are refused rather than given this file.
            with open(weights, "wb") as f:
                f.write(b"other weights")
            with self.assertRaises(SystemExit):
                write(weights, "with_depth", (1.0, 0.02, [0.03, 0.04, 0.3]), "c")

    def test_fits_that_kept_their_track_get_floors_of_their_own(self):
        # 300 tracked frames with errors up to 3 cm, 100 re-acquired with errors up to 50 cm:
        # one floor for all would be set by the re-acquired frames' tail.
        kept = [(k / 10_000.0, 0.0, 0.0, 0.0, True) for k in range(1, 301)]
        lost = [(k / 200.0, 0.0, 0.0, 0.0, False) for k in range(1, 101)]
        rows, best = calibrate_uncertainty.calibrate(kept + lost, 0.99, tracked_floors=True)
        scale, floor, hidden, tracked = best[0]
        # Index int(0.99 * 100) = 99 of the re-acquired errors: the 100th, 0.5 m.
        self.assertAlmostEqual(floor, 0.5)
        # Index int(0.99 * 300) = 297 of the tracked errors: the 298th, 2.98 cm.
        self.assertAlmostEqual(tracked[0], 0.0298)
        self.assertEqual(len(tracked), 4)
        self.assertAlmostEqual(calibrate_uncertainty.radius((0.0, 0.0, 0.0, 0.0, True), best[0]), 0.0298)
        self.assertAlmostEqual(calibrate_uncertainty.radius((0.0, 0.0, 0.0, 0.0, False), best[0]), 0.5)
        for frames in (kept, lost):
            self.assertGreaterEqual(calibrate_uncertainty.coverage(frames, best[0]), 0.99)
        # Without tracked floors every frame takes the pooled floor: index 396 of 400.
        _, pooled = calibrate_uncertainty.calibrate(kept + lost, 0.99)
        self.assertAlmostEqual(pooled[0][1], 0.485)
        self.assertLess(best[1], pooled[1])

    def test_confident_floors_can_stop_short_of_the_most_hidden_band(self):
        # Confident fits (gain 0.8) with the forearm in view, errors up to 2 cm, and with
        # three quarters of it hidden, up to 4 cm; poor fits (gain 0.5) that hidden, up to
        # 60 cm.
        seen = [(k / 10_000.0, 0.0, 0.0, 0.0, False, 0.8) for k in range(1, 201)]
        hidden = [(k / 5_000.0, 0.0, 0.0, 0.8, False, 0.8) for k in range(1, 201)]
        poor = [(k * 0.003, 0.0, 0.0, 0.8, False, 0.5) for k in range(1, 201)]
        frames = seen + hidden + poor
        calibrate = calibrate_uncertainty.calibrate
        _, own = calibrate(frames, 0.99, confident_gain=0.7)
        _, kept = calibrate(frames, 0.99, confident_gain=0.7, confident_bands=3)
        # Index int(0.99 * 200) = 198 of each set's sorted errors: the 199th.
        self.assertAlmostEqual(own[0][4][1][0], 0.0199)
        self.assertAlmostEqual(own[0][4][1][3], 0.0398)
        self.assertAlmostEqual(kept[0][4][1][0], 0.0199)
        self.assertAlmostEqual(kept[0][4][1][3], 0.597)
        radius = calibrate_uncertainty.radius
        confident_hidden = (0.0, 0.0, 0.0, 0.8, False, 0.8)
        self.assertAlmostEqual(radius(confident_hidden, own[0]), 0.0398)
        self.assertAlmostEqual(radius(confident_hidden, kept[0]), 0.597)
        self.assertAlmostEqual(radius((0.0, 0.0, 0.0, 0.0, False, 0.8), kept[0]), 0.0199)

    def test_confident_fits_get_floors_of_their_own(self):
        # 200 frames of gain 0.8 with errors up to 2 cm, 200 of gain 0.5 with errors up to
        # 60 cm; the recorded people among them are the poor fits.
        sure = [(k / 10_000.0, 0.0, 0.0, 0.0, False, 0.8, False) for k in range(1, 201)]
        poor = [(k * 0.003, 0.0, 0.0, 0.0, False, 0.5, True) for k in range(1, 201)]
        rows, best = calibrate_uncertainty.calibrate(sure + poor, 0.99, confident_gain=0.7)
        scale, floor, hidden, tracked, confident = best[0]
        self.assertIsNone(tracked)
        # Index int(0.99 * 200) = 198 of each set's sorted errors: the 199th.
        self.assertAlmostEqual(floor, 0.597)
        self.assertEqual(confident[0], 0.7)
        self.assertAlmostEqual(confident[1][0], 0.0199)
        # A fit of the gain or more takes the confident floor; below it the others'.
        radius = calibrate_uncertainty.radius
        self.assertAlmostEqual(radius((0.0, 0.0, 0.0, 0.0, False, 0.7), best[0]), 0.0199)
        self.assertAlmostEqual(radius((0.0, 0.0, 0.0, 0.0, False, 0.69), best[0]), 0.597)
        for frames in (sure, poor):
            self.assertGreaterEqual(calibrate_uncertainty.coverage(frames, best[0]), 0.99)
        _, pooled = calibrate_uncertainty.calibrate(sure + poor, 0.99)
        self.assertLess(best[1], pooled[1])
        # Written, the confident floors are a table of their own that reads back.
        import tomllib

        with tempfile.TemporaryDirectory() as d:
            weights = os.path.join(d, "w.safetensors")
            with open(weights, "wb") as f:
                f.write(b"w")
            path = calibrate_uncertainty.write_calibration(weights, "with_depth", best[0], "v")
            with open(path, "rb") as f:
                doc = tomllib.load(f)
            self.assertEqual(doc["with_depth"]["confident"]["min_gain"], 0.7)
            self.assertEqual(len(doc["with_depth"]["confident"]["floors_m"]), 4)
        # From the CSVs: the coverage of recorded people and of the generator apart.
        with tempfile.TemporaryDirectory() as d:
            path = os.path.join(d, "pose_frames.csv")
            with open(path, "w", newline="") as f:
                w = csv.writer(f)
                w.writerow(["no_pose", "ends_cm", "sigma_m", "spread_m", "hidden_share",
                            "reacquired", "gain", "recorded"])
                for e, _, _, _, _, g, r in sure + poor:
                    w.writerow(["", 100 * e, 0.0, 0.0, 0.0, "true", g, "true" if r else "false"])
            script = os.path.join(HERE, "..", "..", "scripts", "calibrate_uncertainty.py")
            out = subprocess.run([sys.executable, script, path, "--confident-gain", "0.7"],
                                 capture_output=True, text=True, check=True).stdout
            # The 99th percentile of each set: 199 of its 200 frames within.
            self.assertIn("validation, gain 0.7 or more: 99.50 % of 200", out)
            self.assertIn("validation, recorded people: 99.50 % of 200 within", out)
            self.assertIn("validation, the generator's motion: 99.50 % of 200 within", out)
            none = subprocess.run([sys.executable, script, path, "--confident-gain", "0.9"],
                                  capture_output=True, text=True)
            self.assertNotEqual(none.returncode, 0)
            self.assertIn("no frame with a pose has a gain of 0.9", none.stderr)

    def test_the_fits_settings_are_read_beside_the_csv_and_written(self):
        import tomllib

        def write_csv(path, reacquired):
            with open(path, "w", newline="") as f:
                w = csv.writer(f)
                w.writerow(["no_pose", "ends_cm", "sigma_m", "spread_m", "hidden_share", "reacquired", "gain"])
                for k in range(100):
                    w.writerow(["", 1.0 if reacquired == "false" else 20.0, 0.0, 0.0, 0.0, reacquired, 0.8])

        fit = ("fit_trunk = true\nsearch_below_gain = 0.7\nreversed_start = true\ndepth_start = true\n"
               "trunk_downsample = 2\n")
        with tempfile.TemporaryDirectory() as d:
            val, test = os.path.join(d, "val"), os.path.join(d, "test")
            for folder in (val, test):
                os.mkdir(folder)
                write_csv(os.path.join(folder, "pose_frames.csv"), "false")
                with open(os.path.join(folder, "pose_frames_b.csv"), "a") as f:
                    pass
                with open(os.path.join(folder, "fit.toml"), "w") as f:
                    f.write("# a comment\n" + fit)
            self.assertEqual(
                calibrate_uncertainty.fit_settings(os.path.join(val, "pose_frames.csv")),
                {"fit_trunk": True, "search_below_gain": 0.7, "reversed_start": True, "depth_start": True,
                 "trunk_downsample": 2},
            )
            self.assertIsNone(calibrate_uncertainty.fit_settings(os.path.join(val, "pose_frames_b.csv")))
            weights = os.path.join(d, "w.safetensors")
            with open(weights, "wb") as f:
                f.write(b"w")
            script = os.path.join(HERE, "..", "..", "scripts", "calibrate_uncertainty.py")
            args = [sys.executable, script, os.path.join(val, "pose_frames.csv"),
                    os.path.join(test, "pose_frames.csv"), "--tracked-floors", "--write", weights, "--depth"]
            out = subprocess.run(args, capture_output=True, text=True, check=True).stdout
            self.assertIn("validation: 100 of 100 frames with a pose kept their track", out)
            with open(os.path.join(d, "w.calibration.toml"), "rb") as f:
                doc = tomllib.load(f)
            self.assertEqual(doc["with_depth"]["fit"]["search_below_gain"], 0.7)
            self.assertIs(doc["with_depth"]["fit"]["depth_start"], True)
            # An integer setting stays an integer (the fit's settings read it as one).
            self.assertEqual(doc["with_depth"]["fit"]["trunk_downsample"], 2)
            self.assertIsInstance(doc["with_depth"]["fit"]["trunk_downsample"], int)
            self.assertEqual(doc["with_depth"]["tracked_floors_m"], [0.01, 0.01, 0.01, 0.01])
            # The test split measured with another fit is refused.
            with open(os.path.join(test, "fit.toml"), "w") as f:
                f.write(fit.replace("0.7", "0.55"))
            refused = subprocess.run(args, capture_output=True, text=True)
            self.assertNotEqual(refused.returncode, 0)
            self.assertIn("different fits", refused.stderr)


if __name__ == "__main__":
    unittest.main()
