"""The safety node's outputs as messages: one implementation of :class:`~safenav.ros.core.Outputs` for both ROS.

The transports hand :class:`TopicOutputs` their message classes, a ``publish`` function per
output, the current stamp and the diagnostic level's encoding (a ``byte`` in ROS 2, an ``int``
in ROS 1); everything else about the messages is the same.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from safenav.ros.core import NodeState, SafetyCore
from safenav.ros.messages import fill_markers, fill_twist

__all__ = ["MessageTypes", "TopicOutputs"]


@dataclass(frozen=True)
class MessageTypes:
    """The message classes of one ROS version."""

    twist: type
    twist_stamped: type
    string: type
    diagnostic_array: type
    diagnostic_status: type
    key_value: type
    marker_array: type
    marker: type
    point: type


class TopicOutputs:
    """Publishes what :meth:`SafetyCore.tick <safenav.ros.core.SafetyCore.tick>` decides.

    Args:
        core: the node's core (its configuration and robot).
        types: the message classes.
        publish: one function per output: ``"command"``, ``"state"``, ``"diagnostics"`` and, with
            markers on, ``"markers"``.
        stamp: the current time as a header stamp.
        level: encodes a diagnostic level (0 OK, 1 WARN, 2 ERROR) for ``DiagnosticStatus.level``.
        node_name: the node's name, for the diagnostic status.
    """

    def __init__(self, core: SafetyCore, types: MessageTypes, publish: Mapping[str, Callable[[Any], None]], *,
                 stamp: Callable[[], Any], level: Callable[[int], Any], node_name: str) -> None:
        self.core = core
        self.types = types
        self.publish = dict(publish)
        self.stamp = stamp
        self.level = level
        self.node_name = node_name

    def command(self, u: tuple[float, float]) -> None:
        config = self.core.config
        if config.stamped:
            msg = self.types.twist_stamped()
            msg.header.stamp = self.stamp()
            msg.header.frame_id = config.base_frame
            fill_twist(msg.twist, u)
        else:
            msg = fill_twist(self.types.twist(), u)
        self.publish["command"](msg)

    def state(self, state: NodeState) -> None:
        self.publish["state"](self.types.string(data=json.dumps(state.as_dict())))

    def diagnostics(self, state: NodeState) -> None:
        types = self.types
        status = types.diagnostic_status(
            level=self.level(state.level), name=f"{self.node_name}: safety filter",
            message=f"{state.status}: {state.reason}" if state.reason else state.status,
            hardware_id=self.core.robot.name,
            values=[types.key_value(key=k, value=v) for k, v in self.core.diagnostic_values(state)])
        array = types.diagnostic_array(status=[status])
        array.header.stamp = self.stamp()
        self.publish["diagnostics"](array)

    def markers(self, footprint: np.ndarray, points: np.ndarray, active: np.ndarray) -> None:
        if "markers" in self.publish:
            types = self.types
            self.publish["markers"](fill_markers(types.marker_array(), types.marker, types.point,
                                                 frame_id=self.core.config.base_frame, stamp=self.stamp(),
                                                 footprint=footprint, points=points, active=active))
