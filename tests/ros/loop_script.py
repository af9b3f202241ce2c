"""The whole loop in one process: ``dgse ros sim``'s node and ``dgse ros run``'s node on one
executor, and a recorder of their topics into a rosbag2 folder.

Run by the tests with the Python that has ``rclpy`` (``DGSE_ROS_PYTHON``):
``python loop_script.py CASE OUT_DIR METHOD SEED``. Writes ``OUT_DIR/stats.json`` (the search
node's stats), ``OUT_DIR/live.npz`` (the final belief) and the bag ``OUT_DIR/bag``.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
import rclpy
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped, Vector3Stamped
from nav_msgs.msg import OccupancyGrid
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_msgs.msg import Float64

from dgse.ros.nodes import LATCHED, STREAM, SearchNode, SimNode, spin_until
from dgse.ros.replay import BagRecorder

TOPICS = {
    "/map": (OccupancyGrid, "nav_msgs/msg/OccupancyGrid", LATCHED),
    "/amcl_pose": (PoseWithCovarianceStamped, "geometry_msgs/msg/PoseWithCovarianceStamped", STREAM),
    "/gas": (Float64, "std_msgs/msg/Float64", STREAM),
    "/wind": (Vector3Stamped, "geometry_msgs/msg/Vector3Stamped", STREAM),
    "/gsl/goal": (PoseStamped, "geometry_msgs/msg/PoseStamped", LATCHED),
}


def main(case: str, out: str, method: str, seed: int) -> None:
    out_dir = Path(out)
    sim_time = [Parameter("use_sim_time", value=True)]
    rclpy.init()
    sim = SimNode(
        parameters={"case": case, "seed": seed, "rate": 0.0, "origin_x": -1.5, "origin_y": 2.0,
                    "min_start_distance": 1.0, "message_types": "standard"},
    )  # fmt: skip
    run = SearchNode(
        parameters={
            "method": method,
            "seed": seed,
            "case_name": Path(case).stem,
            "message_types": "standard",
        },
        stats=out_dir / "stats.json",
        parameter_overrides=sim_time,
    )
    recorder = Node("dgse_recorder", parameter_overrides=sim_time)
    bag = BagRecorder(out_dir / "bag", {t: m for t, (_, m, _) in TOPICS.items()})

    def keep(topic: str):
        return lambda data: bag.record(topic, data, recorder.get_clock().now().nanoseconds)

    for topic, (kind, _, qos) in TOPICS.items():
        recorder.create_subscription(kind, topic, keep(topic), qos, raw=True)
    executor = SingleThreadedExecutor()
    for n in (recorder, sim, run):
        executor.add_node(n)
    t0 = time.monotonic()
    done = spin_until(executor, lambda: run.core.stopped, 60.0)
    t_end = time.monotonic() + 0.3
    spin_until(executor, lambda: time.monotonic() > t_end, 1.0)  # the last messages into the bag
    bag.close()
    print(f"loop {'stopped' if done else 'timed out'} after {time.monotonic() - t0:.1f} s", flush=True)
    belief = run.core.belief
    np.savez(out_dir / "live.npz", source_probs=belief.source_probs if belief is not None else np.zeros(0))
    run.write_stats()
    rclpy.shutdown()


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4]))
