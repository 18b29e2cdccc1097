"""Experiments: many seeded episodes run in parallel, aggregated per cell, as tables and figures.

An experiment is a list of :class:`EpisodeSpec` (plain names and a seed, so a spec can be
sent to another process), run by :func:`run_specs` on a pool of processes, each of which
builds its own PyBullet client. The outcomes come back in the order of the specs, whatever
the number of workers, so the same specs give the same numbers. :func:`cell_records`
aggregates the episodes of each :class:`Cell` (scenario, policy, filter) into one record:
collision rate with a Wilson interval, clearance, intervention, progress, stuck time,
fallbacks and filter times::

    from safenav.experiments import cell_records, episode_specs, matrix, outcome_table, run_specs

    cells = matrix(scenarios=["stop_at_wall"], filters=["none", "cbf"])
    outcomes = run_specs(episode_specs(cells, seeds=range(5)), workers=2)
    print(outcome_table(cell_records(outcomes)))

``safenav demo`` and ``safenav bench collisions`` (``benchmarks/collision_rates.py``) are
built on it.
"""

from __future__ import annotations

import dataclasses
import math
import os
import sys
import time
from collections.abc import Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Circle

from safenav.errors import InvalidConfig, UnknownName
from safenav.filters import FILTER_NAMES, make_filter
from safenav.reference import POLICY_NAMES
from safenav.render import plot_world
from safenav.robot import PRESET_NAMES, RobotSpec, preset
from safenav.scenarios import SCENARIO_NAMES, Scenario, scenario
from safenav.worlds import World

if TYPE_CHECKING:
    from safenav.episode import EpisodeMetrics, Trajectory

__all__ = [
    "DEMO_CASES",
    "FILTER_COLORS",
    "FILTER_LABELS",
    "Cell",
    "EpisodeOutcome",
    "EpisodeSpec",
    "available_filters",
    "cell_record",
    "cell_records",
    "collision_point",
    "draw_overlay",
    "episode_specs",
    "markdown",
    "matrix",
    "outcome_table",
    "overlay_figure",
    "run_spec",
    "run_specs",
    "scenario_for",
    "timing_table",
    "wilson_interval",
]

DEMO_CASES = (("stop_at_wall", "stop_at_wall_buggy"), ("obstacle_avoidance", "obstacle_avoidance"),
              ("wall_follower", "wall_follower"))
"""The ``(scenario, policy)`` pairs of ``safenav demo``: the three tutorials, the first one as published."""

FILTER_COLORS = {"none": "#d62728", "zones": "#ff7f0e", "cbf": "#1f77b4", "mpc": "#2ca02c"}
"""Line colour of each filter in the figures."""

FILTER_LABELS = {"none": "naive (no filter)", "zones": "zones", "cbf": "CBF-QP", "mpc": "MPC"}
"""Legend label of each filter."""

_FILTER_DASHES = {"zones": (0, (6, 2, 1, 2)), "mpc": (0, (4, 2))}
"""Line style of each filter in the overlays (solid otherwise), so that coinciding paths all show."""

_Z95 = 1.959963984540054
"""The 97.5 % quantile of the standard normal distribution."""


# ---------------------------------------------------------------------------------------------- specs


@dataclass(frozen=True, order=True)
class Cell:
    """One cell of an experiment matrix: a scenario, a nominal policy, a filter.

    Attributes:
        scenario: a name from :data:`~safenav.scenarios.SCENARIO_NAMES`.
        policy: one of that scenario's policies.
        filter: a name from :data:`~safenav.filters.FILTER_NAMES`.
    """

    scenario: str
    policy: str
    filter: str


