"""How often the proposed openings include the true inlet and outlet (generated validation scenarios).

For 16 generated scenarios (seeds 900-915) and 20, 50 and 150 random noisy wind
readings: does a proposal pair an inlet and an outlet whose centres lie within
1 m of the true ones (on the same side), and at which rank?  Two proposers:

* ``potential_flow``: :func:`dgse.physics.openings.potential_flow_proposals` from the
  readings, the best 5 pairs (what ``dgse-phys --knowledge map`` uses);
* ``dgse_s_wind``: :func:`wind_field_proposals` (this script's: the pairs of
  :func:`dgse.physics.openings.propose_openings`) on DGSE-S's mean wind from the same
  readings (``--model``: the shipped network by default, or a weights file; up to 5 x 5 pairs).

    python benchmarks/opening_proposals.py -o benchmarks/results/opening_proposals.json
    python benchmarks/opening_proposals.py --model benchmarks/results/gpu_training/dgse-s-gpu.safetensors \
        -o benchmarks/results/opening_proposals_gpu.json
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from dgse.errors import InputDataError
from dgse.estimators.registry import get_estimator
from dgse.evaluation.evaluate import draw_observations
from dgse.files import write_text
from dgse.physics.openings import OpeningProposal, potential_flow_proposals, propose_openings
from dgse.physics.scenario import random_cases

SEEDS = range(900, 916)
COUNTS = (20, 50, 150)


def wind_field_proposals(
    occupancy: np.ndarray,
    resolution: float,
    wind: np.ndarray,
    cells: np.ndarray,
    readings: np.ndarray,
    top: int,
) -> list[OpeningProposal]:
    """The best ``top`` pairs of :func:`~dgse.physics.openings.propose_openings` on a belief's mean
    wind (``(2, H, W)``) with the readings (``(m, 2)`` m/s at ``cells``) put in where they were
    taken: up to 5 inflow and 5 outflow runs of at least a tenth of the strongest crossing wind,
    strongest pair first; none where the wind crosses the edge nowhere."""
    w = np.array(wind, dtype=np.float64, copy=True)
    c = np.asarray(cells, dtype=np.int64).reshape(-1, 2)
    w[:, c[:, 0], c[:, 1]] = np.asarray(readings, dtype=np.float64).reshape(-1, 2).T
    try:
        props = propose_openings(occupancy, resolution, w, min_fraction=0.1, max_inlets=5, max_outlets=5)
    except InputDataError:  # no air crosses the edge, or no separate inflow and outflow
        return []
    return props[:top]


def _near(proposed, true) -> bool:
    c = 0.5 * (proposed.start_m + proposed.end_m)
    return any(proposed.side == t.side and abs(c - 0.5 * (t.start_m + t.end_m)) <= 1.0 for t in true)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--out", type=Path, default=Path("benchmarks/results/opening_proposals.json"))
    ap.add_argument("--model", default="default", help="DGSE-S weights: default (shipped) or a file")
    args = ap.parse_args()
    net = get_estimator("dgse-s", model=args.model, seed=0, dtype="auto", channels_last=True)
    hits = {p: {n: 0 for n in COUNTS} for p in ("potential_flow", "dgse_s_wind")}
    top5 = {p: {n: 0 for n in COUNTS} for p in hits}
    ranks: dict[str, dict[int, list[int | None]]] = {p: {n: [] for n in COUNTS} for p in hits}
    for seed in SEEDS:
        case = random_cases(seed, n_sources=1)[0]
        layout = case.layout
        for n in COUNTS:
            obs = draw_observations(case, n, seed=1)
            wind = net.estimate(case.occupancy, case.resolution, obs).wind_mean
            found = {
                "potential_flow": potential_flow_proposals(
                    case.occupancy, case.resolution, obs.cells, obs.wind
                ),
                "dgse_s_wind": wind_field_proposals(
                    case.occupancy, case.resolution, wind, obs.cells, obs.wind, top=25
                ),
            }
            for name, props in found.items():
                rank = next(
                    (
                        r
                        for r, p in enumerate(props, 1)
                        if _near(p.inlets[0], layout.inlets) and _near(p.outlets[0], layout.outlets)
                    ),
                    None,
                )
                ranks[name][n].append(rank)
                hits[name][n] += rank is not None
                top5[name][n] += rank is not None and rank <= 5
        print(f"scenario {seed} done", flush=True)
    for name, by_n in hits.items():
        print(name, ", ".join(f"{n} readings: {k} of {len(SEEDS)}" for n, k in by_n.items()))
        print("  among the best 5:", ", ".join(f"{n} readings: {k}" for n, k in top5[name].items()))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_text(
        args.out,
        json.dumps(
            {
                "seeds": list(SEEDS),
                "scenarios": len(SEEDS),
                "model": args.model,
                "true_pair_found": hits,
                "true_pair_in_best_5": top5,
                "true_pair_rank": ranks,
            },
            indent=1,
        ),
    )
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
