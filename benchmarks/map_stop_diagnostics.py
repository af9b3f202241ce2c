"""What a mass stop at knowledge ``map`` knew when it fired (the aim: 95 % of stops within 2 m).

For every episode of searches journaled with ``--steps`` (``benchmarks/phys_search.py``) that
ended with a mass stop, the belief the stop saw is rebuilt from the recorded readings
(dgse-phys at ``map`` with its search preset and the opening proposals the search held,
as ``benchmarks/deadline_estimate.py`` does; the rebuilt posterior mean must equal the
journal's, checked) and the statistics a stop rule could hold on are recorded beside the
stop's error:

- ``readings``; the flow hypotheses' largest weight and how many hold at least 1 %;
- ``agreement``: the weight of the hypotheses whose own source mode lies within 1 m of the
  mixture's most probable cell (1: every weighty flow puts the source there);
- ``wind_misfit`` (the best flow's, as the ``stop.max_wind_misfit`` hold reads it), ``gas_misfit``;
- ``network_mass_1m``: the mass DGSE-S's own source belief (from the same readings) puts
  within 1 m of the mixture's most probable cell (what a hold on the network's agreement would
  read; ``docs/decisions.md``), ``network_peak_mass_1m``: the most it puts
  within 1 m of any free cell, and ``network_mode_m``: how far its mode is;
  ``network_error_m``: how far DGSE-S's posterior mean is from the source (for the record: a
  rule cannot see it).

A rule is only ever chosen on validation episodes (``--set validation*``); the test split's
stops are for reporting.  A statistic that would have vetoed the wrong stops here can only be
judged by searching again with the hold: an episode held at one stop goes on, and may stop
later, right or wrong::

    python benchmarks/map_stop_diagnostics.py \\
        benchmarks/results/phys_search/validation3_*_map_*-gas1m_fit0.7-disk1-s1-steps.journal.jsonl \\
        -o benchmarks/results/phys_search/map_stop_diagnostics_validation3_s1.json
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
from phys_search import journal_episodes, map_estimator_at_end, step_observations  # this folder's

from dgse.estimators.registry import get_estimator
from dgse.files import write_text
from dgse.planning.planners import mass_around, mass_within
from dgse.presets import PRESETS
from dgse.world.case import Case
from dgse.world.grid import Grid

#: A stop within this distance of the source means something (the issue's goal).
SUCCESS_M = 2.0
#: Radius (m) of the agreement and network-mass statistics.
RADIUS_M = 1.0
#: Hypotheses at least this heavy are counted as weighty.
WEIGHTY = 0.01


def stop_row(case: Case, row: dict[str, Any], network: Any) -> dict[str, Any]:
    """The statistics of the module doc for one episode's stop."""
    obs = step_observations(row["steps"])
    est = map_estimator_at_end(case, obs, **PRESETS["dgse-phys"].estimator_options_at("map", search=True))
    belief = est.estimate(case.occupancy, case.resolution, obs)
    mx, my = belief.source_estimate()
    sx, sy = (float(v) for v in case.source)
    if abs(math.hypot(mx - sx, my - sy) - row["error_m"]) > 1e-6:
        raise SystemExit(
            f"{row['case']}: rebuilt mean {math.hypot(mx - sx, my - sy):.3f} m off, "
            f"the search's {row['error_m']:.3f} m"
        )
    grid = Grid(belief.shape, case.resolution)
    i, j = belief.most_likely_cell()
    mode = grid.center_of(i, j)
    hyps = belief.info["hypotheses"]
    weights = np.array([h["weight"] for h in hyps])
    agree = sum(
        h["weight"]
        for h in hyps
        if h["source_mode_xy"] is not None and math.dist(h["source_mode_xy"], mode) <= RADIUS_M
    )
    net = network.estimate(case.occupancy, case.resolution, obs)
    net_mode = grid.center_of(*net.most_likely_cell())
    net_disks = mass_within(net.source_probs, case.resolution, RADIUS_M)
    return {
        "error_m": row["error_m"],
        "within_2m": row["error_m"] <= SUCCESS_M,
        "readings": len(obs),
        "search_time_s": row["search_time_s"],
        "max_weight": float(weights.max()),
        "weighty_hypotheses": int((weights >= WEIGHTY).sum()),
        "agreement": float(agree),
        "wind_misfit": belief.info["wind_misfit"],
        "gas_misfit": belief.info["gas_misfit"],
        "network_mass_1m": mass_around(net.source_probs, case.resolution, (i, j), RADIUS_M),
        "network_peak_mass_1m": float(net_disks[case.occupancy == 0].max()),
        "network_mode_m": math.dist(net_mode, mode),
        "network_error_m": math.dist(net.source_estimate(), (sx, sy)),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("journals", type=Path, nargs="+", help="search journals written with --steps")
    ap.add_argument("-o", "--out", type=Path, required=True)
    args = ap.parse_args()
    network = get_estimator("dgse-s", model="default", seed=0, dtype="auto", channels_last=True)
    rows: dict[str, dict[str, Any]] = {}
    for name, (case, row) in sorted(journal_episodes(args.journals).items()):
        if row["reason"] != "converged":
            continue
        rows[name] = stop_row(case, row, network)
        print(
            name, {k: round(v, 3) if isinstance(v, float) else v for k, v in rows[name].items()}, flush=True
        )
    right = [r for r in rows.values() if r["within_2m"]]
    wrong = [r for r in rows.values() if not r["within_2m"]]
    keys = [
        "readings",
        "max_weight",
        "agreement",
        "wind_misfit",
        "gas_misfit",
        "network_mass_1m",
        "network_peak_mass_1m",
        "network_mode_m",
    ]
    summary: dict[str, Any] = {"mass_stops": len(rows), "within_2m": len(right)}
    for key in keys:
        summary[key] = {
            "right": [float(np.min([r[key] for r in right])), float(np.max([r[key] for r in right]))]
            if right
            else None,
            "wrong": sorted(float(r[key]) for r in wrong),
        }
    write_text(args.out, json.dumps({"summary": summary, "stops": rows}, indent=1) + "\n")
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
