"""Compiled kernels, whoever uses them: which path a setting selects, and a group of kernels built once a process.

Two groups: the filters' (:mod:`safenav.filters.kernels`) and the simulator's exact clearance
(:data:`safenav.worlds.shapes.COMPILED_GAPS`). Each keeps a numpy reference that gives the same numbers; a
setting ``"auto"`` (default), ``"numba"`` or ``"numpy"`` picks the path (:meth:`KernelGroup.select`), and
``SAFENAV_KERNELS=numba|numpy`` decides ``"auto"`` for a whole process. Light on purpose: the simulator
imports it without the filters.
"""

from __future__ import annotations

import os
import threading
import warnings
from collections.abc import Callable
from types import SimpleNamespace

import numpy as np

from safenav import _checks
from safenav._optional import require
from safenav.errors import SafeNavWarning

__all__ = ["KERNELS", "KernelGroup", "available", "frozen", "plain", "resolve"]

KERNELS = ("auto", "numba", "numpy")
"""Values of a ``kernels`` setting (the filters' configs, :class:`~safenav.sim_bullet.SimConfig`)."""


def available() -> bool:
    """Whether numba can be imported."""
    try:
        import numba  # noqa: F401
    except ImportError:
        return False
    return True


def resolve(name: str) -> str:
    """``"numba"`` or ``"numpy"``: the path ``name`` (one of :data:`KERNELS`) selects here."""
    if name == "auto":
        return "numba" if available() else "numpy"
    if name == "numba":
        require("numba", extra="fast", purpose="the compiled kernels (kernels='numba')")
    return name


def plain(array: np.ndarray, dtype: type = np.float64) -> np.ndarray:
    """``array`` as the kernels were compiled for it: C-contiguous, writable, of ``dtype`` (float64 unless asked: the
    index arrays are intp), a copy only when it is not."""
    if array.dtype == dtype and array.flags.c_contiguous and array.flags.writeable:
        return array
    return np.array(array, dtype=dtype, order="C")


def frozen(array: np.ndarray) -> np.ndarray:
    """``array`` read-only, as a scan's arrays are (and the kernels were compiled for)."""
    if not array.flags.writeable:
        return array
    view = array.view()
    view.flags.writeable = False
    return view


class KernelGroup:
    """Kernels compiled and warmed together, once a process, on the first :meth:`load`.

    Args:
        build: compiles and warms the kernels (every argument type the callers pass, so no call compiles).
        fallback: what happens without them, for the warning when ``"auto"`` cannot compile them.
    """

    def __init__(self, build: Callable[[], SimpleNamespace], fallback: str) -> None:
        self.build = build
        self.fallback = fallback
        self.compiled: SimpleNamespace | None = None
        self.failure: str | None = None     # why compiling failed in this process ("auto" then keeps to numpy)
        self._lock = threading.Lock()

    def load(self) -> SimpleNamespace:
        """The compiled kernels, built on the first call."""
        with self._lock:
            if self.compiled is None:
                self.compiled = self.build()
            return self.compiled

    def select(self, name: str, stacklevel: int = 3) -> SimpleNamespace | None:
        """The kernels a ``kernels=name`` setting uses: the compiled ones, or ``None`` for numpy.

        ``"auto"`` takes numba's when numba is installed and they compile; when they do not (an unsupported
        CPU, a broken LLVM), it warns once with the reason and keeps to numpy, which gives the same numbers.
        ``"numba"`` raises instead (:class:`~safenav.errors.MissingDependency` without numba). The environment
        variable ``SAFENAV_KERNELS`` (``numba`` or ``numpy``) decides for ``"auto"``.
        """
        if name == "auto" and os.environ.get("SAFENAV_KERNELS", "auto") != "auto":
            name = _checks.choice("SAFENAV_KERNELS", os.environ["SAFENAV_KERNELS"], KERNELS)
        if resolve(name) == "numpy":
            return None
        if name == "auto" and self.failure is not None:
            return None
        try:
            return self.load()
        except Exception as error:   # numba's compile errors have no common base; "auto" must still work
            if name != "auto":
                raise
            self.failure = f"{type(error).__name__}: {error}"
            warnings.warn(f"safenav's compiled kernels did not compile ({self.failure}); {self.fallback}",
                          SafeNavWarning, stacklevel=stacklevel)
            return None
