"""Real ROS graphs for the node tests: an isolated ROS 2 domain or a private ROS 1 master per graph.

Every process runs the worktree's code (``python -m safenav.ros.ros2`` from the repository
root). A ROS 2 graph reserves a DDS domain id with a lock file (so parallel test runs on one
machine never share a domain) and keeps discovery on the loopback interface; a ROS 1 graph
starts its own ``roscore`` on a free port. Processes are stopped with SIGINT, then killed.
"""

from __future__ import annotations

import contextlib
import fcntl
import importlib.util
import os
import random
import shutil
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any, BinaryIO

import pytest

from safenav.ros.apps import ROS1_DEBIAN_PACKAGES

ROOT = Path(__file__).resolve().parents[2]
DEBIAN_ROS1 = Path("/usr/lib/python3/dist-packages/rospy/__init__.py")
ROS1_APT = f"apt-get install {' '.join(ROS1_DEBIAN_PACKAGES)}"


def ros2_missing() -> str | None:
    """Why ROS 2 cannot run here, or ``None``."""
    if importlib.util.find_spec("rclpy") is None:
        return 'ROS 2 is absent: pip install ".[ros2]"'
    return None


def ros1_missing() -> str | None:
    """Why ROS 1 cannot run here, or ``None``."""
    if shutil.which("roscore") is None or not DEBIAN_ROS1.is_file():
        return f"ROS 1 is absent: {ROS1_APT}"
    return None


def ros_marks(name: str) -> list[Any]:
    """The marks of a test parameterised by middleware ``name``: ``ros``, and a skip with the reason."""
    reason = ros2_missing() if name == "ros2" else ros1_missing()
    return [pytest.mark.ros, pytest.mark.skipif(reason is not None, reason=reason or "")]


MIDDLEWARES = [pytest.param(name, marks=ros_marks(name), id=name) for name in ("ros2", "ros1")]
MIDDLEWARES_ROS1_SLOW = [pytest.param(name, marks=ros_marks(name) + ([pytest.mark.slow] if name == "ros1" else []),
                                      id=name) for name in ("ros2", "ros1")]
"""As :data:`MIDDLEWARES`, the ROS 1 case under ``-m slow`` (the longest graphs; ROS 1 runs every other test)."""


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


class Graph:
    """One isolated ROS graph and the processes started in it.

    Args:
        middleware: ``"ros2"`` or ``"ros1"``.
        directory: where logs go.
        env: the environment of every process of the graph.
    """

    def __init__(self, middleware: str, directory: Path, env: Mapping[str, str]) -> None:
        self.middleware = middleware
        self.directory = directory
        self.env = dict(env)
        self.processes: list[tuple[subprocess.Popen, BinaryIO]] = []

    def spawn(self, label: str, *args: str, params: Mapping[str, Any] | None = None,
              node_name: str | None = None) -> subprocess.Popen:
        """Start ``safenav-ros2``/``safenav-ros1`` with ``args``, the safety node's ``params`` and node name."""
        command = [sys.executable, "-m", f"safenav.ros.{self.middleware}", *args]
        params = dict(params or {})
        if self.middleware == "ros2":
            if params or node_name:
                command.append("--ros-args")
            for name, value in params.items():
                command += ["-p", f"{name}:={_ros2_value(value)}"]
            if node_name:
                command += ["-r", f"__node:={node_name}"]
        else:
            command += [f"_{name.replace('.', '/')}:={_ros1_value(value)}" for name, value in params.items()]
            if node_name:
                command.append(f"__name:={node_name}")
        return self.run(label, command)

    def run(self, label: str, command: Sequence[str]) -> subprocess.Popen:
        """Start ``command`` in the graph; its output goes to ``<label>.log``."""
        log = (self.directory / f"{label}.log").open("wb")
        process = subprocess.Popen(list(command), cwd=ROOT, env=self.env, stdout=log, stderr=subprocess.STDOUT,
                                   start_new_session=True)
        self.processes.append((process, log))
        return process

    def log(self, label: str) -> str:
        return (self.directory / f"{label}.log").read_text(errors="replace")

    def stop(self) -> None:
        for process, _ in self.processes:
            if process.poll() is None:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(process.pid, signal.SIGINT)
        for process, log in self.processes:
            try:
                process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                os.killpg(process.pid, signal.SIGKILL)
                process.wait()
            log.close()


def _ros2_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f"'{value}'"
    return repr(value)


def _ros1_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return value if value else "''"
    return repr(value)


@contextlib.contextmanager
def _ros2_domain() -> Iterator[int]:
    """A DDS domain id no other test on this machine holds (lock files in the temp directory)."""
    candidates = list(range(1, 102))   # ids whose ports stay clear of the ephemeral range
    random.shuffle(candidates)
    for domain in candidates:
        with Path(f"/tmp/safenav-ros2-domain-{domain}.lock").open("w") as handle:
            try:
                fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                continue
            yield domain
            return
    raise RuntimeError("no free ROS 2 domain id")


def _wait_for_port(port: int, process: subprocess.Popen, timeout: float) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and process.poll() is None:
        with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), timeout=0.5):
            return
        time.sleep(0.1)
    raise RuntimeError(f"roscore did not come up on port {port} within {timeout} s")


@contextlib.contextmanager
def isolated_graphs(directory: Path) -> Iterator[Any]:
    """A factory of isolated graphs, ``make("ros2")``; every process is stopped on exit."""
    stack = contextlib.ExitStack()
    made: list[Graph] = []

    def make(middleware: str) -> Graph:
        where = directory / f"{middleware}-{len(made)}"
        where.mkdir()
        env = {**os.environ, "PYTHONUNBUFFERED": "1", "ROS_LOG_DIR": str(where), "ROS_HOME": str(where)}
        if middleware == "ros2":
            env.update(ROS_DOMAIN_ID=str(stack.enter_context(_ros2_domain())),
                       ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
            graph = Graph(middleware, where, env)
        else:
            port = _free_port()
            env.update(ROS_MASTER_URI=f"http://127.0.0.1:{port}", ROS_HOSTNAME="127.0.0.1")
            graph = Graph(middleware, where, env)
            made.append(graph)
            _wait_for_port(port, graph.run("roscore", ["roscore", "-p", str(port)]), timeout=30.0)
            return graph
        made.append(graph)
        return graph

    try:
        yield make
    finally:
        for graph in reversed(made):
            graph.stop()
        stack.close()
