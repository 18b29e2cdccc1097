"""Reference nominal policies: the three ROS tutorial controllers, go-to-goal and a random walk."""

from safenav.reference.base import Policy

__all__ = ["Policy"]