@dataclass(frozen=True)
class EpisodeSpec:
    """Everything that defines one episode, as plain values that can be sent to another process.

    Attributes:
        scenario: the scenario (robot, world drawn from the seed, duration).
        policy: the nominal policy.
        filter: the safety filter (``"none"`` for the naive robot).
        seed: seeds the world, the start perturbation, the policy and the simulator noise.
        duration: episode length [s]; the scenario's own when ``None``.
        robot: a preset that replaces the scenario's robot, or ``None``.
        record: keep the per-step trajectory.
        record_scans: keep the scans too (for animations).
        gui: open the PyBullet GUI.
        sim_options: extra :class:`~safenav.sim_bullet.SimConfig` fields as ``(name, value)``
            pairs (noise, dropout, latency, ...).
        filter_options: extra filter settings as ``(name, value)`` pairs (``margin``, ...).
    """

    scenario: str
    policy: str
    filter: str
    seed: int
    duration: float | None = None
    robot: str | None = None
    record: bool = False
    record_scans: bool = False
    gui: bool = False
    sim_options: tuple[tuple[str, Any], ...] = ()
    filter_options: tuple[tuple[str, Any], ...] = ()

    @property
    def cell(self) -> Cell:
        """The cell the episode belongs to."""
        return Cell(self.scenario, self.policy, self.filter)


@dataclass(frozen=True, eq=False)
class EpisodeOutcome:
    """One episode's spec and what happened.

    Attributes:
        spec: the episode.
        robot: the preset that ran it.
        metrics: the episode's metrics.
        trajectory: the per-step record when ``spec.record``, else ``None``.
        wall_time: wall-clock time of the episode [s].
    """

    spec: EpisodeSpec
    robot: str
    metrics: EpisodeMetrics
    trajectory: Trajectory | None
    wall_time: float


def scenario_for(name: str, robot: str | None = None, policy: str | None = None) -> Scenario:
    """The scenario ``name``, optionally with another robot or a policy it does not list.

    Args:
        name: a scenario name.
        robot: a preset that replaces the scenario's robot (``None``: keep it).
        policy: a policy to allow besides the scenario's own (``None``: only those).

    Raises:
        UnknownName: an unknown scenario, robot or policy (the message lists the known names).
        InvalidConfig: ``go_to_goal`` in a scenario whose world has no goal.
    """
    base = scenario(name)
    if robot is not None and robot not in PRESET_NAMES:
        raise UnknownName("robot", robot, PRESET_NAMES)
    if policy is not None and policy not in POLICY_NAMES:
        raise UnknownName("policy", policy, POLICY_NAMES)
    if policy == "go_to_goal" and base.world(0).goal is None:
        raise InvalidConfig(f"policy 'go_to_goal' needs a world with a goal, and scenario {name!r} has none")
    changes: dict[str, Any] = {}
    if robot is not None and robot != base.robot_name:
        changes["robot_name"] = robot
    if policy is not None and policy not in base.policies:
        changes["policies"] = (*base.policies, policy)
    return dataclasses.replace(base, **changes) if changes else base


def matrix(scenarios: Iterable[str] | None = None, policies: Iterable[str] | None = None,
           filters: Iterable[str] | None = None) -> list[Cell]:
    """The cells of a sweep: every selected scenario with each of its selected policies, times every filter.

    Args:
        scenarios: scenario names (all of :data:`~safenav.scenarios.SCENARIO_NAMES` when ``None``).
        policies: keep only these policies (all when ``None``); a scenario keeps the ones it lists.
        filters: filter names (all of :data:`~safenav.filters.FILTER_NAMES` when ``None``).

    Returns:
        The cells in registry order: scenarios, then their policies, then filters.

    Raises:
        UnknownName: an unknown scenario, policy or filter.
        InvalidConfig: the selection leaves no cell.
    """
    scenario_names = list(SCENARIO_NAMES if scenarios is None else scenarios)
    policy_names = None if policies is None else list(policies)
    filter_names = list(FILTER_NAMES if filters is None else filters)
    for name in scenario_names:
        scenario(name)
    for name in policy_names or ():
        if name not in POLICY_NAMES:
            raise UnknownName("policy", name, POLICY_NAMES)
    for name in filter_names:
        if name not in FILTER_NAMES:
            raise UnknownName("filter", name, FILTER_NAMES)
    cells = [Cell(name, policy, filter_name)
             for name in scenario_names
             for policy in scenario(name).policies if policy_names is None or policy in policy_names
             for filter_name in filter_names]
    if not cells:
        raise InvalidConfig(f"no scenario among {', '.join(scenario_names)} runs any of the policies "
                            f"{', '.join(policy_names or ())}")
    return cells


