"""A safety shield for any agent: a Gymnasium ``ActionWrapper`` that filters every action.

The agent's action is the nominal command ``u_nom = (v, omega)``; the shield passes it, with
the environment's latest scan, measured velocity, odometry pose and time, through a safenav
safety filter and sends the filtered command to the environment::

    env = SafetyShield(gymnasium.make("safenav/GoToGoal-v0"))          # the CBF-QP filter
    env = SafetyShield(env, "mpc", horizon=30)                           # by name, with settings
    env = SafetyShield(env, CBFSafetyFilter(robot, dt=0.05, margin=0.1)) # or a filter instance
    env = SafetyShield(env, escape=True)                                 # with the deadlock escape

It works on any environment that implements the protocol of :mod:`safenav.gym.protocol`
(``safety_observation()``, plus ``robot`` and ``control_dt`` to build a filter by name) and
whose action space is a ``Box`` of shape ``(2,)`` holding ``(0, 0)``. A filter built by name
is given the robot's limits narrowed to the action space, so every command it sends lies
inside the wrapped environment's action space.

What it adds to each step:

* ``info["shield"]``: the step's :class:`~safenav.filters.FilterResult` as plain values
  (:func:`shield_info`): ``u_nom``, ``u``, ``status``, ``message``, ``escape`` (what the
  escape does instead of the agent's action, empty when it does not), ``reason`` (what bound
  the command, empty when nothing did), ``warnings``, ``modified``,
  ``intervention`` (``||u - u_nom||``), ``min_barrier`` and ``clearance`` (the filter's estimate
  from the scan [m]), and ``safety_change``: ``||u - reachable(u_nom)||``, where
  ``reachable(u_nom)`` is the agent's action clipped to what the base can reach within one
  period (its velocity limits, and its acceleration limits from the measured velocity), so
  only the change made for safety counts, not what the base would have done anyway. The
  result itself, with the solver and its timing, is :attr:`SafetyShield.last_result` (timings
  are left out of ``info`` so that the same seed gives the same infos; a filter's compute budget,
  half the period by default, brakes a call that a loaded machine delays past it, so for
  infos that depend on the seed alone give ``budget=math.inf``);
* an optional **intervention penalty** (off by default): with ``intervention_penalty=w`` the
  reward is lowered by ``w * safety_change`` [(m/s, rad/s)]; a non-finite action counts as
  the diagonal of the velocity limits. It teaches the agent to need the shield less; it does
  not change what the shield lets through.

``reset()`` also resets the filter (its memory of points, its clock and its warm starts).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from safenav._checks import boolean, number
from safenav._optional import require
from safenav.errors import InvalidConfig
from safenav.filters import FILTER_NAMES, FilterResult, SafetyFilter, escaped, make_filter
from safenav.filters.escape import Escape
from safenav.gym.errors import UnsupportedEnv
from safenav.gym.protocol import SafetyObservation, describe
from safenav.robot import RobotSpec

gymnasium = require("gymnasium", extra="gym", purpose="safenav's Gymnasium shield")

__all__ = ["SafetyShield", "shield_info"]

def shield_info(result: FilterResult, safety_change: float) -> dict[str, Any]:
    """The filter result of one step as plain values for ``info["shield"]`` (fresh arrays every call).

    Args:
        result: the filter's result.
        safety_change: ``||u - reachable(u_nom)||`` (module docstring).
    """
    return {
        "u_nom": np.array(result.u_nom, dtype=float),
        "u": np.array(result.u, dtype=float),
        "status": result.status.value,
        "message": result.message,
        "escape": result.escape,
        "reason": "" if result.reason is None else str(result.reason),
        "warnings": tuple(result.warnings),
        "modified": result.modified,
        "intervention": result.intervention,
        "min_barrier": float(result.min_barrier),
        "clearance": float(result.clearance),
        "safety_change": safety_change,
    }


def _wrapper_attr(env: Any, name: str) -> Any:
    """``name`` from the first layer of the wrapper stack that has it, or ``None``."""
    try:
        return env.get_wrapper_attr(name)
    except AttributeError:
        return None


def _narrowed(robot: RobotSpec, low: np.ndarray, high: np.ndarray) -> RobotSpec:
    """``robot`` with its velocity limits narrowed to the box ``[low, high]`` (which holds ``(0, 0)``)."""
    v_max, v_min = min(robot.v_max, float(high[0])), max(robot.v_min, float(low[0]))
    omega_max = min(robot.omega_max, float(high[1]), -float(low[1]))
    if (v_max, v_min, omega_max) == (robot.v_max, robot.v_min, robot.omega_max):
        return robot
    if v_max <= 0.0 or omega_max <= 0.0:
        raise UnsupportedEnv(f"SafetyShield: the action space [{low.tolist()}, {high.tolist()}] leaves robot "
                             f"{robot.name!r} no forward speed or no turn; expected v_max > 0 and a yaw rate range "
                             "around 0")
    return robot.replace(v_max=v_max, v_min=v_min, omega_max=omega_max)


class SafetyShield(gymnasium.ActionWrapper, gymnasium.utils.RecordConstructorArgs):
    """Filter every action of the agent through a safenav safety filter (see the module docstring).

    Args:
        env: the environment; it (or a wrapper in its stack) implements the shield protocol.
        filter: a filter name (``"cbf"``, ``"mpc"``, ``"zones"``), built for the environment's
            ``robot`` and ``control_dt`` with ``filter_settings``, or a
            :class:`~safenav.filters.SafetyFilter` (or :class:`~safenav.filters.escape.Escape`)
            instance (its ``dt`` must equal the
            environment's ``control_dt`` when it has one; an environment re-made from
            ``env.spec`` shares the instance, a name gives each its own filter).
        escape: wrap the filter in the liveness escape (:class:`~safenav.filters.escape.Escape`
            with its default settings): when the filter holds the robot in a deadlock, an escape
            command replaces the agent's action until its way is clear, and passes through the
            same filter (safety unchanged, only progress). A filter built by name is then built as
            ``"<name>+escape"``, with :data:`safenav.filters.ESCAPE_PRESETS` under ``filter_settings``
            (the MPC tracks the CBF's answer). For other settings pass ``Escape(filter, ...)`` as
            ``filter``.
        intervention_penalty: weight of the intervention penalty (module docstring), >= 0; 0 is off.
        **filter_settings: settings of a filter built by name (fields of its config).

    Raises:
        UnsupportedEnv: ``env`` lacks the protocol, or its action space is not a ``Box`` of
            shape ``(2,)`` holding ``(0, 0)``.
        UnknownName: an unknown filter name (the message lists them).
        InvalidConfig: a bad setting, a filter whose period or limits do not match the environment.
    """

    def __init__(self, env: Any, filter: str | SafetyFilter | Escape = "cbf", *, escape: bool = False,
                 intervention_penalty: float = 0.0, **filter_settings: Any) -> None:
        gymnasium.utils.RecordConstructorArgs.__init__(self, filter=filter, escape=escape,
                                                        intervention_penalty=intervention_penalty, **filter_settings)
        super().__init__(env)
        self._source = _wrapper_attr(env, "safety_observation")
        if not callable(self._source):
            raise UnsupportedEnv(f"SafetyShield: {describe(env)} does not implement the shield protocol; expected a "
                                 "method safety_observation() -> SafetyObservation (see safenav.gym.protocol)")
        space = env.action_space
        if not isinstance(space, gymnasium.spaces.Box) or space.shape != (2,):
            raise UnsupportedEnv(f"SafetyShield: {describe(env)} has action space {space}; expected a Box of shape "
                                 "(2,) holding (v [m/s], omega [rad/s])")
        self._low, self._high = space.low.astype(float), space.high.astype(float)
        if np.any(self._low > 0.0) or np.any(self._high < 0.0):
            raise UnsupportedEnv(f"SafetyShield: the action space {space} of {describe(env)} does not hold the stop "
                                 "command (0, 0); a shield must be able to stop")
        self.intervention_penalty = number("SafetyShield.intervention_penalty", intervention_penalty, low=0.0)
        with_escape = boolean("SafetyShield.escape", escape)
        if with_escape and isinstance(filter, str) and filter in FILTER_NAMES:
            filter = escaped(filter)     # by name: the filter inside the escape gets its presets (ESCAPE_PRESETS)
        chosen = self._make_filter(env, filter, filter_settings)
        wrap = with_escape and not isinstance(chosen, Escape)
        self.filter: SafetyFilter | Escape = Escape(chosen) if wrap else chosen
        self._result: FilterResult | None = None
        self._velocity: np.ndarray | None = None

    def _make_filter(self, env: Any, chosen: str | SafetyFilter | Escape,
                     settings: dict[str, Any]) -> SafetyFilter | Escape:
        control_dt = _wrapper_attr(env, "control_dt")
        if isinstance(chosen, (SafetyFilter, Escape)):
            if settings:
                raise InvalidConfig(f"SafetyShield: settings {sorted(settings)} apply to a filter built by name; "
                                    "give them to the filter instance instead")
            if control_dt is not None and abs(chosen.dt - control_dt) > 1e-12:
                raise InvalidConfig(f"SafetyShield: the filter's dt={chosen.dt!r} differs from the control period "
                                    f"{control_dt!r} of {describe(env)}; make the filter with dt={control_dt!r}")
            lower, upper = chosen.robot.lower, chosen.robot.upper
            if np.any(lower < self._low) or np.any(upper > self._high):
                raise InvalidConfig(f"SafetyShield: the filter's velocity limits [{lower.tolist()}, {upper.tolist()}] "
                                    f"exceed the action space [{self._low.tolist()}, {self._high.tolist()}] of "
                                    f"{describe(env)}; give the filter a robot within it (RobotSpec.replace)")
            return chosen
        robot = _wrapper_attr(env, "robot")
        if not isinstance(chosen, str):
            raise InvalidConfig(f"SafetyShield: filter must be a name ({', '.join(FILTER_NAMES[1:])}), a "
                                f"SafetyFilter or an Escape, got {chosen!r}")
        if chosen == "none":
            raise InvalidConfig("SafetyShield: filter='none' makes no shield; use the environment unwrapped")
        if not isinstance(robot, RobotSpec) or control_dt is None:
            raise UnsupportedEnv(f"SafetyShield: building filter {chosen!r} by name needs the robot (a RobotSpec) and "
                                 f"control_dt [s] of {describe(env)}, which it does not expose; pass a SafetyFilter "
                                 "instance instead")
        return make_filter(chosen, _narrowed(robot, self._low, self._high), control_dt, **settings)

    @property
    def last_result(self) -> FilterResult | None:
        """The filter result of the latest action (``None`` before the first)."""
        return self._result

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict]:
        """Reset the environment and the filter (memory, clock, warm starts)."""
        self.filter.reset()
        self._result = None
        return self.env.reset(seed=seed, options=options)

    def action(self, action: Any) -> np.ndarray:
        """The filtered command for the agent's ``action`` (``u_nom``), inside the action space.

        Raises:
            InvalidCommand: ``action`` is not a pair of numbers.
            UnsupportedEnv: ``safety_observation()`` did not return a ``SafetyObservation``.
        """
        observation = self._source()
        if not isinstance(observation, SafetyObservation):
            raise UnsupportedEnv(f"SafetyShield: safety_observation() of {describe(self.env)} returned "
                                 f"{type(observation).__name__}; expected a SafetyObservation")
        self._velocity = observation.velocity
        self._result = self.filter.filter(action, observation.scan, velocity=observation.velocity,
                                          pose=observation.pose, now=observation.time)
        return np.asarray(self._result.u, dtype=self.action_space.dtype)

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict]:
        """Filter ``action``, step the environment with the result, and report what the filter did."""
        observation, reward, terminated, truncated, info = self.env.step(self.action(action))
        change = self._safety_change(self._result, self._velocity)
        info = {**info, "shield": shield_info(self._result, change)}
        if self.intervention_penalty > 0.0:
            reward = float(reward) - self.intervention_penalty * change
        return observation, reward, terminated, truncated, info

    def _safety_change(self, result: FilterResult, velocity: np.ndarray | None) -> float:
        """``||u - reachable(u_nom)||``: the change made for safety, not by the base's own limits."""
        robot = self.filter.robot
        if not np.all(np.isfinite(result.u_nom)):
            return float(np.hypot(*(robot.upper - robot.lower)))
        known = velocity is not None and bool(np.all(np.isfinite(velocity)))
        reachable = robot.clip(result.u_nom, velocity, self.filter.dt) if known else robot.clip(result.u_nom)
        return float(np.hypot(*(result.u - reachable)))
