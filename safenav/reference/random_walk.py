"""Seeded random commands within the robot's limits: the adversarial nominal for stress tests."""

from __future__ import annotations

import numpy as np

from safenav._checks import boolean, integer
from safenav.errors import InvalidConfig
from safenav.geometry import Pose2D
from safenav.reference.base import Policy, require_scan, robot_spec
from safenav.robot import Command, RobotSpec
from safenav.scan import LaserScan
from safenav.seeding import generator

__all__ = ["RandomWalk"]

STATES = ("idle", "new command", "hold")
"""The state names, for logging."""


class RandomWalk(Policy):
    """Random commands held for ``hold_steps`` calls each, blind to obstacles.

    Not a tutorial controller: an adversarial nominal for stress-testing safety filters.
    On the first call and every ``hold_steps`` calls after it, a new command is drawn with
    ``v`` uniform on ``[v_min, v_max)`` (``[0, v_max)`` with ``forward_only``) and ``omega``
    uniform on ``[-omega_max, omega_max)``, independently, from one
    :class:`numpy.random.Generator`, the ``policy`` stream of ``seed`` (:mod:`safenav.seeding`);
    in between, the command is held. The same seed gives the same command sequence.

    Attributes:
        robot: the robot whose velocity limits bound the commands.
        hold_steps: number of calls each command is held for.
        forward_only: when True, ``v`` is drawn from ``[0, v_max)`` (no reversing).
    """

    def __init__(self, robot: RobotSpec, *, hold_steps: int = 10, seed: int | None = None,
                 forward_only: bool = False) -> None:
        """Configure the policy.

        Args:
            robot: the robot (its velocity limits bound the commands).
            hold_steps: calls each command is held for, an integer >= 1.
            seed: the episode's seed, an integer >= 0 (commands draw from its ``policy`` stream);
                ``None`` draws fresh entropy.
            forward_only: draw ``v`` from ``[0, v_max)`` instead of ``[v_min, v_max)``.

        Raises:
            InvalidConfig: a value is out of range (the message names it).
        """
        owner = type(self).__name__
        self.robot = robot_spec(f"{owner}.robot", robot)
        self.hold_steps = integer(f"{owner}.hold_steps", hold_steps, low=1)
        self.forward_only = boolean(f"{owner}.forward_only", forward_only)
        lower = robot.lower.copy()
        if forward_only:
            lower[0] = 0.0
        self._lower, self._upper = lower, robot.upper
        self._rng = self._generator(seed)
        self._calls = 0
        self._command: Command | None = None

    @staticmethod
    def _generator(seed: int | None) -> np.random.Generator:
        try:
            return generator(seed, "policy")
        except InvalidConfig:
            raise InvalidConfig(f"RandomWalk seed must be None or a non-negative integer, got {seed!r}") from None

    @property
    def state(self) -> str:
        """``"idle"`` before the first call, ``"new command"`` on a call that drew one, ``"hold"`` otherwise."""
        if self._calls == 0:
            return STATES[0]
        return STATES[1] if (self._calls - 1) % self.hold_steps == 0 else STATES[2]

    @property
    def command(self) -> Command | None:
        """The command being held (``None`` before the first call)."""
        return self._command

    @property
    def calls(self) -> int:
        """Number of calls since construction or the last :meth:`reset`."""
        return self._calls

    def reset(self, seed: int | None = None) -> None:
        """Forget the held command, so the next call draws a new one.

        Args:
            seed: reseed the generator with it (the command sequence then repeats that of a
                policy built with ``seed``); ``None`` keeps the generator's stream going.
        """
        if seed is not None:
            self._rng = self._generator(seed)
        self._calls = 0
        self._command = None

    def __call__(self, scan: LaserScan, pose: Pose2D | None = None) -> Command:
        """The held command, drawing a new one every :attr:`hold_steps` calls.

        Args:
            scan: the latest scan (checked, then ignored).
            pose: unused.

        Raises:
            InvalidScanType: ``scan`` is not a :class:`~safenav.scan.LaserScan`.
        """
        require_scan(type(self).__name__, scan)
        if self._command is None or self._calls % self.hold_steps == 0:
            v, omega = self._rng.uniform(self._lower, self._upper)
            self._command = Command(float(v), float(omega))
        self._calls += 1
        return self._command
