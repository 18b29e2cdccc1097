"""Shared fixtures: presets, lidar conventions and the real recordings, so filter and policy tests need no simulator.

Helpers that are not fixtures live beside this file: ``tests/scans.py`` (lidar conventions, scans
painted by sector) and ``tests/strategies.py`` (hypothesis strategies).
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from hypothesis import settings

from safenav import PRESET_NAMES, LidarSpec, RobotSpec, preset
from safenav.datasets import lidar_data_dir
from tests.scans import LIDARS

# Hypothesis: reproducible (derandomized) and free of the wall-clock deadline on a shared machine.
settings.register_profile("safenav", derandomize=True, deadline=None, print_blob=True)
settings.load_profile("safenav")


@pytest.fixture(params=PRESET_NAMES)
def robot(request: pytest.FixtureRequest) -> RobotSpec:
    """Each tutorial robot in turn."""
    return preset(request.param)


@pytest.fixture(params=sorted(LIDARS))
def lidar(request: pytest.FixtureRequest) -> LidarSpec:
    """Each lidar convention of ``tests.scans.LIDARS`` in turn (three presets and three others)."""
    return LIDARS[request.param]


@pytest.fixture(scope="session")
def lidar_data() -> Path:
    """Folder of the real recorded scans; the test is skipped (with the reason) when it is missing."""
    folder = lidar_data_dir()
    if folder is None:
        pytest.skip("real lidar recordings not found: set SAFENAV_LIDAR_DATA to shared/data/lidar")
    return folder


HALF_PI = 0.5 * math.pi
