#!/usr/bin/env bash
# Set up DGSE with its test tools at the known-good versions and run the test suite
# (the README's test command; CI runs it too). ./scripts/test-latest.sh does the same
# with the newest releases in a fresh virtual environment.
set -euo pipefail
cd "$(dirname "$0")/.."
# torch first: a bare `torch` requirement would pull a multi-GB CUDA build
python3 -m pip install -q --disable-pip-version-check "torch==2.13.0"
# constraints.txt: the versions the suite passed with (made by ./scripts/test-latest.sh --lock)
python3 -m pip install -q --disable-pip-version-check -c constraints.txt -e ".[dev]"
python3 -m ruff check src tests benchmarks scripts
python3 -m pytest -q "$@"
