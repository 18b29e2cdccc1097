"""Real time and Python's garbage collector: the heap a control loop should not scan.

CPython's cyclic garbage collector now and then makes a *full* collection, which visits every object the
process holds: with numpy, casadi and the filters loaded that is about 28 000 objects and, on the development
machine, 10 ms; with numba's kernels too, 120 000 objects and 60 ms (``python -m benchmarks.filter_latency --gc``
measures it), longer than the period of a 20 ms loop and several times the MPC's compute budget there. It
happens at a call nobody chose.
:func:`settle` collects the garbage once and then freezes every object alive (:func:`gc.freeze`): later
collections skip them, and a full collection visits only what was made since (well under a millisecond
in the filters' loop). Every filter calls it at the end of its construction, once per process (the first
filter built); the objects alive then stay for the life of the process, as a robot's libraries do anyway.
``SAFENAV_GC_FREEZE=0`` in the environment turns it off.
"""

from __future__ import annotations

import gc
import os
import threading

__all__ = ["settle"]

_lock = threading.Lock()
_settled = False


def settle() -> bool:
    """Collect the garbage and freeze the heap, the first time in a process; whether it did so now."""
    global _settled
    with _lock:
        if _settled or os.environ.get("SAFENAV_GC_FREEZE", "1") == "0":
            return False
        _settled = True
        gc.collect()
        gc.freeze()
        return True
