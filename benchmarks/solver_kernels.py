"""The built-in solver's kernels timed alone: Gauss-Seidel's two arithmetics, the AMG coarse update.

* one symmetric Gauss-Seidel sweep on a 300 x 300 random layout (89k free cells) for one and
  two right-hand sides, with the plain division (``short_chain=False``) and the short-chain
  arithmetic (:func:`dgse.physics.fv.gauss_seidel`);
* the coarse operators of a Ruge-Stuben hierarchy on a 200 x 200 layout's pressure stencil:
  ``R A P`` by sparse products against :class:`dgse.physics.rans.GalerkinMap`;
* ``solve_flow`` on paper-size layouts (random 1001, 1002) with either arithmetic.

Each timing is the best of ``--repeats`` (the machine's own noise is +-10-15 %); run it on an
otherwise idle machine::

    python benchmarks/solver_kernels.py -o benchmarks/results/solver_kernels.json
"""

from __future__ import annotations

import argparse
import json
import time
from functools import partial
from pathlib import Path

import numpy as np
import pyamg
from solver_speed import _scenario  # this folder's

from dgse.files import write_text
from dgse.physics.fv import StencilMatrix, build_mesh, gauss_seidel
from dgse.physics.rans import FlowSettings, GalerkinMap, solve_flow


def _best(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def _sweep20(aP, a, b, nb, short: bool) -> None:
    gauss_seidel(aP, a, b, nb, np.zeros(b.shape), 0.0, 20, short)


def sweeps(repeats: int) -> dict:
    mesh = build_mesh(_scenario("rand:7:30")[0])
    rng = np.random.default_rng(0)
    a = np.where(mesh.nb >= 0, rng.uniform(0.5, 1.5, (mesh.n, 4)), 0.0)
    aP = a.sum(axis=1) * 1.02 + 0.01
    out = {"cells": mesh.n, "ms_per_sweep": {}}
    for m in (1, 2):
        b = rng.normal(size=(mesh.n, m))
        for short in (False, True):
            gauss_seidel(aP, a, b, mesh.nb, np.zeros((mesh.n, m)), 0.0, 1, short)  # compile / load
            run = partial(_sweep20, aP, a, b, mesh.nb, short)
            s = _best(run, repeats)
            out["ms_per_sweep"][f"rhs{m}_{'short_chain' if short else 'division'}"] = 1e3 * s / 20
    return out


def galerkin(repeats: int) -> dict:
    mesh = build_mesh(_scenario("rand:7:20")[0])
    st = StencilMatrix(mesh)
    rng = np.random.default_rng(1)

    def laplacian():
        a = np.where(mesh.nb >= 0, rng.uniform(0.5, 1.5, (mesh.n, 4)), 0.0)
        a = 0.5 * (a + np.where(mesh.nb >= 0, a[np.maximum(mesh.nb, 0), [1, 0, 3, 2]], 0.0))
        return st.assemble(a.sum(axis=1) + 1e-3, a).tocsr()

    ml = pyamg.ruge_stuben_solver(laplacian(), max_coarse=400)
    t = time.perf_counter()
    maps, pattern = [], laplacian()
    for lvl in ml.levels[:-1]:
        maps.append(GalerkinMap(pattern, lvl.R, lvl.P))
        pattern = maps[-1].pattern()
    build = time.perf_counter() - t
    A = laplacian()

    def by_map():
        fine = A
        for g in maps:
            fine = g.apply(fine.data)

    def by_products():
        fine = A
        for lvl in ml.levels[:-1]:
            fine = (lvl.R @ fine @ lvl.P).tocsr()

    return {
        "cells": mesh.n,
        "levels": len(ml.levels),
        "map_build_s": build,
        "map_ms": 1e3 * _best(by_map, repeats),
        "products_ms": 1e3 * _best(by_products, repeats),
    }


def flows(repeats: int) -> dict:
    out = {}
    for spec in ("rand:1001", "rand:1002"):
        layout, v, _ = _scenario(spec)
        mesh = build_mesh(layout)
        winds = {}
        for short in (False, True):
            s = FlowSettings(short_chain=short)
            solve_flow(layout, mesh, v, settings=s)  # compile / load
            key = "short_chain" if short else "division"
            out[f"{spec}_{key}_s"] = _best(partial(solve_flow, layout, mesh, v, settings=s), repeats)
            st, _ = solve_flow(layout, mesh, v, settings=s)
            winds[key] = np.stack([st.ux, st.uy])
        d, r = winds["short_chain"] - winds["division"], winds["division"]
        out[f"{spec}_wind_rel_diff"] = float(np.linalg.norm(d) / np.linalg.norm(r))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--out", type=Path, default=Path("benchmarks/results/solver_kernels.json"))
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    result = {"sweeps": sweeps(args.repeats), "galerkin": galerkin(args.repeats)}
    result["flows"] = flows(args.repeats)
    print(json.dumps(result, indent=1))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_text(args.out, json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
