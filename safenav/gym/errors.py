"""Exceptions of the Gymnasium layer (each a :class:`~safenav.errors.SafeNavError` and the matching built-in)."""

from __future__ import annotations

from safenav.errors import SafeNavError

__all__ = ["UnsupportedEnv"]


class UnsupportedEnv(SafeNavError, TypeError):
    """An environment the shield cannot guard: it lacks the protocol, or its action space is not ``(v, omega)``."""
