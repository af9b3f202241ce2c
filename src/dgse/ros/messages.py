"""ROS messages as plain numbers, and back: the topics of ``dgse ros`` and their units.

The functions read messages by their field names only, so the same code serves the
messages of ``rclpy`` (a live node) and the ones :mod:`rosbags` deserializes (a replay).

=================  =================================  ======================================
what               message types                      meaning, units
=================  =================================  ======================================
map                ``nav_msgs/OccupancyGrid``         -1 unknown, 0 free .. 100 occupied;
                                                      ``info.origin`` (no rotation), m
pose               ``geometry_msgs/PoseWithCovar-     the robot's position in the map
                   ianceStamped`` or ``PoseStamped``  frame, m (orientation unused)
gas                ``olfaction_msgs/GasSensor``       ``raw`` in ppm (``raw_units`` 3) or
                                                      ppb (4, divided by 1000); its stamp
                   ``std_msgs/Float64``               ppm; the time it arrives
wind               ``olfaction_msgs/Anemometer``      ``wind_speed`` m/s towards
                                                      ``wind_direction`` rad (map frame,
                                                      counter-clockwise from +x)
                   ``geometry_msgs/Vector3Stamped``   ``vector.x, vector.y`` m/s, map frame
=================  =================================  ======================================
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from dgse.errors import InputDataError
from dgse.ros.core import MapGrid

__all__ = [
    "GAS_UNITS",
    "gas_reading",
    "map_grid",
    "pose_xy",
    "scaled_grid",
    "seconds",
    "wind_reading",
]

#: ``olfaction_msgs/GasSensor.raw_units`` values the search reads, with their factor to ppm.
GAS_UNITS = {3: 1.0, 4: 1e-3}


def seconds(stamp: Any) -> float:
    """A ``builtin_interfaces/Time`` as seconds."""
    return float(stamp.sec) + 1e-9 * float(stamp.nanosec)


def _header_time(msg: Any) -> float | None:
    header = getattr(msg, "header", None)
    if header is None:
        return None
    t = seconds(header.stamp)
    return t if t > 0 else None  # an unset stamp


def map_grid(msg: Any) -> MapGrid:
    """A ``nav_msgs/OccupancyGrid`` as a :class:`~dgse.ros.core.MapGrid`.

    Raises:
        InputDataError: a rotated origin, or data that do not fill the grid.
    """
    info = msg.info
    W, H = int(info.width), int(info.height)
    data = np.asarray(msg.data, dtype=np.int16)
    if data.size != W * H or W < 1 or H < 1:
        raise InputDataError(f"the map's data hold {data.size} cells, its size is {W} x {H}")
    q = info.origin.orientation
    if abs(float(q.z)) > 1e-6 or abs(float(q.x)) > 1e-6 or abs(float(q.y)) > 1e-6:
        raise InputDataError("the map's origin is rotated: only maps aligned with their frame are supported")
    frame = getattr(getattr(msg, "header", None), "frame_id", "") or "map"
    origin = (float(info.origin.position.x), float(info.origin.position.y))
    # the resolution is a float32 on the wire: its 7 significant digits are the cell size meant
    resolution = float(f"{float(info.resolution):.7g}")
    return MapGrid(data.reshape(H, W), resolution, origin, frame)


def pose_xy(msg: Any) -> tuple[float, float, float | None]:
    """``(x, y, t)`` of a ``PoseWithCovarianceStamped`` or ``PoseStamped`` (``t``: its stamp)."""
    pose = msg.pose
    pose = getattr(pose, "pose", pose)
    return float(pose.position.x), float(pose.position.y), _header_time(msg)


def gas_reading(msg: Any) -> tuple[float, float | None]:
    """``(ppm, t)`` of a gas message (``t`` None for a message without a stamp).

    Raises:
        InputDataError: a ``GasSensor`` in units other than ppm or ppb.
    """
    if hasattr(msg, "raw"):
        units = int(getattr(msg, "raw_units", 3))
        if units not in GAS_UNITS:
            raise InputDataError(f"gas sensor readings in units {units}: the search reads ppm (3) or ppb (4)")
        return float(msg.raw) * GAS_UNITS[units], _header_time(msg)
    return float(msg.data), None


def wind_reading(msg: Any) -> tuple[float, float, float | None]:
    """``(u, v, t)`` m/s in the map frame of a wind message (``t`` None without a stamp)."""
    if hasattr(msg, "wind_speed"):
        s, a = float(msg.wind_speed), float(msg.wind_direction)
        return s * math.cos(a), s * math.sin(a), _header_time(msg)
    vec = getattr(msg, "vector", msg)
    return float(vec.x), float(vec.y), _header_time(msg)


def scaled_grid(values: np.ndarray, free: np.ndarray) -> tuple[list[int], float]:
    """A field as ``OccupancyGrid`` data: ``round(100 v / max v)`` in free cells, -1 in walls.

    Returns:
        The row-major cell values and the scale (the field's value at 100; 0 for an
        all-zero field).
    """
    v = np.where(free, np.nan_to_num(np.asarray(values, np.float64), nan=0.0), 0.0)
    top = float(v.max()) if v.size else 0.0
    scaled = np.zeros(v.shape) if top <= 0 else np.clip(np.rint(100.0 * v / top), 0, 100)
    out = np.where(free, scaled, -1).astype(np.int8)
    return out.reshape(-1).tolist(), top
