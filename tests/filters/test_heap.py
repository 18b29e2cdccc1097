"""safenav.filters.heap: the first filter of a process freezes the heap, so full collections skip it."""

from __future__ import annotations

import gc
import subprocess
import sys
import textwrap

from safenav.filters import heap


def test_settle_freezes_once_and_can_be_turned_off(monkeypatch):
    monkeypatch.setattr(heap, "_settled", False)
    monkeypatch.setenv("SAFENAV_GC_FREEZE", "0")
    assert heap.settle() is False and heap._settled is False
    monkeypatch.delenv("SAFENAV_GC_FREEZE")
    assert heap.settle() is True
    assert gc.get_freeze_count() > 0
    assert heap.settle() is False


def test_building_a_filter_leaves_full_collections_short():
    """In a fresh process: after the first filter is built, a full collection visits only what was made since
    (a few thousand objects at most), not the ~1e5 objects numpy, casadi, numba and the filters hold."""
    script = textwrap.dedent("""
        import gc
        from safenav import preset
        from safenav.filters import MPCSafetyFilter
        MPCSafetyFilter(preset("m2wr"), 0.02)
        print(gc.get_freeze_count(), len(gc.get_objects()))
    """)
    frozen, visited = map(int, subprocess.run([sys.executable, "-c", script], check=True, capture_output=True,
                                              text=True).stdout.split())
    assert frozen > 50_000
    assert visited < 0.1 * frozen
