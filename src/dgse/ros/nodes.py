"""The ROS 2 nodes of ``dgse ros run`` and ``dgse ros sim``: thin shells around the cores.

:class:`SearchNode` converts messages (:mod:`dgse.ros.messages`) and hands them to a
:class:`~dgse.ros.core.SearchCore`, then publishes what it decided; :class:`SimNode` plays
a :class:`~dgse.ros.sim.SimRobot`'s events on the same topics. Only stable ``rclpy`` calls
are used (nodes, parameters, publishers, subscriptions, timers, an action client), so any
ROS 2 from Humble on serves. Every setting is a ROS parameter (:data:`RUN_PARAMETERS`,
:data:`SIM_PARAMETERS`); the commands give their options as the parameters' defaults, and
``--ros-args -p name:=value`` overrides them.
"""

from __future__ import annotations

import json
import math
import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np
import rclpy
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped, Vector3Stamped
from nav_msgs.msg import OccupancyGrid
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.time import Time
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64, String
from visualization_msgs.msg import Marker, MarkerArray

from dgse.errors import DGSEError, InputDataError
from dgse.files import json_safe, write_json
from dgse.presets import PROTOCOL
from dgse.ros.core import Decision, MapGrid, MethodSetup, SearchCore
from dgse.ros.messages import gas_reading, map_grid, pose_xy, scaled_grid, wind_reading
from dgse.ros.sim import SimEvent, SimRobot

__all__ = [
    "RUN_PARAMETERS",
    "SIM_PARAMETERS",
    "SearchNode",
    "SimNode",
    "olfaction_types",
    "run_search",
    "run_sim",
    "spin_until",
]

#: The map and the status: the last one kept for late subscribers.
LATCHED = QoSProfile(
    depth=1,
    history=HistoryPolicy.KEEP_LAST,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
    reliability=ReliabilityPolicy.RELIABLE,
)
#: Poses and readings: reliable with room for a burst (a fast simulation).
STREAM = QoSProfile(depth=200, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)

#: ``dgse ros run``'s parameters and defaults (topics relative to the node's namespace).
RUN_PARAMETERS: dict[str, Any] = {
    "map_topic": "map",
    "pose_topic": "amcl_pose",
    "gas_topic": "gas",
    "wind_topic": "wind",
    "goal_topic": "gsl/goal",
    "output_prefix": "gsl",
    "frame_id": "map",
    "message_types": "auto",
    "method": "",
    "knowledge": "map",
    "knowledge_file": "",
    "resolution": 0.0,
    "occupied_threshold": 50,
    "unknown_solid": True,
    "seed": 0,
    "case_name": "",
    "trial": 0,
    "dwell": PROTOCOL.dwell,
    "time_limit": PROTOCOL.time_limit,
    "sample_rate_hz": 0.0,
    "use_nav2": False,
    "nav2_action": "navigate_to_pose",
    "status_period": 0.5,
}

#: ``dgse ros sim``'s parameters and defaults.
SIM_PARAMETERS: dict[str, Any] = {
    "case": "",
    "map_topic": "map",
    "pose_topic": "amcl_pose",
    "gas_topic": "gas",
    "wind_topic": "wind",
    "goal_topic": "gsl/goal",
    "status_topic": "gsl/status",
    "frame_id": "map",
    "message_types": "auto",
    "origin_x": 0.0,
    "origin_y": 0.0,
    "seed": 0,
    "case_name": "",
    "trial": 0,
    "start": [-1, -1],
    "speed": PROTOCOL.speed,
    "dwell": PROTOCOL.dwell,
    "time_limit": PROTOCOL.time_limit,
    "min_start_distance": PROTOCOL.min_start_distance,
    "sample_rate_hz": 0.0,
    "frames": True,
    "rate": 1.0,
    "period": 0.02,
    "repeat_period": 0.2,
    "time_offset": 100.0,
}


def olfaction_types() -> tuple[type, type] | None:
    """``(GasSensor, Anemometer)`` of ``olfaction_msgs`` when it is importable (GADEN's)."""
    try:
        from olfaction_msgs.msg import Anemometer, GasSensor
    except ImportError:
        return None
    return GasSensor, Anemometer


