"""Pictures of one episode: a PNG with the trajectory, the scan and the collisions; an animated GIF."""

import math

import numpy as np
import pytest
from matplotlib.colors import to_rgb
from PIL import Image

from safenav import InvalidConfig, Pose2D, preset
from safenav.plots import plot_episode, pose_array, save_gif, scan_points_world
from safenav.plots.episode import COLLISION_COLOR, SCAN_COLOR, TRAJECTORY_COLOR
from safenav.synthetic import synthetic_scan
from safenav.worlds import Box, Cylinder, World, tutorial_world


def _pixels_near(path, color, tolerance=40):
    image = np.asarray(Image.open(path).convert("RGB"), dtype=int)
    target = np.array(to_rgb(color)) * 255
    return int(np.count_nonzero(np.abs(image - target).sum(axis=2) < tolerance))


def _straight_run(world, n=30, length=2.0):
    start = world.start
    return np.array([(start.x + length * t * math.cos(start.yaw), start.y + length * t * math.sin(start.yaw),
                      start.yaw) for t in np.linspace(0.0, 1.0, n)])


def test_plot_episode_writes_a_png_with_trajectory_scan_and_collisions(tmp_path):
    robot = preset("puzzlebot")
    world = tutorial_world("obstacle_avoidance")
    poses = _straight_run(world)
    scan = synthetic_scan(robot, world.scene(), Pose2D(*poses[-1]))
    clean = tmp_path / "clean.png"
    crashed = tmp_path / "sub" / "crashed.png"
    figure = plot_episode(world, robot, poses, scan=scan, path=clean, title="clean run")
    plot_episode(world, robot, poses, collisions=[poses[-1]], path=crashed)
    assert figure.axes[0].get_title() == "clean run"
    for path in (clean, crashed):
        with Image.open(path) as image:
            assert image.format == "PNG" and image.size == (750, 600)
    assert _pixels_near(clean, TRAJECTORY_COLOR) > 100
    assert _pixels_near(clean, SCAN_COLOR) > 20
    assert _pixels_near(clean, COLLISION_COLOR) == 0
    assert _pixels_near(crashed, COLLISION_COLOR) > 20


def test_plot_episode_accepts_states_with_a_pose_attribute():
    class State:
        def __init__(self, pose):
            self.pose = pose

    world = World("w", (Cylinder((2.0, 0.0), 0.3),))
    poses = [Pose2D(0.1 * k, 0.0, 0.0) for k in range(5)]
    np.testing.assert_array_equal(pose_array([State(p) for p in poses]), pose_array(poses))
    figure = plot_episode(world, preset("rosbot"), [State(p) for p in poses])
    (line,) = [line for line in figure.axes[0].lines if line.get_label() == "trajectory"]
    np.testing.assert_allclose(line.get_xdata(), [0.1 * k for k in range(5)])


def test_scan_points_go_through_the_mount():
    robot = preset("m2wr")   # lidar 0.15 m ahead of the base
    world = World("box", (Box((3.0, 1.0), (1.0, 6.0)),))
    pose = Pose2D(0.5, 1.0, 0.0)
    points = scan_points_world(synthetic_scan(robot, world.scene(), pose), pose)
    assert np.all(np.isclose(points[:, 0], 2.5, atol=1e-9))   # the near face of the box, in the world frame


def test_save_gif_writes_one_frame_per_drawn_pose(tmp_path):
    robot = preset("rosbot")
    world = tutorial_world("stop_at_wall")
    poses = _straight_run(world, n=10)
    scans = [synthetic_scan(robot, world.scene(), Pose2D(*p)) for p in poses]
    scans[3] = None
    path = tmp_path / "episode.gif"
    frames = save_gif(path, world, robot, poses, scans, stride=3, fps=5)
    assert frames == 4   # poses 0, 3, 6, 9
    with Image.open(path) as image:
        assert image.format == "GIF" and image.n_frames == frames
    assert save_gif(tmp_path / "no_scans.gif", world, robot, poses, rays=False) == 10


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda tmp: pose_array(np.zeros((3, 2))), "poses"),
        (lambda tmp: pose_array([]), "poses"),
        (lambda tmp: save_gif(tmp / "a.gif", tutorial_world("stop_at_wall"), preset("rosbot"), np.zeros((3, 3)),
                              scans=[None]), "scans"),
        (lambda tmp: save_gif(tmp / "a.gif", tutorial_world("stop_at_wall"), preset("rosbot"), np.zeros((3, 3)),
                              stride=0), "stride"),
        (lambda tmp: save_gif(tmp / "a.gif", tutorial_world("stop_at_wall"), preset("rosbot"), np.zeros((3, 3)),
                              fps=0), "fps"),
    ],
)
def test_bad_render_arguments(tmp_path, call, message):
    with pytest.raises(InvalidConfig, match=message):
        call(tmp_path)
