"""experiments/scripts/one_armed_human.py on the catalogue's human (standard library only)."""

import importlib.util
import os
import unittest
import xml.etree.ElementTree as ET

HERE = os.path.dirname(os.path.abspath(__file__))
SPEC = importlib.util.spec_from_file_location(
    "one_armed_human",
    os.path.join(HERE, "..", "..", "experiments", "scripts", "one_armed_human.py"),
)
one_armed_human = importlib.util.module_from_spec(SPEC)
SPEC.loader.exec_module(one_armed_human)


class OneArmedHuman(unittest.TestCase):
    def test_the_left_arm_goes_and_the_rest_stays(self):
        with open(one_armed_human.HUMAN) as f:
            text = f.read()
        both = ET.fromstring(text)
        one = ET.fromstring(one_armed_human.one_armed(text))
        names = lambda root, tag: [e.get("name") for e in root.findall(tag)]
        for tag, left in (("link", 6), ("joint", 6)):
            kept = [n for n in names(both, tag) if not n.startswith("left_")]
            self.assertEqual(names(one, tag), kept)
            self.assertEqual(len(names(both, tag)) - len(kept), left)
        # The fifteen joints of the body less the left arm's five movable ones.
        movable = [j for j in one.findall("joint") if j.get("type") != "fixed"]
        self.assertEqual(len(movable), 10)


if __name__ == "__main__":
    unittest.main()
