"""Fixtures of the ROS tests: isolated graphs (see ``graph.py``)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.ros.graph import isolated_graphs


@pytest.fixture
def graphs(tmp_path: Path) -> Iterator[Any]:
    """``graphs("ros2")`` or ``graphs("ros1")``: a new isolated graph; all stopped at teardown."""
    with isolated_graphs(tmp_path) as make:
        yield make
