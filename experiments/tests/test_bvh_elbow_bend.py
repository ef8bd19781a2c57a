"""experiments/scripts/bvh_elbow_bend.py on a hand-built BVH whose answers are known."""

import gzip
import importlib.util
import os
import tempfile
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
SPEC = importlib.util.spec_from_file_location(
    "bvh_elbow_bend", os.path.join(HERE, "..", "scripts", "bvh_elbow_bend.py")
)
bvh_elbow_bend = importlib.util.module_from_spec(SPEC)
SPEC.loader.exec_module(bvh_elbow_bend)


def joint(name, offset, body=""):
    return (f"JOINT {name}\n{{\nOFFSET {offset}\nCHANNELS 3 Zrotation Xrotation Yrotation\n"
            f"{body}}}\n")


def arm(side, x):
    hand = joint(f"{side}_hand", "0 -250 0", "End Site\n{\nOFFSET 0 -50 0\n}\n")
    return joint(f"{side}_upper_arm", f"{x} 450 0", joint(f"{side}_forearm", "0 -300 0", hand))


# y up, the person facing +z, so their left is +x (y x z): the right arm at -x. Both arms
# hang; the head is ahead of the neck. Channels: the root's 6, then 3 per joint in the
# file's order: torso, neck, head, right arm (upper, forearm, hand), left arm.
HIERARCHY = (
    "HIERARCHY\nROOT hip\n{\nOFFSET 0 0 0\n"
    "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n"
    + joint("torso", "0 0 0",
            joint("neck", "0 500 0", joint("head", "0 100 50", "End Site\n{\nOFFSET 0 0 0\n}\n"))
            + arm("right", -200) + arm("left", 200))
    + "}\n"
)


def frame(forearm_x_deg):
    values = [0.0] * (6 + 3 * 9)
    for forearm in (4, 7):  # the joints' order: torso 0, neck 1, head 2, right 3-5, left 6-8
        values[6 + 3 * forearm + 1] = forearm_x_deg
    return " ".join(str(v) for v in values)


class ElbowBendTest(unittest.TestCase):
    def setUp(self):
        self.dir = tempfile.TemporaryDirectory()
        path = os.path.join(self.dir.name, "clip.bvh.gz")
        # Frame 0: both forearms flexed forward (rotated -90 deg about x: (0,-1,0) -> +z);
        # frame 1: both bent backwards by 90 deg, which no elbow does.
        motion = f"MOTION\nFrames: 2\nFrame Time: 0.01\n{frame(-90.0)}\n{frame(90.0)}\n"
        with gzip.open(path, "wt") as f:
            f.write(HIERARCHY + motion)
        self.clip = bvh_elbow_bend.parse(path)

    def tearDown(self):
        self.dir.cleanup()

    def test_the_hand_built_clip_parses(self):
        joints, channels, frames, values = self.clip
        self.assertEqual(channels, 6 + 3 * 9)
        self.assertEqual(frames, 2)
        self.assertEqual(len(values), 2 * channels)
        p = bvh_elbow_bend.positions(self.clip, 0, False, "")
        self.assertEqual([round(c, 6) for c in p["right_hand"]], [-200.0, 150.0, 250.0])

    def test_forward_and_backward_bends_are_told_apart(self):
        # Names as written: the right arm is the person's right.
        hyper, ahead, behind, head = bvh_elbow_bend.measure([self.clip], 1, False, "", False)
        self.assertEqual((hyper, ahead, behind, head), (0.5, 0.5, 0.5, 1.0))
        # Only the backward frame is hyperextended: measured on frame 1 alone, all of it.
        backward_only = (self.clip[0], self.clip[1], 1, self.clip[3][self.clip[1]:])
        self.assertEqual(bvh_elbow_bend.measure([backward_only], 1, False, "", False)[0], 1.0)
        # Sides swapped, the backward bend reads as a forward one and the head falls behind.
        hyper, _, _, head = bvh_elbow_bend.measure([backward_only], 1, False, "", True)
        self.assertEqual((hyper, head), (0.0, 0.0))


if __name__ == "__main__":
    unittest.main()
