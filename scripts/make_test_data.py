#!/usr/bin/env python3
"""Make the OpenFOAM test fixtures in ``tests/fixtures/openfoam/`` (seeded, needs OpenFOAM).

One small random layout of the training distribution (spec section 3; both
sides fixed at 5 m, the smallest size the distribution draws, so the files are
small and a solve takes about a second), an inlet speed and two sources drawn
after it from the same generator, in the same order as ``dgse scenario``
(``dgse scenario --seed 4 --size 5 5 --sources 2 --engine openfoam`` solves the
same scenario).  The flow and both gas fields are solved with the OpenFOAM
engine through :func:`dgse.physics.scenario.solve_cases`, the function behind
``dgse solve`` and ``dgse scenario``, and written as case files
``small_src0.npz`` and ``small_src1.npz``.

Each file's ``meta`` is the one ``solve_cases`` writes, plus a ``fixture``
entry: the seed, the size, the command that made it and the OpenFOAM facts
``solve_cases`` does not keep (flow iterations, convergence, seconds).

Usage::

    python3 scripts/make_test_data.py            # rewrites tests/fixtures/openfoam/
    python3 scripts/make_test_data.py --out DIR  # somewhere else
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from dgse.errors import UnsupportedError
from dgse.physics.engines import Engine, Solution, Source, get_engine
from dgse.physics.scenario import solve_cases
from dgse.world.generate import as_generator, random_inlet_velocity, random_layout, random_sources
from dgse.world.layout import Layout

REPO = Path(__file__).resolve().parents[1]
OUT_DIR = REPO / "tests" / "fixtures" / "openfoam"
COMMAND = "python3 scripts/make_test_data.py"

#: Seed of the layout, inlet speed and sources.  Seed 4: four rooms (five wall rectangles),
#: inlet 1.1 m/s, about 210 SIMPLEC iterations; about 0.15 % of the gas of its first source
#: diffuses out of the inlet (outlet flux / q 0.998), which the OpenFOAM re-run test checks.
SEED = 4
#: Range of both sides in m (``--size 5 5`` of ``dgse scenario``): 50 x 50 cells.
SIZE_M = (5.0, 5.0)
N_SOURCES = 2
NAME = "small"


class _Recorder:
    """An engine that passes ``solve`` on and keeps the solution's ``info``."""

    def __init__(self, engine: Engine) -> None:
        self.engine = engine
        self.name = engine.name
        self.info: dict = {}

    def solve(self, layout: Layout, inlet_velocity: float, sources: Sequence[Source]) -> Solution:
        sol = self.engine.solve(layout, inlet_velocity, sources)
        self.info = sol.info
        return sol


def _openfoam_engine() -> Engine:
    """The OpenFOAM engine, or exit with the reason it is not available."""
    try:
        return get_engine("openfoam")
    except UnsupportedError as e:
        sys.exit(
            f"make_test_data: cannot make the OpenFOAM fixtures: {e}\n"
            "The committed files in tests/fixtures/openfoam/ stay as they are."
        )


def make_test_data(out_dir: Path = OUT_DIR, seed: int = SEED) -> list[Path]:
    """Draw, solve with OpenFOAM and write ``<out_dir>/small_src<n>.npz``; returns the paths."""
    engine = _Recorder(_openfoam_engine())
    rng = as_generator(seed)
    layout = random_layout(rng, width_range=SIZE_M, height_range=SIZE_M, name=NAME)
    v_in = random_inlet_velocity(rng)
    sources = random_sources(layout, rng, n=N_SOURCES)
    t0 = time.perf_counter()
    cases = solve_cases(layout, v_in, sources, engine, name=NAME)
    seconds = time.perf_counter() - t0
    info = engine.info
    fixture = {
        "seed": seed,
        "size_m": list(SIZE_M),
        "command": COMMAND if seed == SEED else f"{COMMAND} --seed {seed}",
        "openfoam": {
            "flow_iterations": info["iterations"]["flow"],
            "flow_converged": bool(info["converged"]),
            "gas_converged": bool(info["gas_converged"]),
            "seconds": {
                "mesh": round(info["seconds"]["mesh"], 3),
                "flow": round(info["seconds"]["flow"], 3),
                "gas": [round(s, 3) for s in info["seconds"]["gas"]],
                "total": round(info["seconds"]["total"], 3),
            },
        },
    }
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for case in cases:
        case = dataclasses.replace(case, meta={**case.meta, "fixture": fixture})
        paths.append(case.save(out_dir / f"{case.name}.npz"))
    H, W = layout.occupancy.shape
    print(
        f"seed {seed}: {W} x {H} cells, {len(layout.walls)} walls, inlet {v_in:.3f} m/s; "
        f"OpenFOAM {info['iterations']['flow']} flow iterations, solve {seconds:.2f} s"
    )
    for case, path in zip(cases, paths, strict=True):
        ratio = case.meta["mass_balance"]["outlet_flux_ratio"]
        print(
            f"  {path} ({path.stat().st_size / 1024:.1f} KiB): source "
            f"({case.source[0]:.2f}, {case.source[1]:.2f}) m, q {case.release_rate:.3f} g/s, "
            f"outlet flux / q {ratio:.5f}"
        )
    return paths


def main(argv: Sequence[str] | None = None) -> int:
    """Command line entry: ``--out DIR`` and ``--seed S``."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--out", type=Path, default=OUT_DIR, help=f"output directory (default {OUT_DIR})")
    parser.add_argument("--seed", type=int, default=SEED, help=f"scenario seed (default {SEED})")
    args = parser.parse_args(argv)
    make_test_data(args.out, args.seed)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