def episode_specs(cells: Iterable[Cell], seeds: Iterable[int], duration: float | None = None,
                  record_seeds: Iterable[int] = ()) -> list[EpisodeSpec]:
    """One spec per cell and seed, in cell order then seed order.

    Args:
        cells: the cells.
        seeds: the seeds of every cell (the same seed draws the same world in every filter).
        duration: episode length [s] for every scenario; each scenario's own when ``None``.
        record_seeds: seeds whose trajectory is recorded (for figures).
    """
    seed_list = [int(seed) for seed in seeds]
    recorded = {int(seed) for seed in record_seeds}
    return [EpisodeSpec(cell.scenario, cell.policy, cell.filter, seed, duration, record=seed in recorded)
            for cell in cells for seed in seed_list]


def available_filters(names: Iterable[str]) -> tuple[list[str], dict[str, str]]:
    """Split filter names into those that can be built here and those whose module is missing.

    Returns:
        The usable names (in the given order), and the unusable ones with the import error.

    Raises:
        UnknownName: an unknown filter.
    """
    robot = preset(PRESET_NAMES[0])
    usable, missing = [], {}
    for name in names:
        try:
            make_filter(name, robot, 0.05)
        except ImportError as error:
            missing[name] = str(error)
        else:
            usable.append(name)
    return usable, missing


# ---------------------------------------------------------------------------------------------- running


def run_spec(spec: EpisodeSpec) -> EpisodeOutcome:
    """Run one episode from its spec (in this process, with its own simulator).

    Raises:
        UnknownName: a name in the spec is not registered.
        InvalidConfig: the names do not go together (``go_to_goal`` without a goal).
    """
    # Imported here, not at the top, so that checking names does not load PyBullet (it prints a banner).
    from safenav.episode import EpisodeConfig, run_episode
    from safenav.sim_bullet import SimConfig

    task = scenario_for(spec.scenario, spec.robot, spec.policy)
    robot = task.robot
    world = task.world(spec.seed)
    policy = task.policy(spec.policy, world, spec.seed)
    sim = SimConfig(gui=spec.gui, **dict(spec.sim_options))
    config = EpisodeConfig(duration=task.duration if spec.duration is None else spec.duration, sim=sim)
    safety_filter = make_filter(spec.filter, robot, sim.control_dt, **dict(spec.filter_options))
    start = time.perf_counter()
    result = run_episode(world, robot, policy, safety_filter, config=config, seed=spec.seed,
                         record=spec.record or spec.record_scans, record_scans=spec.record_scans)
    return EpisodeOutcome(spec, robot.name, result.metrics, result.trajectory, time.perf_counter() - start)


def _cost(spec: EpisodeSpec) -> float:
    """A rough relative cost, to start the longest episodes first (a shorter tail)."""
    duration = scenario(spec.scenario).duration if spec.duration is None else spec.duration
    return duration * {"none": 0.5, "mpc": 3.0}.get(spec.filter, 1.0)


def run_specs(specs: Sequence[EpisodeSpec], workers: int | None = None, *, progress: bool = True,
              description: str = "episodes") -> list[EpisodeOutcome]:
    """Run every spec, on ``workers`` processes, with a progress bar on stderr.

    Each episode depends only on its spec, so the outcomes do not depend on the number of
    workers or on the order in which they finish.

    Args:
        specs: the episodes.
        workers: processes (``None``: one per core; 1 runs in this process).
        progress: show a tqdm progress bar on stderr.
        description: the progress bar's label.

    Returns:
        The outcomes, in the order of ``specs``.

    Raises:
        InvalidConfig: ``workers`` < 1.
    """
    from tqdm import tqdm

    workers = (os.cpu_count() or 1) if workers is None else workers
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise InvalidConfig(f"workers must be an integer >= 1, got {workers!r}")
    # Names are checked here, before any episode starts (and because UnknownName does not survive
    # the trip back from a worker process: it cannot be unpickled).
    for scenario_name, robot, policy, filter_name in dict.fromkeys((s.scenario, s.robot, s.policy, s.filter)
                                                                   for s in specs):
        scenario_for(scenario_name, robot, policy)
        if filter_name not in FILTER_NAMES:
            raise UnknownName("filter", filter_name, FILTER_NAMES)
    outcomes: list[EpisodeOutcome | None] = [None] * len(specs)
    with tqdm(total=len(specs), desc=description, unit="ep", file=sys.stderr, disable=not progress,
              dynamic_ncols=True) as bar:
        if workers == 1 or len(specs) <= 1:
            for index, spec in enumerate(specs):
                outcomes[index] = run_spec(spec)
                bar.update()
        else:
            order = sorted(range(len(specs)), key=lambda i: -_cost(specs[i]))
            with ProcessPoolExecutor(max_workers=min(workers, len(specs))) as pool:
                futures = {pool.submit(run_spec, specs[index]): index for index in order}
                try:
                    for future in as_completed(futures):
                        outcomes[futures[future]] = future.result()
                        bar.update()
                except BaseException:
                    # An episode failed or the user pressed Ctrl-C: do not start the queued ones.
                    pool.shutdown(wait=True, cancel_futures=True)
                    raise
    return [outcome for outcome in outcomes if outcome is not None]


