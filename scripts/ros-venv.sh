#!/usr/bin/env bash
# A virtual environment for dgse's ROS extra: `scripts/ros-venv.sh DIR` makes DIR (default
# .venv-ros) on top of this Python's packages (--system-site-packages: dgse's dependencies
# come from the main environment, install them first) and installs the `ros` extra's packages
# into it (their bootstrap re-executes Python with the ROS libraries' path, so they stay out of
# the main environment). The tests of tests/ros/ that run ROS nodes use it through
# DGSE_ROS_PYTHON=DIR/bin/python.
set -euo pipefail
cd "$(dirname "$0")/.."
venv="${1:-.venv-ros}"
if [ ! -x "$venv/bin/python" ]; then
    python3 -m venv --system-site-packages "$venv"
fi
mapfile -t extra < <(python3 -c \
    "import tomllib; print('\n'.join(tomllib.load(open('pyproject.toml', 'rb'))['project']['optional-dependencies']['ros']))")
"$venv/bin/python" -m pip install -q --disable-pip-version-check -c constraints.txt "${extra[@]}"
"$venv/bin/python" -c "import rclpy, rosbags, nav_msgs.msg, visualization_msgs.msg"
echo "$venv/bin/python"
