"""Base models, each against its closed form over one control period (no simulator needed)."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from safenav import UnknownName, preset
from safenav.base_models import BASE_MODELS, period_velocities

PERIOD, SUBSTEPS = 0.05, 5
H = PERIOD / SUBSTEPS
ROSBOT = preset("rosbot")   # a_max 1.5 m/s^2, alpha_max 6 rad/s^2


def velocities(model, start, command, time_constant=PERIOD, robot=ROSBOT):
    return period_velocities(model, robot, np.array(start, dtype=float), np.array(command, dtype=float),
                             period=PERIOD, substeps=SUBSTEPS, time_constant=time_constant)


def test_instant_is_the_command_at_once():
    ends, means = velocities("instant", (0.2, -1.0), (0.5, 0.4))
    assert np.array_equal(ends, np.tile([0.5, 0.4], (SUBSTEPS, 1))) and np.array_equal(means, ends)


def test_ramp_is_linear_from_the_start_velocity_to_the_command_over_the_period():
    start, command = np.array([0.2, -1.0]), np.array([0.9, 2.0])   # faster than the acceleration limits allow
    ends, means = velocities("ramp", start, command)
    t = H * np.arange(1, SUBSTEPS + 1)[:, None]
    np.testing.assert_allclose(ends, start + (t / PERIOD) * (command - start), rtol=0, atol=1e-15)
    np.testing.assert_allclose(means, start + ((t - H / 2) / PERIOD) * (command - start), rtol=0, atol=1e-15)
    np.testing.assert_allclose(ends[-1], command, rtol=0, atol=1e-15)
    # Distance over the period: the integral of a linear velocity, the mean of its ends times the period.
    assert H * means.sum(axis=0) == pytest.approx(PERIOD * (start + command) / 2, abs=1e-15)


@pytest.mark.parametrize("tau", [0.01, PERIOD, 0.3])
def test_lag_is_the_exact_first_order_response(tau):
    start, command = np.array([0.1, 1.0]), np.array([0.8, -0.5])
    ends, means = velocities("lag", start, command, time_constant=tau)
    t = H * np.arange(SUBSTEPS + 1)[:, None]
    exact = command + (start - command) * np.exp(-t / tau)
    np.testing.assert_allclose(ends, exact[1:], rtol=0, atol=1e-14)
    # The mean over each step is the exact integral of v(t) over it, divided by h.
    integral = command * t + (start - command) * tau * (1.0 - np.exp(-t / tau))
    np.testing.assert_allclose(means, np.diff(integral, axis=0) / H, rtol=0, atol=1e-13)


def test_ramp_limit_moves_at_the_acceleration_limits_at_every_physics_step():
    ends, means = velocities("ramp_limit", (0.0, 0.0), (1.0, 3.0))
    k = np.arange(1, SUBSTEPS + 1)
    np.testing.assert_allclose(ends[:, 0], ROSBOT.a_max * H * k, rtol=0, atol=1e-15)
    np.testing.assert_allclose(ends[:, 1], ROSBOT.alpha_max * H * k, rtol=0, atol=1e-15)
    assert np.array_equal(means, ends)   # each step's velocity is held over the step
    near, _ = velocities("ramp_limit", (0.49, 0.0), (0.5, 0.0))
    assert np.array_equal(near[:, 0], np.full(SUBSTEPS, 0.5))   # reached within the first step, then held


@given(st.sampled_from(BASE_MODELS), st.tuples(st.floats(-1, 1), st.floats(-3, 3)),
       st.tuples(st.floats(-1, 1), st.floats(-3, 3)), st.floats(0.005, 1.0))
def test_every_model_stays_between_the_start_velocity_and_the_command(model, start, command, tau):
    ends, means = velocities(model, start, command, time_constant=tau)
    low, high = np.minimum(start, command) - 1e-12, np.maximum(start, command) + 1e-12
    for values in (ends, means):
        assert np.all(np.isfinite(values)) and np.all((values >= low) & (values <= high))


def test_unknown_model_lists_the_models():
    message = "unknown base model 'hover'; expected one of: instant, lag, ramp, ramp_limit"
    with pytest.raises(UnknownName, match=message):
        velocities("hover", (0.0, 0.0), (0.1, 0.0))


def test_models_differ_where_they_should():
    start, command = (0.0, 0.0), (0.6, 0.0)
    reached = {model: velocities(model, start, command)[0][-1, 0] for model in BASE_MODELS}
    assert reached["instant"] == reached["ramp"] == 0.6
    assert reached["ramp_limit"] == pytest.approx(ROSBOT.a_max * PERIOD)            # 0.075 m/s: limited
    assert reached["lag"] == pytest.approx(0.6 * (1.0 - math.exp(-1.0)))            # one time constant
