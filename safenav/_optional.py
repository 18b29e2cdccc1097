"""Optional dependencies: import them where they are needed, or say exactly what to install.

The core install (the filters) needs only numpy, qpsolvers, DAQP, OSQP and casadi, so it fits a
robot computer (PyBullet has no aarch64 wheel). The simulator, the plots, ROS and Gymnasium
are extras::

    pybullet = require("pybullet", extra="sim", purpose="the PyBullet simulator")

raises :class:`~safenav.errors.MissingDependency` (an ``ImportError``) with the line
``pip install "safenav[sim]"`` when PyBullet is absent.
"""

from __future__ import annotations

import importlib
from types import ModuleType

from safenav.errors import MissingDependency

__all__ = ["require"]


def require(module: str, *, extra: str, purpose: str, package: str | None = None) -> ModuleType:
    """Import ``module``, or raise :class:`~safenav.errors.MissingDependency` naming the extra.

    Args:
        module: the module to import (``"matplotlib.pyplot"``).
        extra: the safenav extra that installs it (``"sim"``).
        purpose: what needs it, for the message (``"plotting an episode"``).
        package: the distribution name when it differs from the top-level module name.
    """
    try:
        return importlib.import_module(module)
    except ImportError as error:
        top = module.partition(".")[0]
        if error.name is not None and error.name.partition(".")[0] != top:
            raise  # the package is there but one of its own imports failed: show that error
        raise MissingDependency(package or top, purpose, extra) from error
