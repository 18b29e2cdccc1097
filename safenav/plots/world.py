"""Drawing a world from above, and the Agg figures every plot of safenav draws on.

Everything draws on :class:`matplotlib.figure.Figure` objects with the Agg canvas, never
through ``pyplot``, so nothing opens a window and no global figure state is kept.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from safenav._optional import require
from safenav.worlds import Cylinder, World

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = ["GOAL_COLOR", "OBSTACLE_COLOR", "matplotlib_module", "new_figure", "plot_world"]

OBSTACLE_COLOR = "#7f7f7f"
GOAL_COLOR = "#9467bd"


def matplotlib_module(name: str) -> Any:
    """``matplotlib.<name>``, or :class:`~safenav.errors.MissingDependency` with the pip line of the ``sim`` extra."""
    return require(f"matplotlib.{name}", extra="sim", purpose="drawing worlds and episodes (safenav.plots)")


def new_figure(figsize: tuple[float, float], dpi: float = 100.0, *, layout: str | None = None) -> Figure:
    """An empty figure on the Agg canvas.

    Args:
        figsize: width and height [inch].
        dpi: resolution [dots per inch].
        layout: matplotlib's layout engine (``"constrained"``), or ``None``.
    """
    figure = matplotlib_module("figure").Figure(figsize=figsize, dpi=dpi, layout=layout)
    matplotlib_module("backends.backend_agg").FigureCanvasAgg(figure)
    return figure


def plot_world(world: World, ax: Axes | None = None, *, show_start: bool = True) -> Axes:
    """Draw the obstacles, the goal and (optionally) the start position of ``world``.

    Args:
        world: the world.
        ax: the axes to draw on; a new Agg figure when ``None``.
        show_start: mark the start position with a small cross.

    Returns:
        The axes, with equal aspect and limits set to ``world.bounds``.
    """
    patches = matplotlib_module("patches")
    if ax is None:
        ax = new_figure((6.0, 6.0)).add_subplot()
    for obstacle in world.obstacles:
        if isinstance(obstacle, Cylinder):
            patch = patches.Circle(obstacle.center, obstacle.radius, facecolor=OBSTACLE_COLOR, edgecolor="black",
                                   linewidth=0.6)
        else:
            patch = patches.Polygon(obstacle.polygon(), closed=True, facecolor=OBSTACLE_COLOR, edgecolor="black",
                                    linewidth=0.6)
        ax.add_patch(patch)
    if world.goal is not None:
        ax.plot(*world.goal, marker="*", markersize=14, color=GOAL_COLOR, linestyle="none", label="goal")
    if show_start:
        ax.plot(world.start.x, world.start.y, marker="x", markersize=6, color="black", linestyle="none")
    xmin, ymin, xmax, ymax = world.bounds
    ax.set_xlim(xmin, xmax)
    ax.set_ylim(ymin, ymax)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(True, linewidth=0.3, alpha=0.5)
    return ax
