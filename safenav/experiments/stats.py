"""Statistics of experiments: Wilson intervals, and one record per cell aggregated from its episodes."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from safenav.errors import InvalidConfig
from safenav.experiments.specs import Cell

if TYPE_CHECKING:
    from safenav.episode import EpisodeMetrics
    from safenav.experiments.runner import EpisodeOutcome

__all__ = ["DEADLOCK_LIMIT", "cell_record", "cell_records", "pooled_records", "wilson_interval"]

DEADLOCK_LIMIT = 5.0
"""An episode counts as deadlocked when its longest deadlock lasts longer than this [s]
(:attr:`~safenav.episode.EpisodeMetrics.longest_deadlock`, see :func:`safenav.episode.liveness`)."""

Z95 = 1.959963984540054
"""The 97.5 % quantile of the standard normal distribution."""


def wilson_interval(successes: int, trials: int, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion (95 % by default).

    Unlike the normal approximation it stays inside [0, 1] and is not empty at 0 or n
    successes: 0 collisions in 10 episodes gives [0, 0.278].

    Args:
        successes: events counted (collisions).
        trials: episodes.
        z: the normal quantile of the confidence level (1.96 for 95 %).

    Raises:
        InvalidConfig: ``trials`` < 1 or ``successes`` outside ``[0, trials]``.
    """
    if trials < 1 or not 0 <= successes <= trials:
        raise InvalidConfig(f"wilson_interval needs 0 <= successes <= trials and trials >= 1, "
                            f"got {successes}/{trials}")
    p = successes / trials
    denominator = 1.0 + z * z / trials
    centre = (p + z * z / (2 * trials)) / denominator
    half = z / denominator * math.sqrt(p * (1.0 - p) / trials + z * z / (4 * trials * trials))
    # The bounds are exactly 0 at 0 successes and 1 at n; say so rather than keep the rounding error.
    low = 0.0 if successes == 0 else float(np.clip(centre - half, 0.0, 1.0))
    high = 1.0 if successes == trials else float(np.clip(centre + half, 0.0, 1.0))
    return low, high


