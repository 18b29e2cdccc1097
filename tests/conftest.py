"""Shared fixtures: presets and synthetic scans, so filter and policy tests need no simulator."""

from __future__ import annotations

import math
import os
from pathlib import Path

import pytest
from hypothesis import settings

from safenav import PRESET_NAMES, RobotSpec, preset

# Hypothesis: reproducible (derandomized) and free of the wall-clock deadline on a shared machine.
settings.register_profile("safenav", derandomize=True, deadline=None, print_blob=True)
settings.load_profile("safenav")


@pytest.fixture(params=PRESET_NAMES)
def robot(request: pytest.FixtureRequest) -> RobotSpec:
    """Each tutorial robot in turn."""
    return preset(request.param)


def lidar_data_dir() -> Path | None:
    """The folder of real recorded scans (``../shared/data/lidar``), or ``None`` when absent.

    Looked up in ``$SAFENAV_LIDAR_DATA``, next to the repository, then at ``/work/shared/data/lidar``.
    """
    candidates = [os.environ.get("SAFENAV_LIDAR_DATA", "")]
    candidates.append(str(Path(__file__).resolve().parents[2] / "shared" / "data" / "lidar"))
    candidates.append("/work/shared/data/lidar")
    for candidate in candidates:
        if candidate and (Path(candidate) / "README.md").is_file():
            return Path(candidate)
    return None


@pytest.fixture(scope="session")
def lidar_data() -> Path:
    """Folder of the real recorded scans; the test is skipped (with the reason) when it is missing."""
    folder = lidar_data_dir()
    if folder is None:
        pytest.skip("real lidar recordings not found: set SAFENAV_LIDAR_DATA to shared/data/lidar")
    return folder


HALF_PI = 0.5 * math.pi
