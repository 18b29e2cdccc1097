"""What to run: cells of an experiment matrix and the episode specs, validated when they are made.

An :class:`EpisodeSpec` is plain names and a seed, so it can be sent to another process; its
names, values and simulator options are checked when it is constructed, so a bad name fails
before any episode starts and an episode cannot fail on a name.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from safenav._checks import boolean, choice, integer, positive
from safenav.errors import InvalidConfig
from safenav.filters import FILTER_NAMES, FILTERS
from safenav.reference import POLICY_NAMES
from safenav.scenarios import SCENARIO_NAMES, scenario, scenario_for
from safenav.sim_bullet import SimConfig

__all__ = ["Cell", "EpisodeSpec", "episode_specs", "matrix"]


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


def _options(name: str, value: Any) -> tuple[tuple[str, Any], ...]:
    """Settings given as a mapping or as ``(name, value)`` pairs, as a tuple of pairs."""
    items = value.items() if isinstance(value, Mapping) else value
    try:
        pairs = tuple((key, setting) for key, setting in items)
    except (TypeError, ValueError):
        raise InvalidConfig(f"EpisodeSpec.{name} must be (name, value) pairs or a mapping, got {value!r}") from None
    for key, _ in pairs:
        if not isinstance(key, str):
            raise InvalidConfig(f"EpisodeSpec.{name} names must be strings, got {key!r}")
    return pairs


@dataclass(frozen=True)
class EpisodeSpec:
    """Everything that defines one episode, as plain values that can be sent to another process.

    Checked on construction: the scenario, policy, filter and robot names (unknown names list the
    known ones), the seed, the duration, the flags, and the simulator options (as a
    :class:`~safenav.sim_bullet.SimConfig` would check them). Filter options are checked by the
    filter when the episode builds it.

    Attributes:
        scenario: the scenario (robot, world drawn from the seed, duration).
        policy: the nominal policy: one of the scenario's, or any other that fits its world.
        filter: the safety filter (``"none"`` for the naive robot).
        seed: the episode's seed, an integer >= 0: the world, the start jitter, the policy and
            the simulator noise draw from their own streams of it (:mod:`safenav.seeding`).
        duration: episode length [s]; the scenario's own when ``None``.
        robot: a preset that replaces the scenario's robot, or ``None``.
        record: keep the per-step trajectory.
        record_scans: keep the scans too (for animations).
        gui: open the PyBullet GUI.
        sim_options: extra :class:`~safenav.sim_bullet.SimConfig` fields as ``(name, value)``
            pairs or a mapping (noise, dropout, latency, base model, ...).
        filter_options: extra filter settings as ``(name, value)`` pairs or a mapping (``margin``, ...).
        odometry: also give the filter the simulator's pose as the odometry pose (as a ROS node
            passes ``/odom``'s); by default it gets the measured velocity only.

    Raises:
        UnknownName: an unknown scenario, policy, filter or robot.
        InvalidConfig: a value out of range, or names that do not go together (``go_to_goal``
            in a world without a goal).
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
    odometry: bool = False

    def __post_init__(self) -> None:
        put = object.__setattr__
        scenario_for(self.scenario, self.robot, self.policy)
        choice("filter", self.filter, FILTER_NAMES)
        put(self, "seed", integer("EpisodeSpec.seed", self.seed, low=0))
        if self.duration is not None:
            put(self, "duration", positive("EpisodeSpec.duration", self.duration))
        for flag in ("record", "record_scans", "gui", "odometry"):
            put(self, flag, boolean(f"EpisodeSpec.{flag}", getattr(self, flag)))
        put(self, "sim_options", _options("sim_options", self.sim_options))
        put(self, "filter_options", _options("filter_options", self.filter_options))
        try:
            SimConfig(gui=self.gui, **dict(self.sim_options))
        except TypeError as exc:   # a name that is not a SimConfig field
            raise InvalidConfig(f"EpisodeSpec.sim_options: {exc}") from None

    @property
    def cell(self) -> Cell:
        """The cell the episode belongs to."""
        return Cell(self.scenario, self.policy, self.filter)


def _checked(kind: str, names: Iterable[str] | None, known: tuple[str, ...]) -> list[str]:
    """``names``, each one known (else :class:`~safenav.errors.UnknownName`); all of ``known`` when ``None``."""
    return list(known) if names is None else [choice(kind, name, known) for name in names]


def matrix(scenarios: Iterable[str] | None = None, policies: Iterable[str] | None = None,
           filters: Iterable[str] | None = None) -> list[Cell]:
    """The cells of a sweep: every selected scenario with each of its selected policies, times every filter.

    Args:
        scenarios: scenario names (all of :data:`~safenav.scenarios.SCENARIO_NAMES` when ``None``).
        policies: keep only these policies (all when ``None``); a scenario keeps the ones it lists.
        filters: filter names from :data:`~safenav.filters.FILTER_NAMES` (the plain filters of
            :data:`~safenav.filters.FILTERS`, without the escape, when ``None``).

    Returns:
        The cells in table order: scenarios, then their policies, then filters.

    Raises:
        UnknownName: an unknown scenario, policy or filter.
        InvalidConfig: the selection leaves no cell.
    """
    scenario_names = _checked("scenario", scenarios, SCENARIO_NAMES)
    policy_names = None if policies is None else _checked("policy", policies, POLICY_NAMES)
    filter_names = _checked("filter", filters, FILTER_NAMES) if filters is not None else list(FILTERS)
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

    The specs keep each filter's defaults, its compute budget included: a call that a loaded machine
    preempts past it brakes, so the same seed can give another episode. Runs to compare (the sweeps,
    the tests) pass them through :func:`~safenav.experiments.runner.reproducible_specs`.

    Args:
        cells: the cells.
        seeds: the seeds of every cell (the same seed draws the same world in every filter).
        duration: episode length [s] for every scenario; each scenario's own when ``None``.
        record_seeds: seeds whose trajectory is recorded (for figures).
    """
    seed_list = list(seeds)
    recorded = set(record_seeds)
    return [EpisodeSpec(cell.scenario, cell.policy, cell.filter, seed, duration, record=seed in recorded)
            for cell in cells for seed in seed_list]
