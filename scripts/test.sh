#!/usr/bin/env bash
# Set up DGSE with its test tools and run the test suite (the README's test command).
set -euo pipefail
cd "$(dirname "$0")/.."
python3 -m pip install -q --disable-pip-version-check -e ".[dev]"
python3 -m ruff check src tests benchmarks
python3 -m pytest -q "$@"
