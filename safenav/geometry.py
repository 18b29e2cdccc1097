"""Planar geometry shared by every module: poses, angle wrapping, the unicycle step.

Frames follow REP-103: x forward, y left, yaw counter-clockwise [rad].
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

__all__ = ["Pose2D", "counter_clockwise", "is_convex", "unicycle_rollout", "unicycle_step", "wrap_angle"]

TWO_PI = 2.0 * math.pi


class Pose2D(NamedTuple):
    """A planar pose: position [m] and heading [rad], REP-103."""

    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0

    def compose(self, other: Pose2D) -> Pose2D:
        """The pose ``other`` (given in this pose's frame) expressed in this pose's parent frame."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return Pose2D(
            self.x + c * other.x - s * other.y,
            self.y + s * other.x + c * other.y,
            wrap_angle(self.yaw + other.yaw),
        )

    def inverse(self) -> Pose2D:
        """The pose of the parent frame expressed in this pose's frame."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return Pose2D(-c * self.x - s * self.y, s * self.x - c * self.y, wrap_angle(-self.yaw))

    def to_local(self, points: np.ndarray) -> np.ndarray:
        """Points ``(N, 2)`` in the parent frame [m], expressed in this pose's frame [m]."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        d = np.asarray(points, dtype=float) - (self.x, self.y)
        return np.column_stack((c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]))

    def to_parent(self, points: np.ndarray) -> np.ndarray:
        """Points ``(N, 2)`` in this pose's frame [m], expressed in the parent frame [m]."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        p = np.asarray(points, dtype=float)
        return np.column_stack((self.x + c * p[:, 0] - s * p[:, 1], self.y + s * p[:, 0] + c * p[:, 1]))


def counter_clockwise(polygon: np.ndarray) -> np.ndarray:
    """A copy of the polygon ``(V, 2)`` [m] with its vertices in counter-clockwise order."""
    polygon = np.asarray(polygon, dtype=float).reshape(-1, 2)
    following = np.concatenate((polygon[1:], polygon[:1]))     # each vertex's successor (np.roll, without its cost)
    area2 = np.sum(polygon[:, 0] * following[:, 1] - following[:, 0] * polygon[:, 1])
    return polygon[::-1].copy() if area2 < 0 else polygon.copy()


def is_convex(polygon: np.ndarray) -> bool:
    """Whether the polygon ``(V, 2)`` [m], in either orientation, is convex (no turn the other way)."""
    ordered = counter_clockwise(polygon)
    edges = np.roll(ordered, -1, axis=0) - ordered
    turns = edges[:, 0] * np.roll(edges[:, 1], -1) - edges[:, 1] * np.roll(edges[:, 0], -1)
    return bool(np.all(turns >= -1e-12))


def wrap_angle(angle: float | np.ndarray) -> float | np.ndarray:
    """Wrap an angle [rad] (or an array of them) into ``[-pi, pi)``."""
    if isinstance(angle, np.ndarray):
        return (angle + math.pi) % TWO_PI - math.pi
    return (float(angle) + math.pi) % TWO_PI - math.pi


def _sinc(x: float | np.ndarray) -> float | np.ndarray:
    """sin(x)/x, 1 at x = 0."""
    return np.sinc(np.asarray(x) / math.pi) if isinstance(x, np.ndarray) else (
        1.0 - x * x / 6.0 if abs(x) < 1e-4 else math.sin(x) / x
    )


def unicycle_step(pose: Pose2D, v: float, omega: float, dt: float) -> Pose2D:
    """Exact pose after holding ``(v, omega)`` for ``dt`` from ``pose``.

    The unicycle follows a circular arc (a straight segment when ``omega`` is 0):
    the chord has length ``v*dt*sinc(omega*dt/2)`` and points along
    ``yaw + omega*dt/2``, which is exact and free of the ``1/omega`` singularity.

    Args:
        pose: start pose [m, m, rad].
        v: linear velocity along the base x axis [m/s].
        omega: yaw rate [rad/s].
        dt: duration [s].

    Returns:
        The end pose, yaw wrapped into ``[-pi, pi)``.
    """
    half_turn = 0.5 * omega * dt
    chord = v * dt * _sinc(half_turn)
    heading = pose.yaw + half_turn
    return Pose2D(
        pose.x + chord * math.cos(heading),
        pose.y + chord * math.sin(heading),
        wrap_angle(pose.yaw + omega * dt),
    )


def unicycle_rollout(pose: Pose2D, commands: np.ndarray, dt: float) -> np.ndarray:
    """Poses reached by applying each command of ``commands`` for ``dt`` in turn.

    Args:
        pose: start pose [m, m, rad].
        commands: ``(N, 2)`` array of ``(v [m/s], omega [rad/s])``.
        dt: duration of each command [s].

    Returns:
        ``(N + 1, 3)`` array of poses ``(x, y, yaw)``, starting with ``pose``.
        Yaw is accumulated, not wrapped, so it is continuous.
    """
    commands = np.asarray(commands, dtype=float).reshape(-1, 2)
    turn = commands[:, 1] * dt
    yaw = pose.yaw + np.concatenate(([0.0], np.cumsum(turn)))
    chord = commands[:, 0] * dt * _sinc(0.5 * turn)
    heading = yaw[:-1] + 0.5 * turn
    x = pose.x + np.concatenate(([0.0], np.cumsum(chord * np.cos(heading))))
    y = pose.y + np.concatenate(([0.0], np.cumsum(chord * np.sin(heading))))
    return np.column_stack((x, y, yaw))
