#!/usr/bin/env bash
# Set up DGSE with its test tools and run the test suite (the README's test command).
set -euo pipefail
cd "$(dirname "$0")/.."
# torch first: a bare `torch` requirement would pull a multi-GB CUDA build
python3 -m pip install -q --disable-pip-version-check "torch==2.13.0"
python3 -m pip install -q --disable-pip-version-check -e ".[dev]"
python3 -m ruff check src tests benchmarks
python3 -m pytest -q "$@"