# ---------------------------------------------------------------------------------------------- statistics


def wilson_interval(successes: int, trials: int, z: float = _Z95) -> tuple[float, float]:
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
        * ``stuck_time``: mean time the nominal wanted to move and the robot did not [s], and
          ``stuck_fraction`` of the episode time;
        * ``fallbacks``: periods in which the filter braked because its optimiser failed (total);
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
        "episode_wall_s": float(np.mean(wall_times)) if wall_times else None,
        "statuses": dict(sorted(statuses.items())),
        "seeds": seeds,
        "collided_seeds": [seed for seed, hit in zip(seeds, collided, strict=True) if hit],
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


# ---------------------------------------------------------------------------------------------- tables


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


_COLUMNS = {
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
}
"""How each column of :func:`outcome_table` is formatted from a cell record."""


def outcome_table(records: Sequence[dict[str, Any]], columns: Sequence[str] | None = None) -> str:
    """What happened in each cell, as markdown (no wall-clock numbers: the same seeds give the same table).

    Progress is the goal progress [m] in goal scenarios (marked "goal"), else the distance
    travelled; intervention is the mean ``||u - u_nom||``; stuck is the mean time [s] the
    nominal wanted to move and the robot did not.

    Args:
        records: cell records from :func:`cell_records`.
        columns: the columns to show, in order (all when ``None``): scenario, robot, policy,
            filter, episodes, collisions, rate [95% CI], clearance min / p5 / median [m],
            intervention, progress [m], goal reached, stuck [s], fallbacks.

    Raises:
        UnknownName: an unknown column.
    """
    columns = list(_COLUMNS) if columns is None else list(columns)
    for column in columns:
        if column not in _COLUMNS:
            raise UnknownName("table column", column, _COLUMNS)
    return markdown(columns, [[_COLUMNS[column](record) for column in columns] for record in records])


def timing_table(records: Sequence[dict[str, Any]]) -> str:
    """Filter call times [us] and episode times [s] of each cell (wall clock: they vary with the machine's load)."""
    rows = [[record["scenario"], record["policy"], record["filter"], record["filter_calls"],
             _number(record["filter_p50_us"], 0), _number(record["filter_p99_us"], 0),
             _number(record["episode_wall_s"], 2)]
            for record in records]
    return markdown(["scenario", "policy", "filter", "filter calls", "filter p50 [us]", "filter p99 [us]",
                     "episode [s]"], rows)


# ---------------------------------------------------------------------------------------------- figures


def collision_point(outcome: EpisodeOutcome) -> np.ndarray | None:
    """Where the base was when the body first touched an obstacle ``(x, y)`` [m], from the trajectory."""
    metrics, trajectory = outcome.metrics, outcome.trajectory
    if trajectory is None or metrics.collision_time is None:
        return None
    index = int(np.searchsorted(trajectory.time, metrics.collision_time - 1e-9))
    return trajectory.pose[min(index, len(trajectory.pose) - 1), :2]