def _reading_types(choice: str) -> tuple[type, type]:
    olf = olfaction_types()
    if choice == "olfaction":
        if olf is None:
            raise InputDataError("message_types 'olfaction' needs olfaction_msgs (GADEN's messages)")
        return olf
    if choice == "standard" or olf is None:
        return Float64, Vector3Stamped
    if choice != "auto":
        raise InputDataError(f"message_types must be auto, olfaction or standard, got {choice!r}")
    return olf


def _stamp(t: float) -> Any:
    return Time(nanoseconds=round(t * 1e9)).to_msg()


def _declare(node: Node, defaults: dict[str, Any], given: dict[str, Any]) -> dict[str, Any]:
    """Declare every parameter (``given`` over ``defaults``; ``--ros-args -p`` over both)."""
    out = {}
    for name, default in defaults.items():
        value = given.get(name, default)
        node.declare_parameter(name, value)
        out[name] = node.get_parameter(name).value
    return out


def _topic(prefix: str, name: str) -> str:
    return f"{prefix.rstrip('/')}/{name}" if prefix else name


class SearchNode(Node):
    """``dgse ros run``: the search on the robot's topics (module docstring).

    Args:
        name: the node's name.
        parameters: values of :data:`RUN_PARAMETERS` (the command's options).
        stats: write the decisions and the latency to this JSON file when the node stops.
        **kw: passed to ``rclpy.node.Node`` (e.g. ``parameter_overrides``).
    """

    def __init__(
        self,
        name: str = "dgse_search",
        parameters: dict[str, Any] | None = None,
        stats: str | Path | None = None,
        **kw: Any,
    ):
        super().__init__(name, **kw)
        p = self.params = _declare(self, RUN_PARAMETERS, parameters or {})
        self.setup = MethodSetup.from_parameters(p)
        self.messages: list[tuple[str, str]] = []
        self.core = SearchCore(
            self.setup,
            self._log,
            occupied_threshold=int(p["occupied_threshold"]),
            unknown_solid=bool(p["unknown_solid"]),
        )
        gas_type, wind_type = _reading_types(p["message_types"])
        out = p["output_prefix"]
        self.create_subscription(OccupancyGrid, p["map_topic"], self._on_map, LATCHED)
        self.create_subscription(PoseWithCovarianceStamped, p["pose_topic"], self._on_pose, STREAM)
        self.create_subscription(wind_type, p["wind_topic"], self._on_wind, STREAM)
        self.create_subscription(gas_type, p["gas_topic"], self._on_gas, STREAM)
        self.goal_pub = self.create_publisher(PoseStamped, p["goal_topic"], LATCHED)
        self.source_pub = self.create_publisher(PoseStamped, _topic(out, "source"), LATCHED)
        self.status_pub = self.create_publisher(String, _topic(out, "status"), LATCHED)
        self.grid_pubs = {
            k: self.create_publisher(OccupancyGrid, _topic(out, k), LATCHED)
            for k in ("source_posterior", "concentration", "wind_speed")
        }
        self.marker_pub = self.create_publisher(MarkerArray, _topic(out, "markers"), LATCHED)
        self.nav = None
        if p["use_nav2"]:
            self.nav = _nav2_client(self, p["nav2_action"])
        self.latencies: list[float] = []
        self.overheads: list[float] = []  # the latency less the search step's computation
        self.stats_path = None if stats is None else Path(stats)
        self.create_timer(float(p["status_period"]), self._tick)
        self._last_status = ""

    # -- callbacks -----------------------------------------------------------------------
    def _log(self, level: str, message: str) -> None:
        self.messages.append((level, message))
        logger = self.get_logger()
        {"info": logger.info, "warning": logger.warning}.get(level, logger.error)(message)

    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _on_map(self, msg: OccupancyGrid) -> None:
        try:
            grid = map_grid(msg)
        except InputDataError as e:
            self._log("error", f"map refused: {e}")
            return
        self.core.set_map(grid)
        self._publish_status()

    def _on_pose(self, msg: PoseWithCovarianceStamped) -> None:
        x, y, t = pose_xy(msg)
        self.core.set_pose(x, y, self._now() if t is None else t)

    def _on_wind(self, msg: Any) -> None:
        arrived = time.perf_counter()
        u, v, t = wind_reading(msg)
        decision = self._step(lambda: self.core.set_wind(u, v, self._now() if t is None else t))
        if decision is not None:
            self._publish(decision, arrived)

    def _on_gas(self, msg: Any) -> None:
        arrived = time.perf_counter()
        try:
            ppm, t = gas_reading(msg)
        except InputDataError as e:
            self._log("warning", f"gas reading refused: {e}")
            return
        decision = self._step(lambda: self.core.add_gas(ppm, self._now() if t is None else t))
        if decision is not None:
            self._publish(decision, arrived)

    def _step(self, step: Any) -> Decision | None:
        try:
            return step()
        except DGSEError as e:  # an estimator or planner refusing this input: logged, the node goes on
            self._log("error", f"search step failed: {e}")
            return None

    def _tick(self) -> None:
        if self.core.check_time(self._now()):
            self._finish()
        self._publish_status()

    # -- outputs -------------------------------------------------------------------------
    def _pose(self, xy: tuple[float, float]) -> PoseStamped:
        msg = PoseStamped()
        msg.header.frame_id = self.params["frame_id"]
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.pose.position.x, msg.pose.position.y = float(xy[0]), float(xy[1])
        msg.pose.orientation.w = 1.0
        return msg

    def _publish(self, d: Decision, arrived: float) -> None:
        if d.goal_xy is not None:
            self._send_goal(d.goal_xy)
        latency = time.perf_counter() - arrived
        self.latencies.append(latency)
        self.overheads.append(latency - d.compute_s)
        self._publish_belief(d)
        if d.reason is not None:
            self._finish()
        self._publish_status()

    def _send_goal(self, xy: tuple[float, float]) -> None:
        pose = self._pose(xy)
        self.goal_pub.publish(pose)
        if self.nav is not None:
            self.nav.send(pose)

    def goal_rejected(self) -> None:
        """The navigation refused the goal: publish the next choice."""
        arrived = time.perf_counter()
        d = self.core.goal_rejected()
        if d is not None:
            self._publish(d, arrived)

    def _finish(self) -> None:
        if self.core.declared_xy is not None:
            self.source_pub.publish(self._pose(self.core.declared_xy))
        self._log("info", f"search stopped: {self.core.reason}")
        self.write_stats()

    def _grid(self, values: np.ndarray) -> tuple[OccupancyGrid, float]:
        core = self.core
        assert core.map is not None and core.occupancy is not None
        msg = OccupancyGrid()
        msg.header.frame_id = self.params["frame_id"]
        msg.header.stamp = self.get_clock().now().to_msg()
        H, W = core.occupancy.shape
        msg.info.resolution = float(core.resolution)
        msg.info.width, msg.info.height = W, H
        msg.info.origin.position.x, msg.info.origin.position.y = core.map.origin
        msg.info.origin.orientation.w = 1.0
        data, scale = scaled_grid(values, core.occupancy == 0)
        msg.data = data
        return msg, scale

    def _publish_belief(self, d: Decision) -> None:
        b = d.belief
        fields = {"source_posterior": b.source_probs}
        if b.log_conc_mean is not None:
            fields["concentration"] = np.expm1(b.log_conc_mean)
        if b.wind_mean is not None:
            fields["wind_speed"] = np.hypot(b.wind_mean[0], b.wind_mean[1])
        self.scales = {}
        for k, v in fields.items():
            msg, self.scales[k] = self._grid(v)
            self.grid_pubs[k].publish(msg)
        self.marker_pub.publish(self._markers(d))

    def _markers(self, d: Decision) -> MarkerArray:
        core = self.core
        out = MarkerArray()
        frame = self.params["frame_id"]

        def marker(ident: int, kind: int, rgba: tuple[float, float, float, float], size: float) -> Marker:
            m = Marker()
            m.header.frame_id = frame
            m.header.stamp = self.get_clock().now().to_msg()
            m.ns, m.id, m.type, m.action = "dgse", ident, kind, Marker.ADD
            m.pose.orientation.w = 1.0
            m.scale.x = m.scale.y = m.scale.z = size
            m.color.r, m.color.g, m.color.b, m.color.a = rgba
            return m

        src = marker(0, Marker.SPHERE, (1.0, 0.1, 0.1, 0.9), 0.3)
        src.pose.position.x, src.pose.position.y = d.declared_xy
        out.markers.append(src)
        pts = marker(1, Marker.SPHERE_LIST, (0.1, 0.4, 1.0, 0.9), 0.12)
        for c in (x.cell for x in core.decisions):
            p = type(src.pose.position)()
            p.x, p.y = core.center_of(c)
            pts.points.append(p)
        out.markers.append(pts)
        if d.goal_xy is not None:
            goal = marker(2, Marker.CYLINDER, (0.1, 0.9, 0.2, 0.8), 0.2)
            goal.pose.position.x, goal.pose.position.y = d.goal_xy
            out.markers.append(goal)
        return out

    def _publish_status(self) -> None:
        status = json.dumps(json_safe({**self.core.status(), "scales": getattr(self, "scales", {})}))
        if status != self._last_status:
            self._last_status = status
            self.status_pub.publish(String(data=status))

    # -- measurements --------------------------------------------------------------------
    def stats(self) -> dict[str, Any]:
        """The decisions so far; the latency from a reading's arrival to the next goal's
        publication, the search step's computation time (estimate, stop test, plan) and the
        difference (the node's own handling), each as median and 95th percentile in ms."""
        compute = [d.compute_s for d in self.core.decisions]

        def summary(v: list[float]) -> dict[str, float | None]:
            if not v:
                return {"median_ms": None, "p95_ms": None, "n": 0}
            return {
                "median_ms": 1e3 * statistics.median(v),
                "p95_ms": 1e3 * float(np.percentile(v, 95)),
                "n": len(v),
            }

        return {
            "latency": summary(self.latencies),
            "step_compute": summary(compute),
            "overhead": summary(self.overheads),
            "status": self.core.status(),
            "method": self.setup.method.to_json(),
            "decisions": [d.to_dict() for d in self.core.decisions],
            "messages": [list(m) for m in self.messages],
        }

    def write_stats(self) -> None:
        """Write :meth:`stats` to the ``stats`` file, if one was given."""
        if self.stats_path is not None:
            self.stats_path.parent.mkdir(parents=True, exist_ok=True)
            write_json(self.stats_path, json_safe(self.stats()), indent=1)


