"""DGSE's search on a ROS 2 robot: ``dgse ros run``, ``dgse ros sim``, ``dgse ros replay``.

An optional extra (``pip install 'dgse[ros]'``, or a sourced ROS 2 that provides
``rclpy``); nothing else in the package imports it. The parts:

* :mod:`dgse.ros.core`: the search fed by messages, plain Python (maps to occupancy,
  reading bookkeeping, decisions through :func:`dgse.search.episode.search_step`);
* :mod:`dgse.ros.messages`: the topics' messages as numbers, units (no ROS needed);
* :mod:`dgse.ros.sim`: the simulated robot's events (``dgse search``'s robot);
* :mod:`dgse.ros.nodes`: the ``rclpy`` nodes, thin shells around those;
* :mod:`dgse.ros.replay`: the estimator over a rosbag2 recording (:mod:`rosbags`, no ROS).
"""

from __future__ import annotations

import importlib.util

from dgse.errors import UnsupportedError

__all__ = ["ROS_MISSING", "require_rclpy"]

#: What to do when ``rclpy`` is not importable.
ROS_MISSING = (
    "ROS 2 is not available here (no module rclpy): pip install 'dgse[ros]', "
    "or source your ROS 2 setup (e.g. /opt/ros/jazzy/setup.bash)"
)


def require_rclpy() -> None:
    """Raise :class:`~dgse.errors.UnsupportedError` (:data:`ROS_MISSING`) unless ``rclpy`` imports."""
    if importlib.util.find_spec("rclpy") is None:
        raise UnsupportedError(ROS_MISSING)
