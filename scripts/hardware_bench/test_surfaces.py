"""Hand-made checks of surfaces.py and room.py:
.venv-ros2/bin/python -m unittest discover -s scripts/hardware_bench -p 'test_*.py'"""
import math
import os
import sys
import unittest

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from room import Room, RoomError, load_room  # noqa: E402
from surfaces import coverage, patches, visible, yaw_quaternion  # noqa: E402

SCENARIO = os.path.join(HERE, "..", "..", "sims", "scenarios", "pillar_room.toml")


def pose(x, y, z, yaw, t=0.0):
    return [t, x, y, z, *yaw_quaternion(yaw)]


class Surfaces(unittest.TestCase):
    def setUp(self):
        self.room = load_room(SCENARIO)
        self.centres, self.normals, self.classes = patches(self.room, 0.15)

    def test_the_room_is_the_scenarios(self):
        self.assertEqual(self.room.interior_min, (0.0, 0.0, 0.0))
        self.assertEqual(self.room.interior_max, (20.0, 10.0, 4.0))
        self.assertEqual(len(self.room.pillars), 4)
        self.assertAlmostEqual(self.room.sdf((3.5, 1.6, 2.0)), 0.5)
        self.assertLess(self.room.sdf((3.5, 2.5, 2.0)), 0.0)

    def test_patches_cover_the_free_surfaces_once(self):
        # Walls 2·(20 + 10)·4, floor and ceiling 2·200 less 4·0.64 under the pillars
        # each, pillar sides 4·(4·0.8·4): the patches' total area.
        area = 240 + 2 * (200 - 4 * 0.64) + 4 * 4 * 0.8 * 4
        cells = {"wall": 0, "floor": 0, "ceiling": 0, "pillar": 0}
        for c in self.classes:
            cells[c] += 1
        self.assertTrue(all(n > 0 for n in cells.values()), cells)
        # Patches are about 0.15 m squares; the room's edges make some smaller.
        self.assertAlmostEqual(len(self.centres) * 0.15 ** 2 / area, 1.0, delta=0.05)
        # No patch inside a pillar or on its top or bottom (they touch floor and ceiling).
        for lo, hi in self.room.pillars:
            inside = np.all((self.centres > np.array(lo) + 1e-6)
                            & (self.centres < np.array(hi) - 1e-6), axis=1)
            self.assertFalse(inside.any())
        self.assertFalse(np.any((self.classes == "pillar") & (np.abs(self.normals[:, 2]) > 0)))

    def test_a_pose_facing_one_wall_sees_only_that_wall_within_its_frustum(self):
        # 2 m from the x = 0 wall, facing it: the frustum covers |y − 5| ≤ 2·320/382
        # and |z − 2| ≤ 2·240/382; the floor and ceiling are out of view.
        seen = visible(pose(2.0, 5.0, 2.0, math.pi), self.centres, self.normals,
                       self.room.pillars)
        on_wall = np.abs(self.centres[:, 0]) < 1e-9
        self.assertTrue(np.all(on_wall[seen]))
        c = self.centres
        expected = on_wall & (np.abs(c[:, 1] - 5.0) < 2 * 320 / 382) \
            & (np.abs(c[:, 2] - 2.0) < 2 * 240 / 382)
        self.assertEqual(seen.sum(), expected.sum())
        self.assertTrue(np.array_equal(seen, expected))

    def test_beyond_five_metres_nothing_is_seen(self):
        # 6 m from the x = 0 wall: it is out of range, and so is the floor (4 m below
        # the near edge of a 32° half-angle) until z-depth 5 m... only near floor.
        seen = visible(pose(6.0, 5.0, 2.0, math.pi), self.centres, self.normals,
                       self.room.pillars)
        self.assertFalse(np.any(seen & (np.abs(self.centres[:, 0]) < 1e-9)))
        z_depth = 6.0 - self.centres[seen, 0]
        self.assertTrue(np.all(z_depth <= 5.0 + 1e-9))

    def test_a_pillar_hides_the_wall_behind_it(self):
        # From (3.5, 4.5, 2) looking at −y: the pillar at y 2.1..2.9 hides the wall
        # behind it; its own face is seen, and so is the wall beside it.
        seen = visible(pose(3.5, 4.5, 2.0, -math.pi / 2), self.centres, self.normals,
                       self.room.pillars)

        def nearest(p):
            return int(np.argmin(np.linalg.norm(self.centres - np.array(p), axis=1)))

        self.assertFalse(seen[nearest((3.5, 0.0, 2.0))])
        self.assertTrue(seen[nearest((3.5, 2.9, 2.0))])
        self.assertTrue(seen[nearest((6.0, 0.0, 2.0))])
        # The pillar's far face (normal −y) faces away.
        self.assertFalse(seen[nearest((3.5, 2.1, 2.0))])

    def test_coverage_grows_with_time_and_reports_the_fraction_at_a_time(self):
        poses = [pose(2.0, 5.0, 2.0, math.pi, 0.0), pose(2.0, 5.0, 2.0, 0.0, 1.0),
                 pose(2.0, 5.0, 2.0, math.pi / 2, 2.0)]
        result = coverage(self.room, poses, 0.15, at_s=1.5, curve_step_s=0.5)
        fractions = [f for _, f in result["curve"]]
        self.assertEqual(fractions, sorted(fractions))
        self.assertGreater(result["fraction_end"], result["fraction_at"])
        self.assertGreater(result["fraction_at"], fractions[0])

    def test_a_room_without_its_table_is_refused_by_key(self):
        with self.assertRaises(RoomError):
            load_room(os.path.join(HERE, "..", "..", "sims", "scenarios", "default.toml"))
        room = Room((0, 0, 0), (4, 4, 3), [((1, 1, 0), (2, 2, 3))])
        self.assertAlmostEqual(room.sdf((0.5, 1.5, 1.0)), 0.5)


if __name__ == "__main__":
    unittest.main()
