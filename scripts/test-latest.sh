#!/usr/bin/env bash
# Run the docs build and the test suite against the newest releases of every dependency, in a fresh virtual
# environment, so that the next breakage is seen here before a user sees it.
#
#   ./scripts/test-latest.sh            # newest releases, lint, pytest (pytest arguments may follow)
#   ./scripts/test-latest.sh --lock     # the same; if everything passes, write constraints.txt
#                                       # (the known-good versions the README and CI install)
#
# The environment goes to $DGSE_LATEST_VENV (default: $TMPDIR/dgse-latest-venv) and is made anew.
set -euo pipefail
cd "$(dirname "$0")/.."

lock=0
if [ "${1:-}" = "--lock" ]; then
    lock=1
    shift
fi
venv="${DGSE_LATEST_VENV:-${TMPDIR:-/tmp}/dgse-latest-venv}"
rm -rf "$venv"
python3 -m venv "$venv"
py="$venv/bin/python"
pip_q=(-m pip install -q --disable-pip-version-check)

# torch first: a bare `torch` requirement would pull a multi-GB CUDA build
"$py" "${pip_q[@]}" --upgrade pip
"$py" "${pip_q[@]}" "torch==2.13.0"
"$py" "${pip_q[@]}" --upgrade --upgrade-strategy eager -e ".[dev,docs]"

versions="$venv/versions.txt"
"$py" -m pip list --format=freeze --exclude-editable --disable-pip-version-check > "$versions"
echo "newest releases installed: $(grep -ciE '^(numpy|scipy|h5py|dask|torch|lightning)==' "$versions") key packages:"
grep -iE '^(numpy|scipy|numba|h5py|dask|distributed|torch|lightning|typer|rich|matplotlib)==' "$versions" \
    | tr '\n' ' '
echo

"$py" -m ruff check src tests benchmarks scripts
site_dir="$(mktemp -d)"
trap 'rm -rf "$site_dir"' EXIT
"$py" -m mkdocs build --strict --quiet --site-dir "$site_dir"
"$py" -m pytest -q -p no:cacheprovider "$@"

if [ "$lock" = 1 ]; then
    {
        echo "# Known-good versions: the test suite passed with exactly these ($(date -u +%Y-%m-%d), Python"
        echo "# $("$py" -c 'import sys; print(sys.version.split()[0])')). Made by ./scripts/test-latest.sh --lock;"
        echo "# used by the README's install command and by .ci/run (pip install -c constraints.txt)."
        echo "# torch is installed first, on its own (CPU or CUDA build), and is not pinned here."
        grep -viE '^(torch|triton|nvidia-[a-z0-9-]+|pip|setuptools|wheel)==' "$versions"
    } > constraints.txt
    echo "wrote constraints.txt ($(grep -vc '^#' constraints.txt) packages)"
fi
