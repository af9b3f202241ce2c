"""The whole loop on the loopback: the simulated robot and the search node find the source with
dgse search's readings and decisions; a recording of it replayed gives the live belief.

The nodes run in the Python that has ``rclpy`` (:func:`tests.ros.ros_python`), as fresh
processes on a random ROS domain restricted to this machine.
"""

from __future__ import annotations

import json
import math
import subprocess

import numpy as np
import pytest

from tests.ros import METHOD, ORIGIN, REPO, SEED, ros_env, ros_python
from tests.search import solved_two_rooms

PYTHON = ros_python()
pytestmark = pytest.mark.skipif(
    PYTHON is None, reason="rclpy is not importable (install dgse[ros] into a venv, set DGSE_ROS_PYTHON)"
)


@pytest.fixture(scope="module")
def loop(tmp_path_factory):
    """The case file, the live run's output folder, and dgse search's trial on the case."""
    from dgse.search.campaign import run_trials

    d = tmp_path_factory.mktemp("ros")
    case_file = solved_two_rooms().save(d / "two_rooms.npz")
    out = d / "live"
    out.mkdir()
    script = REPO / "tests" / "ros" / "loop_script.py"
    r = subprocess.run([PYTHON, str(script), str(case_file), str(out), METHOD, str(SEED)],
                       capture_output=True, text=True, env=ros_env(), timeout=120)  # fmt: skip
    assert r.returncode == 0 and "loop stopped" in r.stdout, (r.stdout, r.stderr)
    ref = run_trials(case_file, METHOD, METHOD, 1, SEED, estimator_options={"seed": SEED},
                     min_start_distance=1.0, steps=True)["per_case"][0]["trials"][0]  # fmt: skip
    return d, case_file, out, ref


def _same_as_search(stats: dict, ref: dict) -> None:
    got = stats["decisions"]
    assert [d["cell"] for d in got] == [s["cell"] for s in ref["steps"]]
    assert [d["gas"] for d in got] == [s["gas"] for s in ref["steps"]]
    assert [d["wind"] for d in got] == [s["wind"] for s in ref["steps"]]
    assert [d["goal"] for d in got] == [s["goal"] for s in ref["steps"]]
    assert [d["time_s"] for d in got] == pytest.approx([s["time_s"] for s in ref["steps"]], abs=1e-6)
    status = stats["status"]
    assert status["state"] == "stopped" and status["reason"] == ref["reason"]
    declared = np.subtract(status["declared_xy"], ORIGIN)
    assert np.allclose(declared, ref["estimate_xy"])
    assert math.dist(declared, solved_two_rooms().source) < 2.0


def test_the_loop_finds_the_source_as_dgse_search_does(loop):
    _, _, out, ref = loop
    stats = json.loads((out / "stats.json").read_text())
    _same_as_search(stats, ref)
    assert stats["latency"]["n"] == len(ref["steps"]) and stats["latency"]["median_ms"] > 0
    assert not [m for m in stats["messages"] if m[0] != "info"], stats["messages"]


def test_replay_of_the_recording_gives_the_live_belief(loop):
    d, _, out, ref = loop
    replay = d / "replay"
    r = subprocess.run(
        [PYTHON, "-m", "dgse.cli.main", "ros", "replay", str(out / "bag"), "-o", str(replay), "-m", METHOD,
         "--seed", str(SEED), "--case-name", "two_rooms"],
        capture_output=True, text=True, env=ros_env(), timeout=120,
    )  # fmt: skip
    assert r.returncode == 0, (r.stdout, r.stderr)
    with np.load(replay / "beliefs.npz") as z:
        assert z["cells"].tolist() == [s["cell"] for s in ref["steps"]]
        assert z["gas"].tolist() == [s["gas"] for s in ref["steps"]]
        live = np.load(out / "live.npz")["source_probs"]
        np.testing.assert_array_equal(z["source_probs"][-1], live)
        assert np.allclose(z["origin"], ORIGIN) and z["source_probs"].shape == (len(ref["steps"]), 20, 30)
    from PIL import Image

    with Image.open(replay / "beliefs.gif") as im:
        assert im.n_frames == len(ref["steps"])
    assert (replay / "belief.png").stat().st_size > 10_000


def _two_commands(
    d, case_file, name: str, sim_extra: tuple[str, ...] = (), run_extra: tuple[str, ...] = ()
) -> tuple[dict, str, str]:
    """``dgse ros sim`` and ``dgse ros run`` in two processes (each with its extra options): the
    run's stats, its output and the simulation's."""
    env = ros_env()
    dgse = [PYTHON, "-m", "dgse.cli.main", "ros"]
    sim = subprocess.Popen(
        [*dgse, "sim", str(case_file), "--seed", str(SEED), "--min-start-distance", "1",
         "--origin", *map(str, ORIGIN), "--exit-on-stop", "--timeout", "60", *sim_extra],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
    )  # fmt: skip
    try:
        r = subprocess.run(
            [*dgse, "run", "-m", METHOD, "--seed", str(SEED), "--case-name", "two_rooms", "--sim-time",
             "--stats", str(d / name), "--exit-on-stop", "--timeout", "60", *run_extra],
            capture_output=True, text=True, env=env, timeout=90,
        )  # fmt: skip
        sim_out, sim_err = sim.communicate(timeout=30)
    finally:
        sim.kill()
    assert r.returncode == 0, (r.stdout, r.stderr)
    assert sim.returncode == 0, (sim_out, sim_err)
    return json.loads((d / name).read_text()), r.stdout, sim_out


def test_the_two_commands_in_two_processes(loop):
    """``dgse ros sim`` and ``dgse ros run`` as a user starts them, in two terminals."""
    d, case_file, _, ref = loop
    stats, out, sim_out = _two_commands(d, case_file, "cli-stats.json", ("--rate", "0"))
    assert "search stopped (converged)" in out and "declared source" in out
    assert f"{len(ref['steps']) - 1} goals" in sim_out
    _same_as_search(stats, ref)


def test_readings_on_the_way_through_the_two_commands(loop):
    """With ``--sample-rate`` on both, the robot's readings on each drive reach the search node
    and go into its estimates with the goals' (the exact pairing is the core's test: a gas
    message without a stamp is timed on arrival, so the simulation runs paced here)."""
    d, case_file, _, _ = loop
    rate = ("--sample-rate", "2")
    stats, _, _ = _two_commands(d, case_file, "sampled.json", (*rate, "--rate", "10"), rate)
    steps = [s["step"] for s in stats["decisions"]]
    assert len(steps) > 1 and steps[-1] > len(steps)  # more readings than goals
    assert stats["status"]["state"] == "stopped" and stats["status"]["declared_xy"] is not None
