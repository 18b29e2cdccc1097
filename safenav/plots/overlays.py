"""Figures of experiments: recorded episodes overlaid per filter, collision rates, clearance histograms.

They read what :mod:`safenav.experiments` returns (outcomes and cell records) and never run
anything; experiments import no plotting at run time.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import numpy as np

from safenav.errors import InvalidConfig
from safenav.experiments.tables import FILTER_LABELS
from safenav.plots.world import matplotlib_module, new_figure, plot_world
from safenav.robot import preset

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from safenav.experiments import EpisodeOutcome

__all__ = ["FILTER_COLORS", "clearance_figure", "collision_rate_figure", "draw_overlay", "overlay_figure"]

FILTER_COLORS: Mapping[str, str] = MappingProxyType(
    {"none": "#d62728", "zones": "#ff7f0e", "cbf": "#1f77b4", "mpc": "#2ca02c",
     "zones+escape": "#8c564b", "cbf+escape": "#9467bd", "mpc+escape": "#17becf"})
"""Line colour of each filter in the figures."""

FILTER_DASHES: Mapping[str, Any] = MappingProxyType({"zones": (0, (6, 2, 1, 2)), "mpc": (0, (4, 2)),
                                                    "mpc+escape": (0, (4, 2))})
"""Line style of each filter in the overlays (solid otherwise), so that coinciding paths all show."""


def _label(name: str) -> str:
    return FILTER_LABELS.get(name, name)


def _color(name: str, default: str = "black") -> str:
    return FILTER_COLORS.get(name, default)


def draw_overlay(ax: Axes, outcomes: Sequence[EpisodeOutcome], title: str | None = None,
                 legend_ax: Axes | None = None) -> Axes:
    """Draw several recorded episodes of the same world on one axes, one colour per filter.

    Each trajectory ends with the body outline; a collision is a large cross where it
    happened. The legend says, per filter, whether it collided and its minimum clearance.

    Args:
        ax: the axes to draw on.
        outcomes: recorded episodes that ran in the same world (the first one's world is drawn).
        title: the axes title.
        legend_ax: an empty axes to hold the legend (it is hidden); the legend goes inside
            ``ax`` when ``None``.

    Raises:
        InvalidConfig: no outcome, or one was run without ``record``.
    """
    if not outcomes:
        raise InvalidConfig("draw_overlay needs at least one episode")
    circle = matplotlib_module("patches").Circle
    line = matplotlib_module("lines").Line2D
    plot_world(outcomes[0].world, ax)
    handles: list[Any] = []
    for outcome in outcomes:
        if outcome.trajectory is None:
            raise InvalidConfig(f"episode {outcome.spec} was not recorded; run it with record=True")
        name = outcome.spec.filter
        color = _color(name)
        pose = outcome.trajectory.pose
        metrics = outcome.metrics
        # The naive path is drawn wide and pale underneath, so a filter that leaves it unchanged shows as
        # a coloured line inside a red band rather than hiding it.
        naive = name == "none"
        width, alpha, layer = (4.5, 0.45, 2) if naive else (1.6, 0.95, 3)
        style = FILTER_DASHES.get(name, "-")
        ax.plot(pose[:, 0], pose[:, 1], color=color, linewidth=width, alpha=alpha, zorder=layer, linestyle=style,
                solid_capstyle="round")
        ax.add_patch(circle((pose[-1, 0], pose[-1, 1]), preset(outcome.robot).radius, fill=False, edgecolor=color,
                            linewidth=1.2, zorder=4))
        hit = outcome.collision_point()
        if hit is not None:
            ax.plot(*hit, marker="X", markersize=13, color=color, markeredgecolor="black", linestyle="none",
                    zorder=5)
            note = f"collided at {metrics.collision_time:.1f} s"
        else:
            note = f"min clearance {100 * metrics.min_clearance:.0f} cm"
        handles.append(line([], [], color=color, linewidth=width, alpha=alpha, linestyle=style,
                            marker="X" if hit is not None else None, markeredgecolor="black", markersize=8,
                            label=f"{_label(name)}: {note}"))
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
    figure = new_figure((panel_size[0] * len(panels), panel_size[1]), dpi, layout="constrained")
    rows = max(len(outcomes) for outcomes in panels)
    axes = figure.subplots(2, len(panels), squeeze=False, height_ratios=[1.0, 0.045 * rows + 0.02])
    for ax, legend_ax, outcomes in zip(axes[0], axes[1], panels, strict=True):
        if not outcomes:
            raise InvalidConfig("overlay_figure: a panel has no episodes")
        first = outcomes[0]
        key = (first.spec.scenario, first.robot, first.spec.seed)
        if any((o.spec.scenario, o.robot, o.spec.seed) != key for o in outcomes):
            raise InvalidConfig(f"overlay_figure: a panel mixes scenarios, robots or seeds: "
                                f"{[o.spec for o in outcomes]}")
        policies = ", ".join(sorted({o.spec.policy for o in outcomes}))
        draw_overlay(ax, outcomes, legend_ax=legend_ax,
                     title=f"{first.spec.scenario}, policy {policies}\n{first.robot}, seed {first.spec.seed}")
    if title is not None:
        figure.suptitle(title)
    return figure


def collision_rate_figure(records: Sequence[dict[str, Any]]) -> Figure:
    """Grouped bars: the collision rate of each filter in each (scenario, policy) pair, with Wilson 95 % bars.

    Args:
        records: cell records (:func:`safenav.experiments.cell_records`).
    """
    pairs = list(dict.fromkeys((r["scenario"], r["policy"]) for r in records))
    filters = list(dict.fromkeys(r["filter"] for r in records))
    by_key = {(r["scenario"], r["policy"], r["filter"]): r for r in records}
    figure = new_figure((max(7.0, 0.75 * len(pairs) * max(len(filters), 2) / 2 + 2.0), 6.0), 110.0,
                        layout="constrained")
    ax = figure.add_subplot()
    width = 0.8 / len(filters)
    for index, name in enumerate(filters):
        x, rate, low, high = [], [], [], []
        for position, (scenario_name, policy) in enumerate(pairs):
            record = by_key.get((scenario_name, policy, name))
            if record is None:
                continue
            x.append(position - 0.4 + width * (index + 0.5))
            rate.append(record["collision_rate"])
            low.append(record["collision_rate"] - record["collision_rate_ci"][0])
            high.append(record["collision_rate_ci"][1] - record["collision_rate"])
            # The count above the interval, so that a zero rate still shows which filter it is.
            ax.text(x[-1], record["collision_rate_ci"][1] + 0.015, f"{record['collisions']}/{record['episodes']}",
                    rotation=90, ha="center", va="bottom", fontsize=6.5, color=_color(name, "gray"))
        ax.bar(x, rate, width, color=_color(name, "gray"), label=_label(name), yerr=[low, high], capsize=2,
               error_kw={"elinewidth": 0.8, "ecolor": "black"})
    episodes = sorted({r["episodes"] for r in records})
    ax.set_xticks(range(len(pairs)), [f"{s}\n{p}" for s, p in pairs], rotation=35, ha="right", fontsize="small")
    ax.set_ylim(0.0, 1.18)
    ax.set_yticks(np.linspace(0.0, 1.0, 6))
    ax.set_ylabel("collision rate (95% Wilson interval)")
    ax.set_title(f"Collision rate by filter ({'/'.join(map(str, episodes))} episodes per bar)")
    ax.grid(True, axis="y", linewidth=0.3, alpha=0.6)
    ax.legend(ncols=len(filters), loc="upper center", bbox_to_anchor=(0.5, 1.0), fontsize="small")
    return figure


def clearance_figure(outcomes: Sequence[EpisodeOutcome], low: float = -0.1, high: float = 1.0) -> Figure:
    """Histogram of each episode's minimum clearance, per filter (values outside [low, high] in the end bins)."""
    filters = list(dict.fromkeys(o.spec.filter for o in outcomes))
    bins = np.linspace(low, high, 45)
    figure = new_figure((7.5, 4.6), 110.0, layout="constrained")
    ax = figure.add_subplot()
    for name in filters:
        values = np.clip([o.metrics.min_clearance for o in outcomes if o.spec.filter == name], low, high)
        ax.hist(values, bins=bins, histtype="step", linewidth=1.6, color=_color(name, "gray"),
                label=f"{_label(name)} ({values.size} episodes)")
    ax.axvline(0.0, color="black", linestyle="--", linewidth=1.0)
    ax.text(0.0, 0.98, " contact", transform=ax.get_xaxis_transform(), va="top", fontsize="small")
    ax.set_xlabel(f"minimum body clearance in the episode [m] (clipped to [{low:g}, {high:g}])")
    ax.set_ylabel("episodes")
    ax.set_title("Minimum clearance per episode")
    ax.grid(True, linewidth=0.3, alpha=0.6)
    ax.legend(fontsize="small")
    return figure
