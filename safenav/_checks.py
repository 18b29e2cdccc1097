"""Value checks shared by every config, spec and command-line type.

Each check returns the value converted (``float``, ``int``, ``bool``, tuple) or raises
``error`` (by default :class:`~safenav.errors.InvalidConfig`, a ``ValueError``) with a
message that names the setting, the bad value and what was expected::

    gamma = number("CBFConfig.gamma", value, low=0.0, high=1.0, low_open=True)

``bool`` is never accepted where a number is expected (``True`` is an ``int`` in Python,
and ``margin=True`` is a mistake, not ``1.0``).
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence
from typing import Any

from safenav.errors import InvalidConfig, SafeNavError

__all__ = ["boolean", "choice", "duration", "integer", "is_real", "number", "pair", "positive"]


def is_real(value: Any) -> bool:
    """Whether ``value`` is a real number (numpy scalars included) and not a ``bool``."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def _bound(low: float | None, high: float | None, low_open: bool, high_open: bool) -> str:
    parts = []
    if low is not None:
        parts.append(f"{'>' if low_open else '>='} {low:g}")
    if high is not None:
        parts.append(f"{'<' if high_open else '<='} {high:g}")
    return " and ".join(parts)


def number(name: str, value: Any, *, low: float | None = None, high: float | None = None,
           low_open: bool = False, high_open: bool = False, finite: bool = True,
           error: type[SafeNavError] = InvalidConfig) -> float:
    """``value`` as a float within the bounds, or ``error`` naming ``name``.

    Args:
        name: how the message names the setting (``"CBFConfig.gamma"``).
        value: the value to check.
        low: smallest allowed value (excluded with ``low_open``).
        high: largest allowed value (excluded with ``high_open``).
        finite: reject ``inf`` and ``NaN`` (``NaN`` is always rejected).
        error: the exception class to raise.
    """
    bounds = _bound(low, high, low_open, high_open)
    expected = f"a {'finite ' if finite else ''}number{' ' + bounds if bounds else ''}"
    if not is_real(value):
        raise error(f"{name} must be {expected}, got {value!r} of type {type(value).__name__}")
    result = float(value)
    if math.isnan(result) or (finite and math.isinf(result)):
        raise error(f"{name} must be {expected}, got {value!r}")
    if low is not None and (result < low or (low_open and result == low)):
        raise error(f"{name} must be {expected}, got {value!r}")
    if high is not None and (result > high or (high_open and result == high)):
        raise error(f"{name} must be {expected}, got {value!r}")
    return result


def positive(name: str, value: Any, *, error: type[SafeNavError] = InvalidConfig) -> float:
    """A finite number > 0."""
    return number(name, value, low=0.0, low_open=True, error=error)


def duration(name: str, value: Any, *, high: float | None = None,
             error: type[SafeNavError] = InvalidConfig) -> float:
    """A finite duration > 0 [s], at most ``high`` (a larger value is most likely milliseconds)."""
    result = positive(name, value, error=error)
    if high is not None and result > high:
        raise error(f"{name} must be a duration in seconds in (0, {high:g}], got {value!r}"
                    f"{' (milliseconds?)' if result >= 1.0 else ''}")
    return result


def integer(name: str, value: Any, *, low: int | None = None, high: int | None = None,
            error: type[SafeNavError] = InvalidConfig) -> int:
    """``value`` as an int within ``[low, high]``, or ``error`` naming ``name``."""
    bounds = _bound(low, high, False, False)
    expected = f"an integer{' ' + bounds if bounds else ''}"
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise error(f"{name} must be {expected}, got {value!r} of type {type(value).__name__}")
    result = int(value)
    if (low is not None and result < low) or (high is not None and result > high):
        raise error(f"{name} must be {expected}, got {value!r}")
    return result


def boolean(name: str, value: Any, *, error: type[SafeNavError] = InvalidConfig) -> bool:
    """``value`` if it is ``True`` or ``False`` (numpy booleans included)."""
    if isinstance(value, bool) or type(value).__name__ == "bool_":
        return bool(value)
    raise error(f"{name} must be True or False, got {value!r}")


def pair(name: str, value: Any, *, low: float | None = None, high: float | None = None,
         low_open: bool = False, error: type[SafeNavError] = InvalidConfig) -> tuple[float, float]:
    """Two numbers, each within the bounds, as a tuple of floats."""
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence) or len(value) != 2:
        raise error(f"{name} must be a pair of numbers, got {value!r}")
    return (number(f"{name}[0]", value[0], low=low, high=high, low_open=low_open, error=error),
            number(f"{name}[1]", value[1], low=low, high=high, low_open=low_open, error=error))


def choice(kind: str, value: Any, known: Sequence[str]) -> str:
    """``value`` if it is one of ``known``, else :class:`~safenav.errors.UnknownName` listing them."""
    from safenav.errors import UnknownName

    if not isinstance(value, str) or value not in known:
        raise UnknownName(kind, value, known)
    return value
