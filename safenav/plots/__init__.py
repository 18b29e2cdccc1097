"""Pictures: worlds and episodes from above (PNG, GIF), and the figures of the experiments.

=============  ==============================================================================
module         draws
=============  ==============================================================================
``world``      :func:`plot_world`: obstacles, start and goal (and the Agg figure every plot uses)
``episode``    :func:`plot_episode` (PNG), :func:`save_gif` (animation with the lidar rays)
``overlays``   :func:`overlay_figure`, :func:`collision_rate_figure`, :func:`clearance_figure`
=============  ==============================================================================

matplotlib (and Pillow for GIFs) come with the ``sim`` extra; without them a plotting call
raises :class:`~safenav.errors.MissingDependency` with the line ``pip install "safenav[sim]"``.
Nothing draws through ``pyplot``: no window opens and no global figure state is kept.
"""

from safenav.plots.episode import plot_episode, pose_array, save_gif, scan_points_world
from safenav.plots.overlays import (
    FILTER_COLORS,
    clearance_figure,
    collision_rate_figure,
    draw_overlay,
    overlay_figure,
)
from safenav.plots.world import new_figure, plot_world

__all__ = [
    "FILTER_COLORS",
    "clearance_figure",
    "collision_rate_figure",
    "draw_overlay",
    "new_figure",
    "overlay_figure",
    "plot_episode",
    "plot_world",
    "pose_array",
    "save_gif",
    "scan_points_world",
]
