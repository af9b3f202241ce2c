"""``dgse ros``'s command line in any Python: the help, the errors before ROS is needed, the
one line without rclpy."""

from __future__ import annotations

import importlib.util

import pytest

from dgse.cli.main import main
from tests.test_cli import _assert_user_error

HAS_RCLPY = importlib.util.find_spec("rclpy") is not None


def _run(capsys, *args) -> tuple[int, str, str]:
    code = main(["ros", *map(str, args)])
    out, err = capsys.readouterr()
    return code, out, err


def test_the_help_lists_the_three_commands(capsys):
    code, out, _ = _run(capsys, "--help")
    assert code == 0 and all(c in out for c in ("run", "sim", "replay"))
    code, out, _ = _run(capsys, "run", "--help")
    assert code == 0 and "--ros-args" in out and "--stats" in out


@pytest.mark.skipif(HAS_RCLPY, reason="this Python has rclpy: the node would start")
def test_without_rclpy_one_line_says_what_to_install(capsys):
    _assert_user_error(*_run(capsys, "run"), "pip install 'dgse[ros]'", "source your ROS 2")


def test_words_that_are_not_ros_arguments_are_refused(capsys, tmp_path):
    _assert_user_error(*_run(capsys, "run", "--", "map:=/x"), "ROS arguments go after '-- --ros-args'")
    _assert_user_error(*_run(capsys, "sim", tmp_path / "none.npz"), "no such case file")


def test_replay_of_a_missing_bag_is_an_error(capsys, tmp_path):
    code, out, err = _run(capsys, "replay", tmp_path / "nothing", "-o", tmp_path / "out")
    assert code == 2 and ("no such bag" in out + err or "needs rosbags" in out + err)
    bad_topic = _run(capsys, "replay", tmp_path, "-o", tmp_path / "o", "--topic", "odom")
    _assert_user_error(*bad_topic, "KIND=TOPIC")