def _nav2_client(node: SearchNode, action: str) -> Any:
    """A NavigateToPose client that tells ``node`` of a refused goal (None without nav2_msgs)."""
    try:
        from nav2_msgs.action import NavigateToPose
        from rclpy.action import ActionClient
    except ImportError:
        node._log(
            "warning", "use_nav2 is set but nav2_msgs is not importable: goals go to the goal topic only"
        )
        return None

    class Nav:
        def __init__(self) -> None:
            self.client = ActionClient(node, NavigateToPose, action)

        def send(self, pose: PoseStamped) -> None:
            goal = NavigateToPose.Goal()
            goal.pose = pose
            if not self.client.wait_for_server(timeout_sec=1.0):
                node._log("warning", f"Nav2 action {action!r} is not available: goal on the topic only")
                return
            self.client.send_goal_async(goal).add_done_callback(self._answered)

        def _answered(self, future: Any) -> None:
            handle = future.result()
            if not handle.accepted:
                node.goal_rejected()
                return
            handle.get_result_async().add_done_callback(self._done)

        def _done(self, future: Any) -> None:
            from action_msgs.msg import GoalStatus

            if future.result().status == GoalStatus.STATUS_ABORTED:
                node.goal_rejected()

    return Nav()


class SimNode(Node):
    """``dgse ros sim``: a simulated robot on the search's topics (module docstring).

    Publishes the case's map (latched), ``/clock`` (the simulated clock: run the search with
    ``use_sim_time``), the pose at every cell entered and the reading at the end of each
    dwell (and on the way, with ``sample_rate_hz``), the last again every ``repeat_period`` s of
    wall time while it waits (a sensor that keeps publishing); drives to each goal that arrives
    on the goal topic.
    """

    def __init__(self, name: str = "dgse_sim", parameters: dict[str, Any] | None = None, **kw: Any):
        super().__init__(name, **kw)
        from dgse.world.case import Case

        p = self.params = _declare(self, SIM_PARAMETERS, parameters or {})
        if not p["case"]:
            raise InputDataError("the simulation needs a case file (parameter 'case')")
        path = Path(p["case"])
        case = Case.load(path)
        start = [int(v) for v in p["start"]]
        self.robot = SimRobot(
            case,
            seed=int(p["seed"]),
            case_name=p["case_name"] or path.stem,
            trial=int(p["trial"]),
            start=None if min(start) < 0 else start,
            speed=float(p["speed"]),
            dwell=float(p["dwell"]),
            time_limit=float(p["time_limit"]),
            use_frames=bool(p["frames"]),
            min_start_distance=float(p["min_start_distance"]),
            sample_rate_hz=float(p["sample_rate_hz"]) or None,
        )
        self.case = case
        self.origin = (float(p["origin_x"]), float(p["origin_y"]))
        self.offset = float(p["time_offset"])
        self.rate = float(p["rate"])
        self.gas_type, self.wind_type = _reading_types(p["message_types"])
        self.clock_pub = self.create_publisher(Clock, "/clock", 10)
        self.map_pub = self.create_publisher(OccupancyGrid, p["map_topic"], LATCHED)
        self.pose_pub = self.create_publisher(PoseWithCovarianceStamped, p["pose_topic"], STREAM)
        self.gas_pub = self.create_publisher(self.gas_type, p["gas_topic"], STREAM)
        self.wind_pub = self.create_publisher(self.wind_type, p["wind_topic"], STREAM)
        self.create_subscription(PoseStamped, p["goal_topic"], self._on_goal, LATCHED)
        self.create_subscription(String, p["status_topic"], self._on_status, LATCHED)
        self.t_sim = 0.0
        self.last_pose: SimEvent | None = None
        self.done = False
        self.goals = 0
        self._last_repeat = time.monotonic()
        self._publish_map()
        self.create_timer(float(p["period"]), self._tick)

    def _publish_map(self) -> None:
        grid = MapGrid.from_occupancy(self.case.occupancy, self.case.resolution, self.origin)
        msg = OccupancyGrid()
        msg.header.frame_id = self.params["frame_id"]
        msg.header.stamp = _stamp(self.offset)
        H, W = grid.values.shape
        msg.info.resolution = grid.resolution
        msg.info.width, msg.info.height = W, H
        msg.info.origin.position.x, msg.info.origin.position.y = self.origin
        msg.info.origin.orientation.w = 1.0
        msg.data = grid.values.reshape(-1).tolist()
        self.map_pub.publish(msg)

    def _xy(self, cell: tuple[int, int]) -> tuple[float, float]:
        x, y = self.robot.position(cell)
        return self.origin[0] + x, self.origin[1] + y

    def _publish_event(self, e: SimEvent) -> None:
        stamp = _stamp(self.offset + e.time_s)
        frame = self.params["frame_id"]
        if e.kind == "pose":
            msg = PoseWithCovarianceStamped()
            msg.header.frame_id, msg.header.stamp = frame, stamp
            msg.pose.pose.position.x, msg.pose.pose.position.y = self._xy(e.cell)
            msg.pose.pose.orientation.w = 1.0
            self.pose_pub.publish(msg)
            self.last_pose = e
            return
        wind = self.wind_type()
        if hasattr(wind, "wind_speed"):
            wind.header.frame_id, wind.header.stamp = frame, stamp
            wind.wind_speed = float(math.hypot(*e.wind))
            wind.wind_direction = float(math.atan2(e.wind[1], e.wind[0]))
        else:
            wind.header.frame_id, wind.header.stamp = frame, stamp
            wind.vector.x, wind.vector.y = float(e.wind[0]), float(e.wind[1])
        self.wind_pub.publish(wind)
        gas = self.gas_type()
        if hasattr(gas, "raw"):
            gas.header.frame_id, gas.header.stamp = frame, stamp
            gas.raw, gas.raw_units = float(e.gas), 3
        else:
            gas.data = float(e.gas)
        self.gas_pub.publish(gas)

    def _publish_clock(self) -> None:
        msg = Clock()
        msg.clock = _stamp(self.offset + self.t_sim)
        self.clock_pub.publish(msg)

    def _tick(self) -> None:
        robot = self.robot
        until = math.inf if self.rate <= 0 else self.t_sim + self.rate * float(self.params["period"])
        for e in robot.due(until):
            self.t_sim = e.time_s
            self._publish_clock()
            self._publish_event(e)
        if robot.events:  # on the way: the clock runs at the rate
            self.t_sim = until
        self._publish_clock()
        now = time.monotonic()
        if not robot.events and now - self._last_repeat >= float(self.params["repeat_period"]):
            self._last_repeat = now
            if self.last_pose is not None:
                self._publish_event(self.last_pose)
            if robot.last_reading is not None:
                self._publish_event(robot.last_reading)

    def _on_goal(self, msg: PoseStamped) -> None:
        x = msg.pose.position.x - self.origin[0]
        y = msg.pose.position.y - self.origin[1]
        res = self.case.resolution
        cell = (math.floor(y / res), math.floor(x / res))
        if self.robot.go_to(cell):
            self.goals += 1
        else:
            self.get_logger().warning(f"goal ({msg.pose.position.x:.2f}, {msg.pose.position.y:.2f}) refused")

    def _on_status(self, msg: String) -> None:
        try:
            state = json.loads(msg.data).get("state")
        except (ValueError, AttributeError):
            return
        if state == "stopped":
            self.done = True


