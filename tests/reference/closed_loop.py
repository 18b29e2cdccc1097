"""Closed-loop episodes of the tutorial policies in their own worlds, for the policies' tests."""

from safenav import preset
from safenav.episode import EpisodeConfig, EpisodeResult, run_episode
from safenav.reference import Policy
from safenav.robot import RobotSpec
from safenav.worlds import TUTORIALS, World


def tutorial_episode(world_name: str, policy: Policy, duration: float, *,
                     world: World | None = None) -> tuple[RobotSpec, World, EpisodeResult]:
    """Run ``policy`` on the tutorial's robot in its world (or ``world``), seed 0, recorded with scans."""
    tutorial = TUTORIALS[world_name]
    robot = preset(tutorial.robot)
    world = world or tutorial.world()
    return robot, world, run_episode(world, robot, policy, config=EpisodeConfig(duration=duration), seed=0,
                                     record=True, record_scans=True)
