"""Hypothesis strategies shared by the tests: presets, seeds, poses, obstacle shapes, velocities."""

import math

from hypothesis import strategies as st

from safenav import PRESET_NAMES, Pose2D
from safenav.worlds import Box, Cylinder

presets = st.sampled_from(PRESET_NAMES)
"""A preset name."""

seeds = st.integers(0, 2**32 - 1)
"""An episode seed."""

headings = st.floats(-math.pi, math.pi)
"""A yaw [rad]."""

poses = st.builds(Pose2D, st.floats(-20, 20), st.floats(-20, 20), st.floats(-10, 10))
"""A pose anywhere near the origin, its yaw not wrapped [m, m, rad]."""

_centers = st.tuples(st.floats(-3, 3), st.floats(-3, 3))

boxes = st.builds(Box, _centers, st.tuples(st.floats(0.1, 2), st.floats(0.1, 2)), st.floats(0, math.pi))
"""A box within 3 m of the origin, sides 0.1 to 2 m."""

cylinders = st.builds(Cylinder, _centers, st.floats(0.05, 1.0))
"""A post within 3 m of the origin, radius 5 cm to 1 m."""

shapes = st.one_of(boxes, cylinders)
"""A box or a post."""


def velocities(v_max: float, omega_max: float) -> st.SearchStrategy[tuple[float, float]]:
    """Commands ``(v [m/s], omega [rad/s])`` within symmetric limits."""
    return st.tuples(st.floats(-v_max, v_max), st.floats(-omega_max, omega_max))
