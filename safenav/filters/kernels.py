"""Compiled kernels of the filters' per-call arithmetic: the same numbers as the numpy code they mirror.

The filters' numpy code works on arrays of a few dozen points; a call then spends most of its time in
numpy's per-operation overhead (about a hundred operations a call), not in arithmetic. With numba
installed (``pip install "safenav[fast]"``) eleven pieces run as compiled loops instead
(:mod:`safenav.filters._compiled_rows`):

* the CBF's obstacle rows of the disk and cover bodies with the cut: ``cbf_distances`` (every point's distance, the
  cut's ceiling and the body's clearance), ``cbf_cut`` (the points the cut keeps, and the smallest barrier of those
  it leaves out), ``pair_minima`` (every point's
  smallest barrier, which sets how far the cut reaches) and ``obstacle_rows`` (the kept pairs' tilted
  half-planes, then the barrier, braking and sweep rows and their ramp corners, in the order
  :mod:`~safenav.filters.rows` stacks them);
* what each beam of a scan reads (``scan_readings``: :attr:`~safenav.scan.LaserScan.readings`, seeded by
  :func:`~safenav.filters.perception.classify`) and the points its hits give (``hit_points``,
  :func:`~safenav.filters.perception.beam_points`), the edges of what obstacles hide (``shadow_beams``,
  :func:`~safenav.filters.perception.shadow_points`);
* which remembered points a scan shows again or contradicts, and where those it cannot see may still be
  (``seen_again``, :meth:`~safenav.filters.perception.PointMemory.recall`: every point's beam, the beams its
  uncertainty fans over, the narrowing beyond an edge of the field of view; ``memory_recall``: the whole recall
  with one scan taken at once);
* the MPC's direct SQP: the clearance rows' values at an iterate, the QP's rows and the check of each
  answer (``sqp_values``, ``sqp_clearance_rows``, ``sqp_violated``, :class:`~safenav.filters.mpc.DirectSQP`);
* the MPC's verification of a plan (``plan_check``, :meth:`~safenav.filters.MPCSafetyFilter.check_plan`): the
  rollout, every body disk at every knot against every point, the bounds and the acceleration rows;
* the zones' test of which points lie inside the stop and slowdown polygons (``inside_polygon``,
  :func:`~safenav.filters.body.inside_polygon`, :class:`~safenav.filters.ZonesFilter`);
* the working sets' nearest point per angular bin (``nearest_per_bin``,
  :func:`~safenav.filters.perception.nearest_per_bin`: the MPC's point slots, the CBF's first working set);
* the CBF's decision around its QPs (``cbf_screen``, ``cbf_qp_rows``, ``cbf_violated``, ``cbf_answer``, ``cbf_stage``:
  the rows that can bind, each QP's rows, the rows an answer misses, the answer's check and the row that bound it,
  a slack tier's rows; the numpy references are :mod:`safenav.filters.cbf`'s functions of the same names without
  the prefix ``cbf``);
* DAQP's arrays (``daqp_arrays``: the bounds of the simple bounds and rows and their flags) and the reading of its
  answer (``daqp_answer``), :class:`~safenav.filters.qp.DirectDAQP`'s for either filter;
* where a turning lidar was at each beam of a scan of known age (``sweep_poses``,
  :func:`~safenav.filters.perception.sweep_poses`), and from which beam's pose the memory looks at each remembered
  point (``sweep_shift``, :func:`~safenav.filters.perception.sweep_shift`).

The numpy code stays the reference: each kernel names the function it mirrors, and
``tests/filters/test_kernels.py`` checks that both give the same rows to rounding on random problems, the
same commands and plans in closed loop and on the recorded MPC problems, the same plan checks on random plans. The
polygon body and the cut's reference (``cut=False``, which the contract checker compares against) always use numpy.

``kernels`` in the filters' configs picks the path (:func:`select`): ``"auto"`` (numba when installed and
it compiles; ``SAFENAV_KERNELS=numpy`` or ``numba`` decides for a whole process), ``"numba"`` (raises
:class:`~safenav.errors.MissingDependency` with the pip line when absent) or ``"numpy"``. The kernels are
compiled for the exact argument types the filters pass when the first filter is built (about 5 s, then
about 1 s from numba's cache on disk), so no control call compiles. The selection itself (:func:`select`, the
warning of ``"auto"``, ``SAFENAV_KERNELS``) is :class:`safenav._kernels.KernelGroup`'s, which the simulator's
compiled clearance (:attr:`safenav.sim_bullet.SimConfig.kernels`) shares.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from safenav import _kernels
from safenav._optional import require

__all__ = ["KERNELS", "available", "frozen", "load", "plain", "resolve", "select"]

KERNELS = _kernels.KERNELS
"""Values of ``kernels`` in :class:`~safenav.filters.CBFConfig`, :class:`~safenav.filters.MPCConfig` and
:class:`~safenav.filters.ZonesConfig`."""

available, resolve, plain, frozen = _kernels.available, _kernels.resolve, _kernels.plain, _kernels.frozen

#: The filters' kernels (built by :func:`_build`, looked up when first loaded, so that a test can replace it).
GROUP = _kernels.KernelGroup(lambda: _build(), "the filters use numpy (the same rows, slower)")


def select(name: str) -> SimpleNamespace | None:
    """The kernels a filter configured with ``kernels=name`` uses: the compiled ones, or ``None`` for numpy.

    ``"auto"`` takes numba's when numba is installed and they compile; when they do not (an unsupported
    CPU, a broken LLVM), it warns once with the reason and keeps to numpy, which gives the same rows.
    ``"numba"`` raises instead (:class:`~safenav.errors.MissingDependency` without numba). The environment
    variable ``SAFENAV_KERNELS`` (``numba`` or ``numpy``) decides for ``"auto"`` (a whole process, a ROS node,
    a benchmark run, without changing any config).
    """
    return GROUP.select(name, stacklevel=4)


def load() -> SimpleNamespace:
    """The compiled kernels (``pair_minima``, ``obstacle_rows``, ...), compiled and warmed on the first call."""
    return GROUP.load()


def _build() -> SimpleNamespace:
    require("numba", extra="fast", purpose="the compiled kernels (kernels='numba')")
    from safenav.filters import _compiled_rows

    kernels = SimpleNamespace(**{name: getattr(_compiled_rows, name) for name in (
        "cbf_distances", "cbf_cut", "pair_minima", "obstacle_rows", "scan_readings", "hit_points", "shadow_beams",
        "sqp_values", "sqp_clearance_rows", "sqp_violated", "plan_check", "seen_again", "memory_recall",
        "inside_polygon", "nearest_per_bin", "sweep_poses", "sweep_shift", "cbf_screen", "cbf_qp_rows", "cbf_violated",
        "cbf_answer", "cbf_stage", "daqp_arrays", "daqp_answer")})
    _warm(kernels)
    return kernels


def _warm(kernels: SimpleNamespace) -> None:
    """Compile every kernel for the argument types the filters pass (plain float64 arrays, read-only scan arrays,
    float scalars): one specialisation each."""
    points, uncertainty = np.array([[0.5, 0.1], [0.6, -0.2]]), np.zeros(2)
    control, offsets = np.array([[0.1, 0.0]]), np.array([0.3])
    for centred in (True, False):
        distance, _, _ = kernels.cbf_distances(points, uncertainty, control, offsets, centred, 0.1)
    kernels.cbf_cut(points, uncertainty, distance, 0.5, 1.0, control, offsets, 0.1, 0.05)
    per_point = kernels.pair_minima(points, uncertainty, control, offsets)
    box = np.array([-0.5, -1.0]), np.array([0.5, 1.0])
    z = np.array([-0.5, -1.0, 0.0, 0.0]), np.array([0.5, 1.0, 0.5, 1.0])
    kernels.obstacle_rows(points, uncertainty, control, offsets, per_point, 1.0, 0.5, 0.1, 0.01, 0.2, 0.2, 0.05,
                          float(per_point.min()), True, np.array([0.2, 0.1]), 1.0, 2.0, 0.05, 0.01, 1.0, box[0], box[1],
                          0.5, z[0], z[1])
    # the CBF's decision: two rows, one used
    G, h, index = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]]), np.array([0.3, 0.2]), np.arange(2)
    kernels.cbf_screen(G, h, index, index, z[0], z[1], 1e-6)
    working = np.ones(2, dtype=np.bool_)
    kernels.cbf_qp_rows(G, h, G, h, np.zeros(2), working, True)
    kernels.cbf_violated(G, h, working, 0.0, np.zeros(5), working, 1e-7)
    kernels.cbf_answer(G, h, h, index, index, np.zeros(4), np.zeros(4), index, 2, 3, 1e-6)
    kernels.cbf_stage(h, index, index, h, h, 0.02, 1, 3, 0, False)
    # DAQP's arrays: one-sided and two-sided rows, cold and warm
    kernels.daqp_arrays(z[0], z[1], h, np.zeros(0), np.zeros(0, dtype=np.int8), np.zeros(3, dtype=np.int32), 5)
    kernels.daqp_arrays(z[0], z[1], h, -h, np.zeros(6, dtype=np.int8), np.zeros(3, dtype=np.int32), 5)
    kernels.daqp_answer(np.zeros(4), np.zeros(6))
    ranges = frozen(np.array([1.0, 3.0, np.inf]))
    hits = kernels.scan_readings(ranges, 0.1, 10.0, 0, 1, 2, 3)[1]
    for mask in (hits, frozen(hits)):    # the kernel's own, and a scan's numpy one (read-only)
        kernels.hit_points(ranges, frozen(mask), frozen(np.ones(3)), frozen(np.zeros(3)), 0.0, 0.0)
    kernels.shadow_beams(frozen(np.array([1.0, 3.0, np.inf])), frozen(np.array([0, 0, 1], dtype=np.int8)), 0, 1, 2.0,
                         0.05, 0.3, True)
    kernels.seen_again(frozen(np.array([1.0, 3.0, np.inf])), frozen(np.array([0, 0, 1], dtype=np.int8)), 0, 1, 10.0,
                       -1.0, 1.0, 0.0, 0.0, 0.0, False, True, points, np.full(2, 0.02), np.full(2, 0.1))
    for spread in (True, False):
        kernels.memory_recall(points, np.zeros(2), 0.1, 0.0, 1.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.0, spread, 5.0, 0.02,
                              frozen(np.array([1.0, 3.0, np.inf])), frozen(np.array([0, 0, 1], dtype=np.int8)), 0, 1,
                              10.0, -1.0, 1.0, 0.0, 0.0, 0.0, False, True)
    # the MPC's SQP: two points, one knot's two disks, two knot variables and one slack per point
    centres, jacobian, radii = np.array([[0.1, 0.2], [0.0, 0.1]]), np.ones((2, 2, 2)), np.full((2, 2), 0.3)
    dx, dy, values, working, candidates = kernels.sqp_values(centres, points, 1.0 / radii, radii,
                                                             np.zeros(4, dtype=np.int8), 0.2, 1.0)
    matrix = np.zeros((1 + 2, 5))
    kernels.sqp_clearance_rows(np.array([0, 3], dtype=np.intp), 2, jacobian, dx, dy, 1.0 / radii, radii, values,
                               np.zeros(2), matrix, 1, 2, np.array([3, 4], dtype=np.intp))
    kernels.sqp_violated(jacobian, np.zeros(2), dx, dy, 1.0 / radii, values, radii, 0.0, np.zeros(2), candidates,
                         working, 1e-9, True)
    kernels.inside_polygon(np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]), points)
    kernels.nearest_per_bin(np.array([0.1, -2.0]), np.array([0.5, 0.2]), 4)
    kernels.sweep_poses(np.array([0.1, 0.05]), np.array([0.0, 0.06]), np.array([[0.06, 0.5, 1.0]]),
                        np.zeros((2, 3)), 0.1, 0.0, 0.0)
    kernels.sweep_shift(points, frozen(np.zeros((3, 3))), 0.1, 0.0, 0.0, -1.0, 1.0, 3)
    # the MPC's check of a plan: two periods, one disk
    commands, bounds = np.zeros((2, 2)), np.ones((2, 2))
    kernels.plan_check(commands, commands, np.zeros(2), 0.5, 0.5, 0.05, 0.1, np.zeros((1, 2)), points, np.zeros((2, 1)),
                       np.zeros((2, 1)), -bounds, bounds, np.ones((1, 2)))
