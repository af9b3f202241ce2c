"""Tests of dgse.ros: the pure-Python cores here, the ROS 2 nodes through the Python that has
``rclpy`` (``DGSE_ROS_PYTHON``, else this one when it imports ``rclpy``)."""

from __future__ import annotations

import importlib.util
import os
import random
import sys
from pathlib import Path

SRC = Path(__file__).resolve().parents[2] / "src"
REPO = SRC.parent

#: The small case of the loop tests: tests.search's two rooms (3 x 2 m) solved, and the
#: method and seed whose search from the drawn start ends well within 2 m of the source.
METHOD, SEED = "dualmode", 3
#: The simulated map's origin in the map frame (not the grid's corner: frames are tested).
ORIGIN = (-1.5, 2.0)


def ros_python() -> str | None:
    """The Python interpreter with ``rclpy``: ``$DGSE_ROS_PYTHON``, or this one if it has it."""
    given = os.environ.get("DGSE_ROS_PYTHON")
    if given:
        return given
    return sys.executable if importlib.util.find_spec("rclpy") is not None else None


def ros_env() -> dict[str, str]:
    """The environment of a ROS process of the tests: this checkout's package, a random
    domain, discovery on the loopback only."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(SRC), str(REPO), env.get("PYTHONPATH")]))
    env["ROS_DOMAIN_ID"] = str(random.randint(1, 101))
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env["ROS_LOCALHOST_ONLY"] = "1"
    return env
