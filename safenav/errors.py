"""Exceptions raised by safenav.

Every exception derives from :class:`SafeNavError` *and* from the built-in
exception a caller would expect, so both ``except SafeNavError`` and
``except ValueError`` (or ``TypeError``) catch it. Messages name the bad value
and what was expected.

Safety filters do not raise inside the control loop for a scan they can still
act on: they brake and say why in :attr:`safenav.filters.FilterResult.status`.
Exceptions are for structural mistakes (a scan whose fields contradict each
other, a command of the wrong shape, an unknown preset name).
"""

from __future__ import annotations

from collections.abc import Iterable

__all__ = [
    "InvalidCommand",
    "InvalidCommandType",
    "InvalidConfig",
    "InvalidScan",
    "InvalidScanType",
    "LidarMismatch",
    "LidarMismatchWarning",
    "MissingDependency",
    "SafeNavError",
    "SafeNavWarning",
    "SimulatorError",
    "UnknownName",
]


class SafeNavError(Exception):
    """Root of every exception raised by safenav."""


class InvalidScan(SafeNavError, ValueError):
    """A laser scan whose fields are missing, inconsistent or out of range."""


class InvalidScanType(InvalidScan, TypeError):
    """A laser-scan field of the wrong type (a string, ``None``, nested lists)."""


class LidarMismatch(SafeNavError, ValueError):
    """A scan that contradicts the robot's description of its lidar.

    Raised by :meth:`safenav.robot.RobotSpec.match_scan` when a scan's beam layout, range
    limits, no-return convention or explicit mount disagrees with the lidar that should have
    taken it (or names no lidar of the robot). The message gives both values and the fix.
    """


class InvalidCommand(SafeNavError, ValueError):
    """A velocity command ``(v, omega)`` (or a call's measured velocity or odometry pose) of the wrong shape."""


class InvalidCommandType(InvalidCommand, TypeError):
    """A velocity command (or a call's measured velocity or odometry pose) that is not made of real numbers."""


class InvalidConfig(SafeNavError, ValueError):
    """A configuration value (robot spec, filter or simulator setting) out of range."""


class UnknownName(SafeNavError, ValueError):
    """A name (preset, world, policy, filter, solver) that is not registered.

    The message lists the known names.
    """

    def __init__(self, kind: str, name: object, known: Iterable[str], hint: str = "") -> None:
        self.kind = kind
        self.name = name
        self.known = tuple(sorted(known))
        self.hint = hint
        message = f"unknown {kind} {name!r}; expected one of: {', '.join(self.known)}"
        if hint:
            message += f" ({hint})"
        super().__init__(message)

    def __reduce__(self) -> tuple[type, tuple[str, object, tuple[str, ...], str]]:
        # Rebuild from the constructor's arguments, so the error survives a trip between processes.
        return type(self), (self.kind, self.name, self.known, self.hint)


class SimulatorError(SafeNavError, RuntimeError):
    """The simulator was used out of order (stepped before ``reset()``, or after ``close()``)."""


class SafeNavWarning(UserWarning):
    """Root of every warning issued by safenav."""


class LidarMismatchWarning(SafeNavWarning):
    """A scan that contradicts the robot's lidar, accepted because the caller opted out.

    Issued by :meth:`safenav.robot.RobotSpec.match_scan` with ``strict=False``, once per
    robot and cause, instead of :class:`LidarMismatch`.
    """


class MissingDependency(SafeNavError, ImportError):
    """An optional dependency is not installed; the message gives the exact pip line.

    Args:
        package: the missing distribution (``"pybullet"``).
        purpose: what needs it (``"the PyBullet simulator"``).
        extra: the safenav extra that installs it (``"sim"``); without one the message
            names the package itself.
    """

    def __init__(self, package: str, purpose: str, extra: str | None = None) -> None:
        self.package = package
        self.purpose = purpose
        self.extra = extra
        line = f'pip install "safenav[{extra}]"' if extra else f"pip install {package}"
        super().__init__(f"{purpose} needs the optional package {package!r}: {line}")

    def __reduce__(self) -> tuple[type, tuple[str, str, str | None]]:
        return type(self), (self.package, self.purpose, self.extra)
