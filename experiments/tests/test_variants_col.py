"""experiments/scripts/lib/variants.sh's `col`: a cell of `eval segmentation`'s forearm table by group and
column header (bash and awk; standard library Python drives it)."""

import os
import subprocess
import tempfile
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
VARIANTS = os.path.join(HERE, "..", "scripts", "lib", "variants.sh")

# The shape of `eval segmentation`'s Markdown: a per-class table first, then the forearm table
# (the first whose header starts `| group |`), then the loss breakdown, which repeats the
# group names under other columns.
TABLE = """| class | Dice loss (per frame) | batch Dice loss | IoU | focal loss |
|---|---|---|---|---|
| forearm | 0.9 | 0.9 | 0.1 | 0.1 |

| group | sequences | frames | Dice loss | batch Dice loss | IoU | focal loss | ceiling, stored | ceiling, input | class mean Dice |
|---|---|---|---|---|---|---|---|---|---|
| all | 120 | 3480 | 0.3124 | 0.3060 | 0.5628 | 0.0214 | 0.0027 | 0.0182 | 0.2951 |
| occlusion heavy | 40 | 1160 | 0.3614 | 0.3427 | 0.5078 | 0.0242 | 0.0024 | 0.0169 | 0.3164 |

| group | frames | Dice loss, thresholded | with the elbow and wrist right |
|---|---|---|---|
| all | 3480 | 0.7777 | 0.6666 |
"""


def col(group, column):
    with tempfile.NamedTemporaryFile("w", suffix=".md", delete=False) as f:
        f.write(TABLE)
    try:
        out = subprocess.run(
            ["bash", "-c", f'. "{VARIANTS}"; col "$1" "$2" "$3"', "col", f.name, group, column],
            check=True, capture_output=True, text=True,
        )
    finally:
        os.unlink(f.name)
    return out.stdout.strip()


class Col(unittest.TestCase):
    def test_a_cell_is_found_by_group_and_header_in_the_forearm_table(self):
        self.assertEqual(col("all", "Dice loss"), "0.3124")
        self.assertEqual(col("occlusion heavy", "Dice loss"), "0.3614")
        # The last column, behind the two ceilings (reading it by position once gave the
        # input ceiling, 0.0182, for the five-class mean).
        self.assertEqual(col("all", "class mean Dice"), "0.2951")

    def test_the_breakdown_below_is_not_read(self):
        # Its columns are not the forearm table's, and its `all` row comes later.
        self.assertEqual(col("all", "Dice loss, thresholded"), "")

    def test_a_missing_group_or_column_is_empty(self):
        self.assertEqual(col("distance nowhere", "Dice loss"), "")
        self.assertEqual(col("all", "no such column"), "")


if __name__ == "__main__":
    unittest.main()
