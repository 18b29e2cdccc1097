"""Entry points of ``safenav-ros2`` and ``safenav-ros1``: a missing ROS is one line, not a traceback."""

from __future__ import annotations

import importlib
import sys
from collections.abc import Sequence

from safenav.errors import MissingDependency

__all__ = ["ros1_main", "ros2_main"]


def _main(transport: str, argv: Sequence[str] | None) -> int:
    try:
        module = importlib.import_module(f"safenav.ros.{transport}")
    except MissingDependency as error:
        print(f"safenav-{transport}: {error}", file=sys.stderr)
        return 2
    return module.main(argv)


def ros2_main(argv: Sequence[str] | None = None) -> int:
    """``safenav-ros2``: see :mod:`safenav.ros.ros2`."""
    return _main("ros2", argv)


def ros1_main(argv: Sequence[str] | None = None) -> int:
    """``safenav-ros1``: see :mod:`safenav.ros.ros1`."""
    return _main("ros1", argv)
