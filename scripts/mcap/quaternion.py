"""Quaternion helpers shared by the recording scripts (check_run.py, render.py)."""


def rotation(q):
    """The 3x3 rotation matrix (rows) of a `foxglove.Quaternion` dict {x, y, z, w}."""
    x, y, z, w = q["x"], q["y"], q["z"], q["w"]
    return [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]
