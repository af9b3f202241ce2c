"""The ``dgse ros`` commands: the search on a ROS 2 robot (:mod:`dgse.ros`).

* ``dgse ros run``: the search node on the robot's topics (map, pose, gas, wind);
* ``dgse ros sim CASE``: a simulated robot on the same topics (``dgse search``'s robot);
* ``dgse ros replay BAG``: the estimator over a rosbag2 recording (no ROS needed).

ROS arguments (remappings, parameters, a parameter file) go after ``--``:
``dgse ros run -- --ros-args -r map:=/my_map -p dwell:=5.0``. ``dgse.ros`` is imported
only here, inside the commands; without ``rclpy`` the node commands print one line that
says how to get it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from dgse.belief.knowledge import DEFAULT_LEVEL
from dgse.cli.common import (
    DwellOption,
    FramesOption,
    KnowledgeOption,
    MethodOption,
    MinStartDistanceOption,
    SampleRateOption,
    SpeedOption,
    TimeLimitOption,
    check_output_dir,
    check_output_file,
    console,
    new_app,
    option_bundle,
    path_text,
    user_errors,
)
from dgse.errors import InputDataError
from dgse.presets import PROTOCOL

__all__ = ["register"]

#: Extra words after ``--`` go to ROS.
ROS_ARGS = {"allow_extra_args": True, "ignore_unknown_options": False}

SeedOption = Annotated[int, typer.Option("--seed", "-s", help="Seed, as dgse search --seed.")]
CaseNameOption = Annotated[
    str | None,
    typer.Option(
        "--case-name",
        help="Seed the planner as dgse search seeds its trials on the case file of this stem.",
    ),
]
TrialOption = Annotated[int, typer.Option("--trial", help="The trial of dgse search to repeat.")]
KnowledgeFileOption = Annotated[
    Path | None,
    typer.Option(
        "--knowledge-file",
        help="Case or layout file with the openings (and a case's wind field) of the robot's map.",
    ),
]
ExitOnStopOption = Annotated[
    bool, typer.Option("--exit-on-stop/--keep-running", help="Exit when the search stops.")
]
TimeoutOption = Annotated[
    float | None, typer.Option("--timeout", help="Stop after this many seconds of wall time.")
]
TypesOption = Annotated[
    str,
    typer.Option(
        "--message-types",
        help="Gas and wind messages: auto (olfaction_msgs when importable), olfaction or standard "
        "(std_msgs/Float64 ppm, geometry_msgs/Vector3Stamped m/s).",
    ),
]


def _method_params(
    method: MethodOption = None,
    knowledge: KnowledgeOption = DEFAULT_LEVEL,
    knowledge_file: KnowledgeFileOption = None,
    seed: SeedOption = 0,
    case_name: CaseNameOption = None,
    trial: TrialOption = 0,
) -> dict[str, Any]:
    """The node parameters of the method and its seeding, which ``ros run`` and ``ros replay``
    share (:func:`~dgse.cli.common.option_bundle`)."""
    return {"method": method or "", "knowledge": knowledge, "knowledge_file": str(knowledge_file or ""),
            "seed": seed, "case_name": case_name or "", "trial": trial}  # fmt: skip


def _ros_args(ctx: typer.Context) -> list[str]:
    """The ROS arguments after ``--`` of a node command, once ``rclpy`` is known to import."""
    extra = list(ctx.args)
    if extra and extra[0] != "--ros-args":
        words = " ".join(extra)
        raise InputDataError(f"unexpected arguments {words!r}: ROS arguments go after '-- --ros-args'")
    from dgse.ros import require_rclpy

    require_rclpy()
    return extra


@user_errors
@option_bundle("setup", _method_params)
def run_cmd(
    ctx: typer.Context,
    setup: dict[str, Any],
    resolution: Annotated[
        float | None,
        typer.Option("--resolution", help="The method's cell size, m (default: the map's)."),
    ] = None,
    dwell: DwellOption = PROTOCOL.dwell,
    time_limit: TimeLimitOption = PROTOCOL.time_limit,
    sample_rate: SampleRateOption = PROTOCOL.sample_rate_hz,
    pose_topic: Annotated[str, typer.Option("--pose-topic", help="The robot's pose topic.")] = "amcl_pose",
    message_types: TypesOption = "auto",
    nav2: Annotated[
        bool, typer.Option("--nav2/--no-nav2", help="Send goals through Nav2's NavigateToPose too.")
    ] = False,
    sim_time: Annotated[
        bool, typer.Option("--sim-time/--wall-time", help="Use the /clock of a simulation.")
    ] = False,
    stats: Annotated[
        Path | None,
        typer.Option("--stats", help="Write the decisions and the latency (reading to goal) as JSON."),
    ] = None,
    exit_on_stop: ExitOnStopOption = False,
    timeout: TimeoutOption = None,
) -> None:
    """Run the search node: subscribe the map, pose, gas and wind; publish goals and beliefs.

    ROS arguments (remappings, parameters) go after '-- --ros-args'.
    """
    check_output_file(stats, "stats file")
    args = _ros_args(ctx)
    from dgse.ros.nodes import run_search

    params: dict[str, Any] = {
        **setup,
        "resolution": resolution or 0.0,
        "dwell": dwell,
        "time_limit": time_limit,
        "sample_rate_hz": sample_rate or 0.0,
        "pose_topic": pose_topic,
        "message_types": message_types,
        "use_nav2": nav2,
    }
    out = run_search(
        params, ros_args=args, sim_time=sim_time, stats=stats, exit_on_stop=exit_on_stop, timeout_s=timeout
    )
    st = out["status"]
    console.print(f"search {st['state']} ({st['reason'] or 'running'}) after {st['steps']} readings")
    if st["declared_xy"] is not None:
        x, y = st["declared_xy"]
        console.print(f"declared source ({x:.2f}, {y:.2f}) m in the map frame")
    lat = out["latency"]
    if lat["n"]:
        med, p95 = lat["median_ms"], lat["p95_ms"]
        console.print(f"reading to goal: median {med:.1f} ms, 95th percentile {p95:.1f} ms")
    if stats is not None:
        console.print(f"wrote stats [cyan]{path_text(stats)}[/]")


@user_errors
def sim_cmd(
    ctx: typer.Context,
    case: Annotated[Path, typer.Argument(metavar="CASE", help="The case file to simulate.")],
    seed: SeedOption = 0,
    case_name: Annotated[
        str | None, typer.Option("--case-name", help="Seed as dgse search does this stem (default: CASE's).")
    ] = None,
    trial: TrialOption = 0,
    start: Annotated[
        tuple[int, int] | None, typer.Option("--start", metavar="I J", help="Start cell (default: drawn).")
    ] = None,
    rate: Annotated[
        float, typer.Option("--rate", help="Simulated seconds per wall-clock second (0: as fast as it goes).")
    ] = 1.0,
    origin: Annotated[
        tuple[float, float], typer.Option("--origin", metavar="X Y", help="The map's origin, m.")
    ] = (0.0, 0.0),
    speed: SpeedOption = PROTOCOL.speed,
    dwell: DwellOption = PROTOCOL.dwell,
    time_limit: TimeLimitOption = PROTOCOL.time_limit,
    min_start_distance: MinStartDistanceOption = PROTOCOL.min_start_distance,
    sample_rate: SampleRateOption = PROTOCOL.sample_rate_hz,
    frames: FramesOption = True,
    message_types: TypesOption = "auto",
    exit_on_stop: ExitOnStopOption = False,
    timeout: TimeoutOption = None,
) -> None:
    """Simulate a robot on the search's topics: the case's map, the pose and noisy readings.

    ROS arguments (remappings, parameters) go after '-- --ros-args'.
    """
    if not case.is_file():
        raise InputDataError(f"{case}: no such case file")
    args = _ros_args(ctx)
    from dgse.ros.nodes import run_sim

    params: dict[str, Any] = {
        "case": str(case),
        "seed": seed,
        "case_name": case_name or "",
        "trial": trial,
        "start": list(start) if start is not None else [-1, -1],
        "rate": rate,
        "origin_x": origin[0],
        "origin_y": origin[1],
        "speed": speed,
        "dwell": dwell,
        "time_limit": time_limit,
        "min_start_distance": min_start_distance,
        "sample_rate_hz": sample_rate or 0.0,
        "frames": frames,
        "message_types": message_types,
    }
    out = run_sim(params, ros_args=args, exit_on_stop=exit_on_stop, timeout_s=timeout)
    console.print(
        f"simulated robot: start {tuple(out['start'])}, {out['goals']} goals, "
        f"{out['distance_m']:.1f} m in {out['clock_s']:.0f} s"
    )


@user_errors
@option_bundle("setup", _method_params)
def replay_cmd(
    bag: Annotated[Path, typer.Argument(metavar="BAG", help="A rosbag2 folder of a search's topics.")],
    out: Annotated[
        Path, typer.Option("--out", "-o", help="Folder for beliefs.npz, belief.png, beliefs.gif.")
    ],
    setup: dict[str, Any],
    dwell: DwellOption = PROTOCOL.dwell,
    sample_rate: SampleRateOption = PROTOCOL.sample_rate_hz,
    topic: Annotated[
        list[str] | None,
        typer.Option(
            "--topic", metavar="KIND=TOPIC", help="The recording's topic of map, pose, gas, wind or goal."
        ),
    ] = None,
    figures: Annotated[bool, typer.Option("--figures/--no-figures", help="Write the figure and GIF.")] = True,
) -> None:
    """Run the estimator over a recording of a search: the belief at every reading taken."""
    from dgse.ros.replay import DEFAULT_TOPICS, replay_bag

    topics = {}
    for item in topic or []:
        kind, sep, name = item.partition("=")
        if not sep or kind not in DEFAULT_TOPICS:
            raise InputDataError(f"--topic takes KIND=TOPIC with KIND one of {', '.join(DEFAULT_TOPICS)}")
        topics[kind] = name
    check_output_dir(out, "output folder")
    params = {**setup, "dwell": dwell, "sample_rate_hz": sample_rate or 0.0}
    result = replay_bag(bag, out, params, topics=topics, figures=figures)
    x, y = result["final"]["estimate_xy"]
    n = result["readings"]
    console.print(f"{n} readings; the last belief's source ({x:.2f}, {y:.2f}) m in the map frame")
    for kind, path in result["files"].items():
        console.print(f"wrote {kind} [cyan]{path_text(Path(path))}[/]")


def register(app: typer.Typer) -> typer.Typer:
    """Attach the ``ros`` group (``dgse ros run|sim|replay``) to ``app``."""
    sub = new_app("ros", "The search on a ROS 2 robot: the node, a simulated robot, replay of a bag.")
    sub.command("run", context_settings=ROS_ARGS)(run_cmd)
    sub.command("sim", context_settings=ROS_ARGS)(sim_cmd)
    sub.command("replay")(replay_cmd)
    app.add_typer(sub, name="ros")
    return sub
