"""How a simulated base executes a velocity command: four models of its velocity loop.

A command ``(v [m/s], omega [rad/s])`` arrives at the start of a control period of
``period`` seconds and is held for all of it; the simulator integrates the pose over
``substeps`` physics steps of ``h = period / substeps``. The base starts the period at the
velocity ``v0`` it reached at the end of the last one. The command is first clipped to the
robot's velocity limits; then, by model:

==============  ================================================================================
model           the velocity ``v(t)`` during the period, ``t`` from its start
==============  ================================================================================
``ramp_limit``  tracks the command at the acceleration limits, updated at every physics step:
                over step ``k`` it is ``clip(c, v_{k-1} ± a_max·h)`` (with ``alpha_max`` for
                ``omega``), reached at the start of the step and held over it. The default.
``instant``     the command at once: ``v(t) = c``.
``ramp``        moves linearly from ``v0`` to ``c`` over the whole period, whatever the
                acceleration: ``v(t) = v0 + (t / period)·(c - v0)``.
``lag``         first-order lag ``dv/dt = (c - v) / tau``, integrated exactly:
                ``v(t) = c + (v0 - c)·exp(-t / tau)``, ``tau = time_constant`` [s].
==============  ================================================================================

:func:`period_velocities` gives, for every physics step, the velocity at its end and the
mean velocity over it; the pose advances by the exact arc of the mean velocity
(:func:`~safenav.geometry.unicycle_step`), so for a straight run (or a turn on the spot)
every model's distance (or angle) is the integral of its ``v(t)`` to rounding error.
``ramp_limit`` holds each step's velocity over that step, so its mean is its end value.

The filters' guarantees assume a base whose velocity stays between the period's start velocity
and the command (``instant``, ``ramp`` and ``ramp_limit`` do; ``lag`` too, but reaches the
command only asymptotically, so a plan that assumes each command is reached brakes too late).
"""

from __future__ import annotations

import math

import numpy as np

from safenav._checks import choice
from safenav.robot import RobotSpec

__all__ = ["BASE_MODELS", "period_velocities"]

BASE_MODELS = ("ramp_limit", "instant", "ramp", "lag")
"""Names of the base models (the first is the simulator's default)."""


def period_velocities(model: str, robot: RobotSpec, start: np.ndarray, command: np.ndarray, *, period: float,
                      substeps: int, time_constant: float) -> tuple[np.ndarray, np.ndarray]:
    """The base's velocity over one control period, physics step by physics step.

    Args:
        model: one of :data:`BASE_MODELS`.
        robot: the robot (velocity and acceleration limits).
        start: velocity ``(v, omega)`` at the start of the period [m/s, rad/s].
        command: the command held over the period, already within the velocity limits.
        period: the control period [s].
        substeps: physics steps per period.
        time_constant: ``tau`` of the ``"lag"`` model [s].

    Returns:
        ``(ends, means)``, two ``(substeps, 2)`` arrays: the velocity at the end of each
        physics step, and its mean over the step [m/s, rad/s].

    Raises:
        UnknownName: ``model`` is not a base model (the message lists them).
    """
    choice("base model", model, BASE_MODELS)
    start = np.asarray(start, dtype=float)
    command = np.asarray(command, dtype=float)
    h = period / substeps
    if model == "ramp_limit":
        ends = robot.ramp(command, start, h, substeps)
        return ends, ends.copy()
    if model == "instant":
        ends = np.tile(command, (substeps, 1))
        return ends, ends.copy()
    if model == "ramp":
        fraction = np.arange(1, substeps + 1, dtype=float)[:, None] / substeps
        change = command - start
        return start + fraction * change, start + (fraction - 0.5 / substeps) * change
    # lag: v(t) = c + (v0 - c) e^(-t/tau); over a step of h the mean is c + (v_begin - c) tau/h (1 - e^(-h/tau)).
    decay = math.exp(-h / time_constant)
    offsets = (start - command) * decay ** np.arange(substeps + 1, dtype=float)[:, None]
    return command + offsets[1:], command + offsets[:-1] * (time_constant / h) * -math.expm1(-h / time_constant)