def draw_overlay(ax: Axes, world: World, robot: RobotSpec, outcomes: Sequence[EpisodeOutcome],
                 title: str | None = None, legend_ax: Axes | None = None) -> Axes:
    """Draw several recorded episodes of the same world and seed on one axes, one colour per filter.

    Each trajectory ends with the body outline; a collision is a large cross where it
    happened. The legend says, per filter, whether it collided and its minimum clearance.

    Args:
        ax: the axes to draw on.
        world: the world the episodes ran in.
        robot: the robot (body radius).
        outcomes: recorded episodes.
        title: the axes title.
        legend_ax: an empty axes to hold the legend (it is hidden); the legend goes inside
            ``ax`` when ``None``.

    Raises:
        InvalidConfig: an outcome was run without ``record``.
    """
    plot_world(world, ax)
    handles: list[Any] = []
    for outcome in outcomes:
        if outcome.trajectory is None:
            raise InvalidConfig(f"episode {outcome.spec} was not recorded; run it with record=True")
        name = outcome.spec.filter
        color = FILTER_COLORS.get(name, "black")
        pose = outcome.trajectory.pose
        metrics = outcome.metrics
        # The naive path is drawn wide and pale underneath, so a filter that leaves it unchanged shows as
        # a coloured line inside a red band rather than hiding it.
        naive = name == "none"
        width, alpha, layer = (4.5, 0.45, 2) if naive else (1.6, 0.95, 3)
        style = _FILTER_DASHES.get(name, "-")
        ax.plot(pose[:, 0], pose[:, 1], color=color, linewidth=width, alpha=alpha, zorder=layer, linestyle=style,
                solid_capstyle="round")
        ax.add_patch(Circle((pose[-1, 0], pose[-1, 1]), robot.radius, fill=False, edgecolor=color, linewidth=1.2,
                            zorder=4))
        hit = collision_point(outcome)
        if hit is not None:
            ax.plot(*hit, marker="X", markersize=13, color=color, markeredgecolor="black", linestyle="none",
                    zorder=5)
            note = f"collided at {metrics.collision_time:.1f} s"
        else:
            note = f"min clearance {100 * metrics.min_clearance:.0f} cm"
        handles.append(Line2D([], [], color=color, linewidth=width, alpha=alpha, linestyle=style,
                              marker="X" if hit is not None else None, markeredgecolor="black", markersize=8,
                              label=f"{FILTER_LABELS.get(name, name)}: {note}"))
    if legend_ax is None:
        ax.legend(handles=handles, loc="best", fontsize="small", framealpha=0.85)
    else:
        legend_ax.axis("off")
        legend_ax.legend(handles=handles, loc="upper center", fontsize="small", frameon=False)
    if title is not None:
        ax.set_title(title, fontsize="medium")
    return ax



def overlay_figure(panels: Sequence[Sequence[EpisodeOutcome]], title: str | None = None,
                   panel_size: tuple[float, float] = (5.6, 6.4), dpi: float = 110.0) -> Figure:
    """A figure with one panel per group of recorded episodes, side by side (see :func:`draw_overlay`).

    Every episode of a panel must share its scenario, robot and seed (so they start in the same
    world from the same pose); they usually differ by filter.

    Args:
        panels: the episodes of each panel.
        title: the figure's title.
        panel_size: width and height of one panel [inch].
        dpi: resolution [dots per inch].

    Raises:
        InvalidConfig: an empty panel, or a panel mixing scenarios, robots or seeds.
    """
    figure = Figure(figsize=(panel_size[0] * len(panels), panel_size[1]), dpi=dpi, layout="constrained")
    FigureCanvasAgg(figure)
    rows = max(len(outcomes) for outcomes in panels)
    axes = figure.subplots(2, len(panels), squeeze=False, height_ratios=[1.0, 0.045 * rows + 0.02])
    for ax, legend_ax, outcomes in zip(axes[0], axes[1], panels, strict=True):
        if not outcomes:
            raise InvalidConfig("overlay_figure: a panel has no episodes")
        first = outcomes[0].spec
        if any((o.spec.scenario, o.spec.robot, o.spec.seed) != (first.scenario, first.robot, first.seed)
               for o in outcomes):
            raise InvalidConfig(f"overlay_figure: a panel mixes scenarios, robots or seeds: "
                                f"{[o.spec for o in outcomes]}")
        task = scenario_for(first.scenario, first.robot, first.policy)
        policies = sorted({o.spec.policy for o in outcomes})
        draw_overlay(ax, task.world(first.seed), task.robot, outcomes,
                     title=f"{first.scenario}, policy {', '.join(policies)}\n{task.robot_name}, seed {first.seed}",
                     legend_ax=legend_ax)
    if title is not None:
        figure.suptitle(title)
    return figure
