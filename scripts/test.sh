#!/usr/bin/env bash
# Set up DGSE with its test and docs tools at the known-good versions, lint, build the docs
# and run the test suite
# (the README's test command; CI runs it too). ./scripts/test-latest.sh does the same
# with the newest releases in a fresh virtual environment.
set -euo pipefail
cd "$(dirname "$0")/.."
# torch first: a bare `torch` requirement would pull a multi-GB CUDA build
python3 -m pip install -q --disable-pip-version-check "torch==2.13.0"
# constraints.txt: the versions the suite passed with (made by ./scripts/test-latest.sh --lock)
python3 -m pip install -q --disable-pip-version-check -c constraints.txt -e ".[dev,docs]"
python3 -m ruff check src tests benchmarks scripts
# the documentation site (mkdocs.yml): every page, link and docstring builds without a warning;
# built into a temporary folder, so nothing is left in the tree
site_dir="$(mktemp -d)"
trap 'rm -rf "$site_dir"' EXIT
python3 -m mkdocs build --strict --quiet --site-dir "$site_dir"
python3 -m pytest -q "$@"
