"""``dgse ros replay``: the estimator over a rosbag2 recording, without ROS.

A recording of a search's topics (the map, the pose, the gas and wind readings and the
goals the search sent) is read with :mod:`rosbags` and fed, in the order it was recorded,
to a :class:`~dgse.ros.core.SearchCore` that follows the recorded goals
(``follow_goals``): it takes the readings the live search took (at each goal, after the
dwell) and runs the estimator on them, and the planner not at all. With the live run's
method and seed the beliefs are the live run's. A gas message without a stamp
(``std_msgs/Float64``) has the time it was recorded (record a simulation with the
simulated clock: ``ros2 bag record --use-sim-time``).

Written into the output folder: ``beliefs.npz`` (:data:`NPZ_KEYS`, one row per reading
taken), ``belief.png`` (the last belief, :func:`dgse.viz.belief.plot_belief`) and
``beliefs.gif`` (the posterior over the readings, :func:`dgse.viz.belief.animate_beliefs`).
:class:`BagRecorder` writes such a recording from a live node's subscriptions.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from dgse.errors import InputDataError, UnsupportedError
from dgse.files import atomic_path
from dgse.ros.core import Log, MethodSetup, SearchCore
from dgse.ros.messages import gas_reading, map_grid, pose_xy, wind_reading

__all__ = ["DEFAULT_TOPICS", "NPZ_KEYS", "BagRecorder", "replay_bag"]

#: What each topic of a recording is, by default (``topics=`` overrides any of them).
DEFAULT_TOPICS: dict[str, str] = {
    "map": "/map",
    "pose": "/amcl_pose",
    "gas": "/gas",
    "wind": "/wind",
    "goal": "/gsl/goal",
}

#: The arrays of ``beliefs.npz``: per reading ``k``, ``source_probs[k]`` ``(H, W)`` (and
#: ``log_conc_mean``, ``wind_mean`` ``(2, H, W)`` when the estimator gives them), ``cells``
#: ``(i, j)``, ``gas`` ppm, ``wind`` m/s, ``times`` s on the search's clock; the map:
#: ``occupancy``, ``resolution`` m, ``origin`` (map frame, m).
NPZ_KEYS = ("source_probs", "cells", "gas", "wind", "times", "occupancy", "resolution", "origin")


def _rosbags() -> Any:
    try:
        from rosbags.highlevel import AnyReader
    except ImportError as e:
        raise UnsupportedError(
            "reading ROS bags needs rosbags: pip install 'dgse[ros]' (or pip install rosbags)"
        ) from e
    return AnyReader


def replay_bag(
    bag: str | Path,
    out_dir: str | Path,
    parameters: Mapping[str, Any] | None = None,
    *,
    topics: Mapping[str, str] | None = None,
    log: Log | None = None,
    figures: bool = True,
) -> dict[str, Any]:
    """Run the method's estimator over the recording ``bag`` (module docstring).

    Args:
        parameters: the method and its seeds as ``dgse ros run``'s parameters
            (:meth:`~dgse.ros.core.MethodSetup.from_parameters`; the live run's give its beliefs).
        bag: a rosbag2 folder (or a ROS 1 bag: :mod:`rosbags` reads both).
        out_dir: where the files go.
        topics: the recording's topic of ``"map"``, ``"pose"``, ``"gas"``, ``"wind"``,
            ``"goal"`` (:data:`DEFAULT_TOPICS` for the others).
        figures: write the figure and the animation too.

    Returns:
        ``{"readings": n, "files": {...}, "messages": [...], "final": {...}}``.

    Raises:
        InputDataError: no such bag, a topic missing from it, or no reading taken.
    """
    AnyReader = _rosbags()
    bag, out_dir = Path(bag), Path(out_dir)
    if not bag.exists():
        raise InputDataError(f"{bag}: no such bag")
    names = {**DEFAULT_TOPICS, **(topics or {})}
    messages: list[tuple[str, str]] = []

    def note(level: str, message: str) -> None:
        messages.append((level, message))
        if log is not None:
            log(level, message)

    core = SearchCore(MethodSetup.from_parameters(parameters or {}), note, follow_goals=True)
    kinds = {topic: kind for kind, topic in names.items()}
    with AnyReader([bag]) as reader:
        conns = [c for c in reader.connections if c.topic in kinds]
        present = {c.topic for c in conns}
        missing = [names[k] for k in ("map", "pose", "gas", "wind", "goal") if names[k] not in present]
        if missing:
            found = ", ".join(sorted({c.topic for c in reader.connections})) or "none"
            raise InputDataError(f"{bag.name}: no topic {', '.join(missing)} (its topics: {found})")
        for conn, t_ns, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            _feed(core, kinds[conn.topic], msg, t_ns * 1e-9, note)
    if not core.decisions:
        raise InputDataError(f"{bag.name}: the search took no reading (are the goal and pose topics right?)")
    files = _write(core, out_dir, figures)
    last = core.decisions[-1]
    final = {"steps": len(core.decisions), "estimate_xy": list(last.declared_xy),
             "normalized_entropy": last.belief.normalized_entropy()}  # fmt: skip
    return {"readings": len(core.decisions), "files": files, "messages": messages, "final": final}


def _feed(core: SearchCore, kind: str, msg: Any, t_log: float, note: Log) -> None:
    """One recorded message into ``core`` (stamps where they exist, else the record time)."""
    try:
        if kind == "map":
            core.set_map(map_grid(msg))
        elif kind == "pose":
            x, y, t = pose_xy(msg)
            core.set_pose(x, y, t_log if t is None else t)
        elif kind == "wind":
            u, v, t = wind_reading(msg)
            core.set_wind(u, v, t_log if t is None else t)
        elif kind == "gas":
            ppm, t = gas_reading(msg)
            core.add_gas(ppm, t_log if t is None else t)
        elif kind == "goal":
            x, y, _ = pose_xy(msg)
            core.set_goal(x, y)
    except InputDataError as e:
        note("warning", f"{kind} message refused: {e}")


def _write(core: SearchCore, out_dir: Path, figures: bool) -> dict[str, str]:
    assert core.map is not None and core.occupancy is not None
    out_dir.mkdir(parents=True, exist_ok=True)
    ds = core.decisions
    arrays: dict[str, np.ndarray] = {
        "source_probs": np.stack([d.belief.source_probs for d in ds]),
        "cells": np.array([d.cell for d in ds], np.int64),
        "gas": np.array([d.gas for d in ds]),
        "wind": np.array([d.wind for d in ds]),
        "times": np.array([d.time_s for d in ds]),
        "occupancy": core.occupancy.astype(np.uint8),
        "resolution": np.array(core.resolution),
        "origin": np.array(core.map.origin),
    }
    if all(d.belief.log_conc_mean is not None for d in ds):
        arrays["log_conc_mean"] = np.stack([d.belief.log_conc_mean for d in ds]).astype(np.float32)
    if all(d.belief.wind_mean is not None for d in ds):
        arrays["wind_mean"] = np.stack([d.belief.wind_mean for d in ds]).astype(np.float32)
    npz = out_dir / "beliefs.npz"
    with atomic_path(npz) as tmp, open(tmp, "wb") as f:
        np.savez_compressed(f, **arrays)
    files = {"beliefs": str(npz)}
    if figures:
        from dgse.viz.belief import animate_beliefs, plot_belief

        assert core.stream is not None
        png = out_dir / "belief.png"
        fig = plot_belief(ds[-1].belief, observations=core.stream.observations)
        with atomic_path(png) as tmp:
            fig.savefig(tmp, dpi=110)
        gif = animate_beliefs(arrays["source_probs"], core.occupancy, core.resolution, arrays["cells"],
                              out_dir / "beliefs.gif")  # fmt: skip
        files.update(figure=str(png), animation=str(gif))
    return files


class BagRecorder:
    """Writes the messages a node receives into a rosbag2 folder with :mod:`rosbags`.

    ``record(topic, msgtype, data, t_ns)`` takes a message as the CDR bytes of a raw
    subscription (``create_subscription(..., raw=True)``) and the time to record it at.

    Args:
        path: the bag folder to create.
        msgtypes: ``topic -> "pkg/msg/Type"`` of each topic to record.
    """

    def __init__(self, path: str | Path, msgtypes: Mapping[str, str]) -> None:
        try:
            from rosbags.rosbag2 import Writer
            from rosbags.typesys import Stores, get_typestore
        except ImportError as e:
            raise UnsupportedError("recording ROS bags needs rosbags: pip install 'dgse[ros]'") from e
        store = get_typestore(Stores.LATEST)
        self.writer = Writer(Path(path), version=8)
        self.writer.open()
        self.conns = {t: self.writer.add_connection(t, m, typestore=store) for t, m in msgtypes.items()}
        self.count = 0

    def record(self, topic: str, data: bytes, t_ns: int) -> None:
        """Write one message of ``topic``."""
        self.writer.write(self.conns[topic], int(t_ns), bytes(data))
        self.count += 1

    def close(self) -> None:
        """Finish the bag (its metadata)."""
        self.writer.close()
