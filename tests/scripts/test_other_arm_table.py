"""experiments/scripts/other_arm_table.py against hand-counted episodes (standard library only)."""

import importlib.util
import math
import os
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
SPEC = importlib.util.spec_from_file_location(
    "other_arm_table",
    os.path.join(HERE, "..", "..", "experiments", "scripts", "other_arm_table.py"),
)
other_arm_table = importlib.util.module_from_spec(SPEC)
SPEC.loader.exec_module(other_arm_table)


def episode(seed, violations, other_m, other_s=0.0):
    return {
        "seed": str(seed),
        "violations": str(violations),
        "other_arm_min_separation_m": other_m,
        "other_arm_violation_s": str(other_s),
    }


class OtherArmTable(unittest.TestCase):
    def test_the_hidden_ones_are_the_other_arms_alone(self):
        rows = [
            episode(1, 0, "0.05000", 1.5),  # hidden: only the other arm below d_min
            episode(2, 3, "-0.01000", 0.5),  # both: seen, and the other arm touched
            episode(3, 2, "0.40000"),  # seen only
            episode(4, 0, "0.30000"),  # neither
            episode(5, 0, "NaN"),  # no other arm in the clip
        ]
        r = other_arm_table.row(rows, 0.1)
        self.assertEqual(r["episodes"], 5)
        self.assertEqual(r["with_other_arm"], 4)
        self.assertEqual(r["seen"], 2)
        self.assertEqual(r["other"], 2)
        self.assertEqual(r["hidden"], 1)
        self.assertEqual(r["either"], 3)
        self.assertEqual(r["other_contacts"], 1)
        self.assertAlmostEqual(r["other_closest_m"], -0.01)
        self.assertAlmostEqual(r["other_below_s"], 2.0)

    def test_a_run_without_the_other_arm_has_no_closest(self):
        r = other_arm_table.row([episode(1, 1, "NaN")], 0.1)
        self.assertEqual((r["with_other_arm"], r["other"], r["hidden"]), (0, 0, 0))
        self.assertTrue(math.isnan(r["other_closest_m"]))


if __name__ == "__main__":
    unittest.main()
