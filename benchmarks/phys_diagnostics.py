"""Three diagnoses of issue 12's physics posterior, as numbers a command reproduces.

* ``undershoot``: how negative the raw (unclipped) adjoint rows of the built-in
  linear-upwind operator are, per sensor cell: the share of candidates with a
  negative response and the most negative response over the row's largest.  Left
  in, such responses made a zero reading favour the candidates just downstream of
  its sensor (:meth:`dgse.posterior.adjoint.FlowModel.responses` clips them).
* ``speed``: how far dgse-phys's source estimate moves with the inlet speed it is
  given, from the same random readings (Table I noise) of one scenario: dgse-phys
  with the openings known and a single candidate speed, for each of ``--speeds``.
* ``warm_start``: dgse-phys with its full speed grid from the same readings, each
  speed warm-started from the one below (``flows.warm_start=True``, the default) and solved
  cold from the coarse grid (``flows.warm_start=False``), and how far the two flows at 1 m/s
  differ: wind and ``nu_t`` (relative L2 and the median over free cells of the
  relative difference).

Scenarios are the generated test ones of ``benchmarks/phys_search.py`` (made once)::

    python benchmarks/phys_diagnostics.py --case test2005 --speeds 1.0 1.331 1.38
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from phys_search import cases_dir

from dgse.belief.knowledge import Knowledge
from dgse.estimators.registry import get_estimator
from dgse.evaluation.evaluate import draw_observations
from dgse.files import write_text
from dgse.posterior.adjoint import flow_model
from dgse.world.case import Case


def undershoot(case: Case, sensors: int, seed: int) -> dict:
    """Raw adjoint rows at ``sensors`` random free cells: negative share and depth."""
    fm = flow_model(case.layout, case.inlet_velocity)
    free = np.argwhere(case.free)
    cells = free[np.random.default_rng(seed).choice(len(free), size=sensors, replace=False)]
    raw = fm.mesh.values(fm.transport.adjoint(cells))
    depth = raw.min(axis=1) / raw.max(axis=1)
    return {
        "sensors": sensors,
        "negative_share": float((raw < 0).mean()),
        "min_over_max_median": float(np.median(depth)),
        "min_over_max_worst": float(depth.min()),
    }


def speed(case: Case, speeds: list[float], readings: int, seed: int) -> list[dict]:
    """dgse-phys's error from the same readings with one given inlet speed at a time."""
    obs = draw_observations(case, readings, seed=seed)
    knowledge = Knowledge.from_case(case, "openings")
    rows = []
    for v in speeds:
        est = get_estimator(
            "dgse-phys", knowledge=knowledge, **{"flows.speeds": (v,), "flows.refine_speeds": 0}
        )
        b = est.estimate(case.occupancy, case.resolution, obs)
        rows.append({"speed": v, "error_m": b.localization_error(case.source)})
        print(f"v_in {v:g} m/s: {rows[-1]['error_m']:.2f} m off")
    return rows


def warm_start(case: Case, readings: int, seed: int) -> dict:
    """Cold- against warm-started speed flows: the flows at 1 m/s and dgse-phys's errors."""
    obs = draw_observations(case, readings, seed=seed)
    knowledge = Knowledge.from_case(case, "openings")
    row: dict = {}
    flows = {}
    for warm in (False, True):
        opts = {"flows.refine_speeds": 0, "flows.warm_start": warm}
        est = get_estimator("dgse-phys", knowledge=knowledge, **opts)
        b = est.estimate(case.occupancy, case.resolution, obs)
        tag = "warm" if warm else "cold"
        row[f"{tag}_error_m"] = b.localization_error(case.source)
        row[f"{tag}_flow_seconds"] = sum(h.flow.info["seconds"] for h in est.hypotheses())
        flows[tag] = next(h.flow for h in est.hypotheses() if h.flow.inlet_velocity == 1.0)
        print(f"{tag} starts: {row[f'{tag}_error_m']:.2f} m off")
    free = case.free
    for name in ("wind", "nut"):
        a = np.asarray(getattr(flows["cold"].solved, name))
        b = np.asarray(getattr(flows["warm"].solved, name))
        row[f"{name}_rel_l2"] = float(np.linalg.norm(a - b) / np.linalg.norm(a))
        if name == "nut":
            rel = np.abs(a - b)[free] / np.maximum(np.abs(a)[free], 1e-30)
            row["nut_median_rel_diff"] = float(np.median(rel))
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", default="test2005", help="a test scenario, testSEED (2000-2019)")
    ap.add_argument("--speeds", type=float, nargs="+", default=[1.0, 1.331, 1.38])
    ap.add_argument("--readings", type=int, default=150)
    ap.add_argument("--sensors", type=int, default=50)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("-o", "--out", type=Path, default=Path("benchmarks/results/phys_diagnostics.json"))
    args = ap.parse_args()
    path = cases_dir(Path("benchmarks/results/phys_search"), "test") / f"{args.case}_src0.npz"
    if not path.exists():
        ap.error(f"{path} is not a test scenario")
    case = Case.load(path)
    row = {
        "case": args.case,
        "true_inlet_velocity": float(case.inlet_velocity),
        "readings": args.readings,
        "seed": args.seed,
        "undershoot": undershoot(case, args.sensors, args.seed),
        "speed": speed(case, args.speeds, args.readings, args.seed),
        "warm_start": warm_start(case, args.readings, args.seed),
    }
    print(json.dumps(row["undershoot"]))
    print(json.dumps(row["warm_start"]))
    write_text(args.out, json.dumps(row, indent=1))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
