"""scripts/calibrate_uncertainty.py against hand-computed answers (standard library only)."""

import importlib.util
import os
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
        self.assertEqual(best[0], (2.0, 0.0))
        self.assertEqual(calibrate_uncertainty.coverage(frames, best[0]), 1.0)
        unscaled = [r for r in rows if r[0][0] == 0.0][0]
        # Index int(0.99 * 200) = 198: the 199th error, 0.398 m.
        self.assertAlmostEqual(unscaled[0][1], 0.398)
        self.assertLess(best[1], unscaled[1])


if __name__ == "__main__":
    unittest.main()
