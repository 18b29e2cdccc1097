"""Top-down pictures of one episode: a PNG of the whole run, an animated GIF with the lidar.

:func:`plot_episode` draws the world, the trajectory, the body at the start and the end,
the collision points and optionally a scan; :func:`save_gif` animates an episode.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from safenav._checks import integer, positive
from safenav._optional import require
from safenav.errors import InvalidConfig
from safenav.geometry import Pose2D
from safenav.plots.world import matplotlib_module, new_figure, plot_world
from safenav.robot import RobotSpec
from safenav.scan import LaserScan
from safenav.worlds import World

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = ["plot_episode", "pose_array", "save_gif", "scan_points_world"]

TRAJECTORY_COLOR = "#1f77b4"
BODY_COLOR = "#2ca02c"
COLLISION_COLOR = "#d62728"
SCAN_COLOR = "#ff7f0e"


def pose_array(poses: Any) -> np.ndarray:
    """Poses as an ``(N, 3)`` float array of ``(x [m], y [m], yaw [rad])``.

    Accepts an ``(N, 3)`` array, a sequence of :class:`~safenav.geometry.Pose2D`, or a
    sequence of objects with a ``pose`` attribute (such as simulator states).

    Raises:
        InvalidConfig: the poses do not have that shape.
    """
    if isinstance(poses, np.ndarray):
        array = poses.astype(float, copy=False)
    else:
        items = list(poses)
        array = np.array([tuple(getattr(item, "pose", item)) for item in items], dtype=float)
    if array.ndim != 2 or array.shape[1] != 3 or array.shape[0] == 0:
        raise InvalidConfig(f"poses must be a non-empty (N, 3) array of (x, y, yaw), got shape {array.shape}")
    return array


def scan_points_world(scan: LaserScan, pose: Pose2D | Sequence[float]) -> np.ndarray:
    """The obstacle points of ``scan`` in the world frame, with the base at ``pose`` [m] ``(N, 2)``.

    Points go through the scan's own mount, so a miscalibrated mount draws them where
    the robot believes they are.
    """
    return Pose2D(*pose).to_parent(scan.points("base"))


def _draw_body(ax: Axes, robot: RobotSpec, pose: Sequence[float], *, style: str = "-", alpha: float = 1.0,
               label: str | None = None) -> list[Any]:
    """Draw the body disk, the footprint (if any), the heading and the lidar mount at ``pose``."""
    patches = matplotlib_module("patches")
    base = Pose2D(*pose)
    artists: list[Any] = [ax.add_patch(patches.Circle((base.x, base.y), robot.radius, fill=False,
                                                      edgecolor=BODY_COLOR, linestyle=style, linewidth=1.2,
                                                      alpha=alpha, label=label))]
    if robot.footprint is not None:
        corners = base.to_parent(np.array(robot.footprint))
        artists.append(ax.add_patch(patches.Polygon(corners, closed=True, facecolor=BODY_COLOR, alpha=0.25 * alpha,
                                                    edgecolor=BODY_COLOR, linewidth=0.8)))
    tip = base.to_parent(np.array([[robot.radius, 0.0]]))[0]
    artists.extend(ax.plot([base.x, tip[0]], [base.y, tip[1]], color=BODY_COLOR, linewidth=1.5, alpha=alpha))
    sensor = base.compose(robot.lidar.mount)
    artists.extend(ax.plot(sensor.x, sensor.y, marker="o", markersize=3, color=SCAN_COLOR, alpha=alpha))
    return artists


def plot_episode(
    world: World,
    robot: RobotSpec,
    poses: Any,
    *,
    collisions: Any = None,
    scan: LaserScan | None = None,
    path: str | Path | None = None,
    title: str | None = None,
    dpi: float = 100.0,
) -> Figure:
    """A top-down picture of one episode, optionally saved as a PNG.

    Draws the world, the trajectory of the base, the body at the start (dashed) and at
    the end (solid) with its heading, the collision points as red crosses, and the
    obstacle points of ``scan`` taken at the last pose.

    Args:
        world: the world.
        robot: the robot (body size, footprint and lidar mount).
        poses: the base poses, see :func:`pose_array`.
        collisions: positions where the body touched an obstacle, ``(M, 2)`` or poses; ``None`` for none.
        scan: a scan taken at the last pose, drawn as points.
        path: where to save the PNG; not saved when ``None``.
        title: the figure title; the world's name by default.
        dpi: resolution [dots per inch].

    Returns:
        The figure (Agg canvas).
    """
    trajectory = pose_array(poses)
    ax = new_figure((7.5, 6.0), dpi).add_subplot()
    plot_world(world, ax)
    ax.plot(trajectory[:, 0], trajectory[:, 1], color=TRAJECTORY_COLOR, linewidth=1.5, label="trajectory")
    _draw_body(ax, robot, trajectory[0], style="--", alpha=0.7, label="start")
    _draw_body(ax, robot, trajectory[-1], label="end")
    if scan is not None:
        points = scan_points_world(scan, trajectory[-1])
        ax.plot(points[:, 0], points[:, 1], linestyle="none", marker=".", markersize=2, color=SCAN_COLOR,
                label="scan")
    if collisions is not None:
        hits = np.asarray([tuple(c)[:2] for c in collisions], dtype=float).reshape(-1, 2)
        if hits.size:
            ax.plot(hits[:, 0], hits[:, 1], linestyle="none", marker="x", markersize=8, markeredgewidth=2,
                    color=COLLISION_COLOR, label="collision")
    ax.set_title(world.name if title is None else title)
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize="small", borderaxespad=0.0)
    figure = ax.figure
    figure.tight_layout()
    if path is not None:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        figure.savefig(path)
    return figure


def save_gif(
    path: str | Path,
    world: World,
    robot: RobotSpec,
    poses: Any,
    scans: Sequence[LaserScan | None] | None = None,
    *,
    fps: float = 10.0,
    stride: int = 1,
    rays: bool = True,
    title: str | None = None,
    dpi: float = 80.0,
) -> int:
    """Animate an episode into a GIF (matplotlib's Pillow writer).

    Each frame shows the world, the trajectory so far, the body at the current pose
    and, when ``scans`` are given, the scan taken at that pose: rays from the sensor to
    each obstacle point (or just the points with ``rays=False``).

    Args:
        path: the GIF file to write.
        world: the world.
        robot: the robot.
        poses: the base poses, see :func:`pose_array`.
        scans: one scan per pose (``None`` entries are skipped), or ``None``.
        fps: frames per second of the GIF.
        stride: draw every ``stride``-th pose (the last pose is always drawn).
        rays: draw rays rather than points.
        title: the title; the world's name by default.
        dpi: resolution [dots per inch].

    Returns:
        The number of frames written.

    Raises:
        InvalidConfig: ``scans`` does not have one entry per pose, or ``fps``/``stride`` are not positive.
    """
    trajectory = pose_array(poses)
    if scans is not None and len(scans) != len(trajectory):
        raise InvalidConfig(f"scans must have one entry per pose ({len(trajectory)}), got {len(scans)}")
    stride = integer("save_gif stride", stride, low=1)
    fps = positive("save_gif fps", fps)
    require("PIL", extra="sim", purpose="writing GIFs (safenav.plots.save_gif)", package="pillow")
    frames = list(range(0, len(trajectory), stride))
    if frames[-1] != len(trajectory) - 1:
        frames.append(len(trajectory) - 1)
    ax = new_figure((5.0, 5.0), dpi).add_subplot()
    plot_world(world, ax)
    ax.set_title(world.name if title is None else title)
    (line,) = ax.plot([], [], color=TRAJECTORY_COLOR, linewidth=1.5)
    ray_lines = matplotlib_module("collections").LineCollection([], colors=SCAN_COLOR, linewidths=0.3, alpha=0.6)
    ax.add_collection(ray_lines)
    (scan_dots,) = ax.plot([], [], linestyle="none", marker=".", markersize=2, color=SCAN_COLOR)
    figure = ax.figure
    figure.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    writer = matplotlib_module("animation").PillowWriter(fps=fps)
    body: list[Any] = []
    with writer.saving(figure, str(path), dpi):
        for index in frames:
            for artist in body:
                artist.remove()
            pose = trajectory[index]
            line.set_data(trajectory[: index + 1, 0], trajectory[: index + 1, 1])
            body = _draw_body(ax, robot, pose)
            scan = scans[index] if scans is not None else None
            points = scan_points_world(scan, pose) if scan is not None else np.empty((0, 2))
            if rays and points.size:
                sensor = Pose2D(*pose).compose(scan.mount)
                ray_lines.set_segments([((sensor.x, sensor.y), tuple(p)) for p in points])
            else:
                ray_lines.set_segments([])
            scan_dots.set_data(points[:, 0], points[:, 1])
            writer.grab_frame()
    return len(frames)
