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

__all__ = [
    "angle",
    "argument_type",
    "boolean",
    "choice",
    "duration",
    "integer",
    "is_real",
    "number",
    "optional_integer",
    "pair",
    "positive",
    "vector",
    "writable_file",
]


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


# ---------------------------------------------------------------------------------------------- appended checks
# Built on the checks above; they only add shapes those do not cover (angles, fixed-size vectors,
# optional integers, output files) and the adaptor that makes any check an argparse type.


def angle(name: str, value: Any, *, high: float, allow_zero: bool = False,
          error: type[SafeNavError] = InvalidConfig) -> float:
    """An angle [rad] in ``(0, high]`` (``[0, high]`` with ``allow_zero``), as a float."""
    result = number(name, value, error=error)
    if not 0.0 <= result <= high or (result == 0.0 and not allow_zero):
        raise error(f"{name} must be an angle in {'[0' if allow_zero else '(0'}, {high:.6g}] rad, got {value!r}")
    return result


def vector(name: str, value: Any, size: int, *, expected: str | None = None,
           error: type[SafeNavError] = InvalidConfig) -> tuple[float, ...]:
    """``size`` finite numbers (a sequence or a 1-D array, not a string) as a tuple of floats.

    Args:
        name: how the message names the setting.
        value: the value to check.
        size: how many numbers.
        expected: what the message says was expected (``"a pose (x [m], y [m], yaw [rad])"``);
            ``"a sequence of <size> finite numbers"`` by default.
        error: the exception class to raise.
    """
    import numpy as np

    text = expected or f"a sequence of {size} finite numbers"
    if isinstance(value, (str, bytes)) or not isinstance(value, (Sequence, np.ndarray)) or len(value) != size:
        raise error(f"{name} must be {text}, got {value!r}")
    return tuple(number(f"{name}[{index}]", item, error=error) for index, item in enumerate(value))


def optional_integer(name: str, value: Any, *, low: int | None = None, high: int | None = None,
                     error: type[SafeNavError] = InvalidConfig) -> int | None:
    """``None``, or an int within ``[low, high]`` (see :func:`integer`)."""
    if value is None:
        return None
    try:
        return integer(name, value, low=low, high=high, error=error)
    except error:
        bounds = _bound(low, high, False, False)
        raise error(f"{name} must be an integer{' ' + bounds if bounds else ''} or None, got {value!r}") from None


def writable_file(name: str, path: Any) -> Any:
    """``path`` as a :class:`pathlib.Path` once a file can be written there (parent folders are created).

    Checks by opening the file for appending, so a run that would write it at its end
    fails at its start instead; a file that did not exist is removed again.

    Raises:
        InvalidConfig: ``path`` is a folder, or the file cannot be created (the reason is in the message).
    """
    from pathlib import Path

    target = Path(path)
    if target.is_dir():
        raise InvalidConfig(f"{name} {str(path)!r} is a folder; expected the path of a file to write")
    existed = target.exists()
    blocking = next((folder for folder in target.parents if folder.exists() and not folder.is_dir()), None)
    if blocking is not None:
        raise InvalidConfig(f"cannot write {name} {str(path)!r}: {str(blocking)!r} is a file, not a folder")
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        with target.open("ab"):
            pass
    except OSError as exc:
        raise InvalidConfig(f"cannot write {name} {str(path)!r}: {exc.strerror or exc}") from None
    if not existed:
        target.unlink()
    return target


def argument_type(check: Any, *, name: str = "", text: bool = False, **bounds: Any) -> Any:
    """An argparse ``type=``: the text passed through ``check``.

    Unless ``text`` is set, the text is read as a number first: an ``int`` when it reads as
    one (so :func:`integer` accepts it and the message echoes it as typed), else a ``float``;
    what reads as neither goes to the check as a string, which rejects it. A failed check
    becomes :class:`argparse.ArgumentTypeError` with the check's message; argparse puts the
    option's name in front::

        parser.add_argument("--duration", type=argument_type(positive))
        # safenav run: error: argument --duration: must be a finite number > 0, got -1
        parser.add_argument("--robot", type=argument_type(choice, name="robot", text=True, known=PRESET_NAMES))
        # safenav run: error: argument --robot: unknown robot 'r2d2'; expected one of: m2wr, puzzlebot, rosbot

    Args:
        check: one of this module's checks taking ``(name, value, **bounds)``.
        name: the name the check's message starts with (empty: argparse names the option).
        text: give the check the text itself (names), not a number.
        **bounds: the check's keyword arguments (``low=1`` for :func:`integer`, ``known=`` for :func:`choice`).
    """
    import argparse

    def parse(argument: str) -> Any:
        value: Any = argument
        for kind in () if text else (int, float):
            try:
                value = kind(argument)
                break
            except ValueError:
                continue
        try:
            return check(name, value, **bounds)
        except SafeNavError as exc:
            raise argparse.ArgumentTypeError(str(exc).strip()) from None

    parse.__name__ = check.__name__   # argparse names the type in some of its own messages
    return parse
