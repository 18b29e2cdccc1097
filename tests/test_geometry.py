import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from safenav.geometry import Pose2D, unicycle_rollout, unicycle_step, wrap_angle

finite = st.floats(-5, 5, allow_nan=False)


def euler(pose: Pose2D, v: float, omega: float, dt: float, substeps: int = 20000) -> Pose2D:
    x, y, yaw = pose
    h = dt / substeps
    for _ in range(substeps):
        x += v * math.cos(yaw + 0.5 * omega * h) * h
        y += v * math.sin(yaw + 0.5 * omega * h) * h
        yaw += omega * h
    return Pose2D(x, y, yaw)


@pytest.mark.parametrize(("v", "omega"), [(1.0, 0.0), (0.5, 2.0), (-0.3, -1.0), (0.0, 3.0), (0.7, 1e-9)])
def test_unicycle_step_matches_fine_integration(v, omega):
    start = Pose2D(0.3, -0.2, 0.4)
    exact = unicycle_step(start, v, omega, 0.7)
    reference = euler(start, v, omega, 0.7)
    assert exact.x == pytest.approx(reference.x, abs=1e-9)
    assert exact.y == pytest.approx(reference.y, abs=1e-9)
    assert wrap_angle(exact.yaw - reference.yaw) == pytest.approx(0.0, abs=1e-12)


def test_a_full_turn_returns_to_the_start_pose():
    start = Pose2D(1.0, 2.0, 0.5)
    end = unicycle_step(start, 0.4, 2 * math.pi / 3.0, 3.0)
    assert end.x == pytest.approx(start.x, abs=1e-12)
    assert end.y == pytest.approx(start.y, abs=1e-12)
    assert wrap_angle(end.yaw - start.yaw) == pytest.approx(0.0, abs=1e-12)


@given(st.lists(st.tuples(finite, finite), min_size=1, max_size=20), finite, finite, finite)
def test_rollout_equals_repeated_steps(commands, x, y, yaw):
    start = Pose2D(x, y, yaw)
    poses = unicycle_rollout(start, np.array(commands), 0.1)
    pose = start
    for (v, omega), row in zip(commands, poses[1:], strict=True):
        pose = unicycle_step(pose, v, omega, 0.1)
        assert row[:2] == pytest.approx(pose[:2], abs=1e-9)
        assert wrap_angle(row[2] - pose.yaw) == pytest.approx(0.0, abs=1e-9)


@given(st.floats(-100, 100, allow_nan=False))
def test_wrap_angle_lands_in_half_open_interval(angle):
    wrapped = wrap_angle(angle)
    assert -math.pi <= wrapped < math.pi
    assert math.cos(wrapped) == pytest.approx(math.cos(angle), abs=1e-9)
    assert np.allclose(wrap_angle(np.array([angle])), wrapped)


def test_pose_frames_round_trip():
    pose = Pose2D(1.0, -2.0, 0.7)
    points = np.array([[0.0, 0.0], [1.0, 2.0], [-3.0, 0.5]])
    assert np.allclose(pose.to_local(pose.to_parent(points)), points)
    assert pose.compose(Pose2D(1.0, 0.0, 0.0))[:2] == pytest.approx((1.0 + math.cos(0.7), -2.0 + math.sin(0.7)))


@given(finite, finite, st.floats(-10, 10))
def test_inverse_composes_to_identity(x, y, yaw):
    pose = Pose2D(x, y, yaw)
    identity = pose.compose(pose.inverse())
    assert identity.x == pytest.approx(0.0, abs=1e-9) and identity.y == pytest.approx(0.0, abs=1e-9)
    assert wrap_angle(identity.yaw) == pytest.approx(0.0, abs=1e-9)