def _finite_or_none(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def cell_record(cell: Cell, robot: str, metrics: Sequence[EpisodeMetrics],
                seeds: Sequence[int] | None = None, wall_times: Sequence[float] | None = None) -> dict[str, Any]:
    """Aggregate the episodes of one cell.

    Args:
        cell: the cell.
        robot: the preset that ran it.
        metrics: one per episode.
        seeds: the episodes' seeds, for the record.
        wall_times: the episodes' wall-clock times [s], for the record.

    Returns:
        A JSON-ready record (``None`` where a value does not apply):

        * ``episodes``, ``collisions``, ``collision_rate`` and its Wilson 95 % interval ``collision_rate_ci``;
        * ``min_clearance``: ``min``, ``p5`` and ``median`` over the episodes of each episode's smallest
          body clearance [m] (negative: overlap);
        * ``intervention``: mean over the episodes of the mean ``||u - u_nom||``;
        * ``distance``: mean path length [m]; ``progress``: the mean goal progress [m] where there is
          a goal, else the mean distance (``progress_kind`` says which);
        * ``goal_success``, ``goal_reached``, ``time_to_goal`` (``mean``, ``median`` over the successes [s]);
        * ``stuck_time``: mean time the nominal wanted to move and the robot did not
          (:attr:`safenav.episode.EpisodeConfig.stuck_speed`) [s], and
          ``stuck_fraction`` of the episode time;
        * ``fallbacks``: periods in which the filter braked because its optimiser failed (total);
        * ``deadlocked_episodes``, ``deadlock_rate`` and its Wilson 95 % interval ``deadlock_rate_ci``:
          episodes whose longest deadlock lasted longer than :data:`DEADLOCK_LIMIT`;
          ``deadlock_time``: mean total deadlocked time per episode [s] (deadlocks of at least the
          episode's ``deadlock_time``, see :func:`safenav.episode.liveness`), ``deadlock_time_total``
          summed over the episodes [s]; ``deadlocked_seeds``;
        * ``escapes_started``, ``escapes_succeeded``: summed over the episodes; ``escape_time``: mean
          time an escape drove per episode [s];
        * ``omega_chatter``: mean over the episodes of the mean ``|Δomega| / dt`` [rad/s^2];
          ``v_reversals``: mean over the episodes of the sign changes of ``v`` per second [1/s];
          ``nominal_omega_chatter``: mean over the episodes of the nominal's own [rad/s^2];
          ``escape_omega_chatter``: mean over the episodes in which an escape drove of the commands'
          while it drove [rad/s^2] (``None`` when none did);
        * ``filter_p50_us``, ``filter_p99_us``, ``filter_calls``: every filter call of the cell pooled [us];
        * ``episode_wall_s``: mean wall-clock time of an episode [s] (``None`` without ``wall_times``);
        * ``statuses``: filter statuses summed over the episodes; ``collided_seeds``.

    Raises:
        InvalidConfig: no episodes.
    """
    if not metrics:
        raise InvalidConfig(f"cell {cell} has no episodes")
    seeds = list(range(len(metrics))) if seeds is None else [int(seed) for seed in seeds]
    episodes = len(metrics)
    collided = [bool(m.collided) for m in metrics]
    collisions = sum(collided)
    clearance = np.array([m.min_clearance for m in metrics], dtype=float)
    distance = float(np.mean([m.distance for m in metrics]))
    has_goal = metrics[0].goal_reached is not None
    times = [m.time_to_goal for m in metrics if m.goal_reached]
    filter_times = np.concatenate([m.filter_times for m in metrics])
    deadlocked = [m.longest_deadlock > DEADLOCK_LIMIT for m in metrics]
    escaping = [m.escape_omega_chatter for m in metrics if math.isfinite(m.escape_omega_chatter)]
    statuses: dict[str, int] = {}
    for m in metrics:
        for status, count in m.statuses.items():
            statuses[status] = statuses.get(status, 0) + count
    return {
        "scenario": cell.scenario,
        "robot": robot,
        "policy": cell.policy,
        "filter": cell.filter,
        "episodes": episodes,
        "collisions": collisions,
        "collision_rate": collisions / episodes,
        "collision_rate_ci": list(wilson_interval(collisions, episodes)),
        "min_clearance": {"min": float(clearance.min()), "p5": float(np.percentile(clearance, 5)),
                          "median": float(np.median(clearance))},
        "intervention": float(np.mean([m.mean_intervention for m in metrics])),
        "distance": distance,
        "progress": float(np.mean([m.goal_progress for m in metrics])) if has_goal else distance,
        "progress_kind": "goal_progress" if has_goal else "distance",
        "goal_success": len(times) / episodes if has_goal else None,
        "goal_reached": len(times) if has_goal else None,
        "time_to_goal": {"mean": float(np.mean(times)), "median": float(np.median(times))} if times else None,
        "stuck_time": float(np.mean([m.stuck_time for m in metrics])),
        "stuck_fraction": float(np.mean([m.stuck_time / m.time if m.time > 0 else 0.0 for m in metrics])),
        "fallbacks": int(sum(m.fallbacks for m in metrics)),
        "filter_calls": int(filter_times.size),
        "filter_p50_us": _finite_or_none(float(np.median(filter_times)) * 1e6) if filter_times.size else None,
        "filter_p99_us": _finite_or_none(float(np.percentile(filter_times, 99)) * 1e6) if filter_times.size
        else None,
        "deadlocked_episodes": sum(deadlocked),
        "deadlock_rate": sum(deadlocked) / episodes,
        "deadlock_rate_ci": list(wilson_interval(sum(deadlocked), episodes)),
        "deadlock_time": float(np.mean([m.deadlock_time for m in metrics])),
        "deadlock_time_total": float(np.sum([m.deadlock_time for m in metrics])),
        "escapes_started": int(sum(m.escapes_started for m in metrics)),
        "escapes_succeeded": int(sum(m.escapes_succeeded for m in metrics)),
        "escape_time": float(np.mean([m.escape_time for m in metrics])),
        "omega_chatter": float(np.mean([m.omega_chatter for m in metrics])),
        "v_reversals": float(np.mean([m.v_reversals for m in metrics])),
        "nominal_omega_chatter": float(np.mean([m.nominal_omega_chatter for m in metrics])),
        "escape_omega_chatter": float(np.mean(escaping)) if escaping else None,
        "episode_wall_s": float(np.mean(wall_times)) if wall_times else None,
        "statuses": dict(sorted(statuses.items())),
        "seeds": seeds,
        "collided_seeds": [seed for seed, hit in zip(seeds, collided, strict=True) if hit],
        "deadlocked_seeds": [seed for seed, hit in zip(seeds, deadlocked, strict=True) if hit],
    }


def cell_records(outcomes: Sequence[EpisodeOutcome]) -> list[dict[str, Any]]:
    """One :func:`cell_record` per cell, cells in order of first appearance, episodes in seed order."""
    groups: dict[Cell, list[EpisodeOutcome]] = {}
    for outcome in outcomes:
        groups.setdefault(outcome.spec.cell, []).append(outcome)
    records = []
    for cell, group in groups.items():
        group = sorted(group, key=lambda outcome: outcome.spec.seed)
        records.append(cell_record(cell, group[0].robot, [o.metrics for o in group], [o.spec.seed for o in group],
                                   [o.wall_time for o in group]))
    return records


_POOLED_MEANS = ("intervention", "stuck_time", "deadlock_time", "escape_time", "omega_chatter", "v_reversals",
                 "nominal_omega_chatter")
"""Per-episode means of a cell record that pool as means weighted by the cells' episodes."""

_POOLED_SUMS = ("episodes", "collisions", "deadlocked_episodes", "escapes_started", "escapes_succeeded", "fallbacks")
"""Counts of a cell record that pool as sums."""


def pooled_records(records: Sequence[dict[str, Any]],
                   key: Callable[[dict[str, Any]], tuple[str, ...]]) -> list[dict[str, Any]]:
    """Cell records pooled into groups: the episodes of every cell of a group taken together.

    Args:
        records: cell records from :func:`cell_records`.
        key: the group of a record, e.g. ``lambda r: (r["filter"],)``.

    Returns:
        One record per group, groups in order of first appearance: ``group`` (the key), ``cells``,
        the sums of ``episodes``, ``collisions``, ``deadlocked_episodes``, ``escapes_started``,
        ``escapes_succeeded`` and ``fallbacks``; the episode-weighted means of ``intervention``,
        ``stuck_time``, ``deadlock_time``, ``escape_time``, ``omega_chatter``, ``v_reversals`` and
        ``nominal_omega_chatter``;
        ``collision_rate``, ``deadlock_rate`` and their Wilson 95 % intervals; ``goal_reached``
        and ``goal_episodes`` over the cells that have a goal (``None`` when none has);
        ``collided`` and ``deadlocked``: ``(scenario, seed)`` of every such episode.
    """
    groups: dict[tuple[str, ...], list[dict[str, Any]]] = {}
    for record in records:
        groups.setdefault(tuple(key(record)), []).append(record)
    pooled = []
    for group, members in groups.items():
        weights = np.array([member["episodes"] for member in members], dtype=float)
        result: dict[str, Any] = {"group": list(group), "cells": len(members)}
        result.update({name: int(sum(member[name] for member in members)) for name in _POOLED_SUMS})
        result.update({name: float(np.average([member[name] for member in members], weights=weights))
                       for name in _POOLED_MEANS})
        for rate, count in (("collision_rate", "collisions"), ("deadlock_rate", "deadlocked_episodes")):
            result[rate] = result[count] / result["episodes"]
            result[f"{rate}_ci"] = list(wilson_interval(result[count], result["episodes"]))
        goals = [member for member in members if member["goal_success"] is not None]
        result["goal_reached"] = sum(member["goal_reached"] for member in goals) if goals else None
        result["goal_episodes"] = sum(member["episodes"] for member in goals) if goals else None
        result["collided"] = [[member["scenario"], seed] for member in members for seed in member["collided_seeds"]]
        result["deadlocked"] = [[member["scenario"], seed] for member in members
                                for seed in member["deadlocked_seeds"]]
        pooled.append(result)
    return pooled