def spin_until(executor: Any, done: Any, timeout_s: float) -> bool:
    """Spin ``executor`` until ``done()`` or ``timeout_s`` s of wall time; True when done."""
    t_end = time.monotonic() + timeout_s
    while rclpy.ok() and not done():
        if time.monotonic() > t_end:
            return False
        executor.spin_once(timeout_sec=0.05)
    return True


def _spin(nodes: list[Node], done: Any, timeout_s: float | None) -> bool:
    from rclpy.executors import SingleThreadedExecutor

    executor = SingleThreadedExecutor()
    for n in nodes:
        executor.add_node(n)
    try:
        return spin_until(executor, done, math.inf if timeout_s is None else timeout_s)
    finally:
        executor.shutdown()


def run_search(
    parameters: dict[str, Any],
    *,
    ros_args: list[str] | tuple[str, ...] = (),
    sim_time: bool = False,
    stats: str | Path | None = None,
    exit_on_stop: bool = False,
    timeout_s: float | None = None,
) -> dict[str, Any]:
    """``dgse ros run``: spin a :class:`SearchNode` (until the search stops with ``exit_on_stop``,
    else until Ctrl-C or ``timeout_s``); returns its :meth:`~SearchNode.stats`."""
    from rclpy.parameter import Parameter

    rclpy.init(args=["dgse", *ros_args])
    node = None
    try:
        overrides = [Parameter("use_sim_time", value=True)] if sim_time else []
        node = SearchNode(parameters=parameters, stats=stats, parameter_overrides=overrides)
        _spin([node], lambda: exit_on_stop and node.core.stopped, timeout_s)
        return node.stats()
    finally:
        if node is not None:
            node.write_stats()
            node.destroy_node()
        rclpy.try_shutdown()


def run_sim(
    parameters: dict[str, Any],
    *,
    ros_args: list[str] | tuple[str, ...] = (),
    exit_on_stop: bool = False,
    timeout_s: float | None = None,
) -> dict[str, Any]:
    """``dgse ros sim``: spin a :class:`SimNode` (until the search says it stopped with
    ``exit_on_stop``); returns what it did."""
    rclpy.init(args=["dgse", *ros_args])
    node = None
    try:
        node = SimNode(parameters=parameters)
        _spin([node], lambda: exit_on_stop and node.done, timeout_s)
        r = node.robot.robot
        return {"goals": node.goals, "start": list(r.start), "clock_s": r.clock, "distance_m": r.distance_m,
                "stopped": node.done}  # fmt: skip
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
