"""Markdown tables of cell records: what happened (deterministic) and how long it took (wall clock)."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from types import MappingProxyType
from typing import Any

from safenav._checks import choice

__all__ = ["FILTER_LABELS", "LIVENESS_COLUMNS", "SAFETY_COLUMNS", "markdown", "outcome_table", "summary_table",
           "timing_table"]

FILTER_LABELS: Mapping[str, str] = MappingProxyType(
    {"none": "naive (no filter)", "zones": "zones", "cbf": "CBF-QP", "mpc": "MPC",
     "zones+escape": "zones + escape", "cbf+escape": "CBF-QP + escape", "mpc+escape": "MPC + escape"})
"""How tables, legends and the demo name each filter."""


def markdown(headers: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    """A GitHub-flavoured markdown table of already formatted cells."""
    lines = ["| " + " | ".join(headers) + " |", "|" + "|".join("---" for _ in headers) + "|"]
    lines += ["| " + " | ".join(str(value) for value in row) + " |" for row in rows]
    return "\n".join(lines)


def _number(value: float | None, digits: int = 2) -> str:
    return "–" if value is None else f"{value:.{digits}f}"


def _rate(record: dict[str, Any]) -> str:
    low, high = record["collision_rate_ci"]
    return f"{record['collision_rate']:.2f} [{low:.2f}, {high:.2f}]"


def _clearance(record: dict[str, Any]) -> str:
    clearance = record["min_clearance"]
    return f"{clearance['min']:.3f} / {clearance['p5']:.3f} / {clearance['median']:.3f}"


def _progress(record: dict[str, Any]) -> str:
    return f"{record['progress']:.2f}" + (" (goal)" if record["progress_kind"] == "goal_progress" else "")


def _goal(record: dict[str, Any]) -> str:
    if record["goal_success"] is None:
        return "–"
    text = f"{record['goal_reached']}/{record['episodes']}"
    return text + (f" in {record['time_to_goal']['median']:.1f} s" if record["time_to_goal"] else "")


def _escapes(record: dict[str, Any]) -> str:
    return f"{record['escapes_succeeded']}/{record['escapes_started']}"


_COLUMNS: Mapping[str, Callable[[dict[str, Any]], Any]] = MappingProxyType({
    "scenario": lambda r: r["scenario"],
    "robot": lambda r: r["robot"],
    "policy": lambda r: r["policy"],
    "filter": lambda r: r["filter"],
    "episodes": lambda r: r["episodes"],
    "collisions": lambda r: r["collisions"],
    "rate [95% CI]": _rate,
    "clearance min / p5 / median [m]": _clearance,
    "intervention": lambda r: f"{r['intervention']:.3f}",
    "progress [m]": _progress,
    "goal reached": _goal,
    "stuck [s]": lambda r: f"{r['stuck_time']:.1f}",
    "fallbacks": lambda r: r["fallbacks"],
    "deadlocks > 5 s": lambda r: f"{r['deadlocked_episodes']}/{r['episodes']}",
    "deadlocked [s]": lambda r: f"{r['deadlock_time']:.1f}",
    "escapes ok/started": _escapes,
    "chatter [rad/s²]": lambda r: f"{r['omega_chatter']:.2f}",
    "nominal's chatter": lambda r: f"{r['nominal_omega_chatter']:.2f}",
    "chatter escaping": lambda r: "–" if r["escape_omega_chatter"] is None else f"{r['escape_omega_chatter']:.2f}",
    "v reversals [1/s]": lambda r: f"{r['v_reversals']:.2f}",
})
"""How each column of :func:`outcome_table` is formatted from a cell record."""


def outcome_table(records: Sequence[dict[str, Any]], columns: Sequence[str] | None = None) -> str:
    """What happened in each cell, as markdown (no wall-clock numbers: the same seeds give the same table).

    Progress is the goal progress [m] in goal scenarios (marked "goal"), else the distance
    travelled; intervention is the mean ``||u - u_nom||``; stuck is the mean time [s] the
    nominal wanted to move and the robot did not; deadlocks > 5 s counts the episodes with a
    deadlock longer than :data:`~safenav.experiments.stats.DEADLOCK_LIMIT`, deadlocked is the
    mean deadlocked time per episode [s]; escapes ok/started are summed over the episodes;
    chatter is the mean ``|Δomega| / dt`` [rad/s²] and v reversals the sign changes of the
    commanded speed per second (:func:`safenav.episode.liveness`).

    Args:
        records: cell records from :func:`cell_records`.
        columns: the columns to show, in order (all when ``None``): scenario, robot, policy,
            filter, episodes, collisions, rate [95% CI], clearance min / p5 / median [m],
            intervention, progress [m], goal reached, stuck [s], fallbacks, deadlocks > 5 s,
            deadlocked [s], escapes ok/started, chatter [rad/s²], v reversals [1/s].

    Raises:
        UnknownName: an unknown column.
    """
    columns = list(_COLUMNS) if columns is None else list(columns)
    for column in columns:
        choice("table column", column, tuple(_COLUMNS))
    return markdown(columns, [[_COLUMNS[column](record) for column in columns] for record in records])


def timing_table(records: Sequence[dict[str, Any]]) -> str:
    """Filter call times [us] and episode times [s] of each cell (wall clock: they vary with the machine's load)."""
    rows = [[record["scenario"], record["policy"], record["filter"], record["filter_calls"],
             _number(record["filter_p50_us"], 0), _number(record["filter_p99_us"], 0),
             _number(record["episode_wall_s"], 2)]
            for record in records]
    return markdown(["scenario", "policy", "filter", "filter calls", "filter p50 [us]", "filter p99 [us]",
                     "episode [s]"], rows)


SAFETY_COLUMNS = ("scenario", "robot", "policy", "filter", "episodes", "collisions", "rate [95% CI]",
                  "clearance min / p5 / median [m]", "intervention", "progress [m]", "fallbacks")
"""The columns of :func:`outcome_table` about safety and intervention."""

LIVENESS_COLUMNS = ("scenario", "policy", "filter", "goal reached", "stuck [s]", "deadlocks > 5 s", "deadlocked [s]",
                    "escapes ok/started", "chatter [rad/s²]", "nominal's chatter", "chatter escaping",
                    "v reversals [1/s]")
"""The columns of :func:`outcome_table` about progress: goals, stuck and deadlocked time, escapes, chatter (the
commands', the nominal's along the same path, the commands' while an escape drove)."""


def summary_table(pooled: Sequence[dict[str, Any]], group_names: Sequence[str]) -> str:
    """Pooled records (:func:`~safenav.experiments.stats.pooled_records`) as markdown, one row per group.

    Args:
        pooled: the pooled records.
        group_names: the header of each part of the group key (``["scenarios", "filter"]``).
    """
    rows = []
    for record in pooled:
        goals = "–" if record["goal_reached"] is None else f"{record['goal_reached']}/{record['goal_episodes']}"
        rows.append([*record["group"], record["episodes"], record["collisions"], goals,
                     f"{record['stuck_time']:.1f}", f"{record['deadlocked_episodes']}/{record['episodes']}",
                     f"{record['deadlock_time']:.1f}", f"{record['escapes_succeeded']}/{record['escapes_started']}",
                     f"{record['omega_chatter']:.2f}", f"{record['v_reversals']:.2f}",
                     f"{record['intervention']:.2f}"])
    return markdown([*group_names, "episodes", "collisions", "goals reached", "mean stuck [s]", "deadlocks > 5 s",
                     "deadlocked [s]", "escapes ok/started", "chatter [rad/s²]", "v reversals [1/s]",
                     "intervention"], rows)
