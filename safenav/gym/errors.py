"""Exceptions of the Gymnasium layer (each a :class:`~safenav.errors.SafeNavError` and the matching built-in)."""

from __future__ import annotations

from safenav.errors import SafeNavError

__all__ = ["FeatureUnavailable", "UnsupportedEnv"]


class UnsupportedEnv(SafeNavError, TypeError):
    """An environment the shield cannot guard: it lacks the protocol, or its action space is not ``(v, omega)``."""


class FeatureUnavailable(SafeNavError, NotImplementedError):
    """A documented option whose implementation this version of safenav does not have yet; the message names it."""
