"""Worlds as data: obstacles, a start pose and an optional goal, built into a simulator on demand.

=====================  ========================================================================
module                 holds
=====================  ========================================================================
``shapes``             :class:`Box`, :class:`Cylinder`, :class:`Wall`, :func:`room`, :func:`gap`
``world``              :class:`World` (exact signed distances, analytic scene, the simulator's mesh)
``tutorial``           :data:`TUTORIALS`, the three classic tutorials; :func:`tutorial_world`
``generator``          :func:`random_world`, :func:`door_world`, :func:`dead_end_world`; :func:`reachable`
``dynamic``            :class:`DynamicWorld`, :class:`MovingObstacle`; scripted encounters and seeded walkers
=====================  ========================================================================

Drawing a world is :func:`safenav.plots.plot_world`.
"""

from safenav.worlds.dynamic import (
    DynamicWorld,
    MovingObstacle,
    crossing,
    head_on,
    overtaking,
    pass_beside,
    patrols,
    random_movers,
    step_in,
)
from safenav.worlds.generator import (
    GRID_RESOLUTION,
    START_CLEARANCE,
    dead_end_world,
    door_world,
    random_world,
    reachable,
)
from safenav.worlds.shapes import WALL_THICKNESS, Box, Cylinder, Obstacle, Wall, gap, room
from safenav.worlds.tutorial import TUTORIAL_WORLDS, TUTORIALS, Tutorial, tutorial_world
from safenav.worlds.world import World, obstacle_mesh

__all__ = [
    "GRID_RESOLUTION",
    "START_CLEARANCE",
    "TUTORIALS",
    "TUTORIAL_WORLDS",
    "WALL_THICKNESS",
    "Box",
    "Cylinder",
    "DynamicWorld",
    "MovingObstacle",
    "Obstacle",
    "Tutorial",
    "Wall",
    "World",
    "crossing",
    "dead_end_world",
    "door_world",
    "gap",
    "head_on",
    "obstacle_mesh",
    "overtaking",
    "pass_beside",
    "patrols",
    "random_movers",
    "random_world",
    "reachable",
    "room",
    "step_in",
    "tutorial_world",
]
