"""Were the true openings among dgse-phys's proposals at ``map``, and did the wind say so? (issue 12)

For every episode of ``map`` searches journaled with ``--steps`` (``benchmarks/phys_search.py``), the
opening pairs ``dgse-phys`` proposes from the episode's first 64 wind readings (or all, if fewer) are
compared with the case's true inlet and outlet (a proposal hits an opening when it lies on the same
side and its window overlaps it), and the best proposal's wind misfit is computed: the RMS of the
readings minus the proposal's flow at their cells (one free, non-negative scale fitted), over the
RMS of the readings.  Writes one row per episode and the split by success.

    python benchmarks/map_proposal_misfit.py \\
        benchmarks/results/phys_search/validation3*_map_*-gas1m_base-s0.journal.jsonl \\
        -o benchmarks/results/phys_search/map_proposal_misfit_validation3.json
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from phys_search import journal_episodes, map_estimator_at_end, step_observations  # this folder's

from dgse.belief.knowledge import Knowledge
from dgse.estimators.registry import get_estimator
from dgse.files import write_text
from dgse.physics.openings import potential_flow_proposals
from dgse.posterior.mixture import fitted_wind_scale, relative_wind_misfit
from dgse.world.case import Case
from dgse.world.layout import Opening

READINGS = 64


def _hits(opening: Opening, truth: dict) -> bool:
    """The proposed opening lies on the true one's side and overlaps it."""
    return (
        opening.side == truth["side"]
        and opening.start_m < truth["end_m"]
        and opening.end_m > truth["start_m"]
    )


def _misfit(hyp, obs) -> float:
    """``dgse-phys``'s ``wind_misfit`` of one proposal: its flow scaled to fit the readings."""
    u = hyp.flow.wind[:, obs.cells[:, 0], obs.cells[:, 1]].T
    return relative_wind_misfit(fitted_wind_scale(u, obs.wind) * u, obs.wind)


def episode_row(name: str, case: Case, row: dict) -> dict:
    steps = row["steps"]
    n = min(READINGS, len(steps))
    obs = step_observations(steps[:n])
    est = get_estimator("dgse-phys", knowledge=Knowledge.from_case(case, "map"))
    hyps = est.hypotheses(obs)  # proposed from these readings
    # the same call the estimator makes, for the openings themselves (its hypotheses keep labels)
    props = potential_flow_proposals(
        case.occupancy, case.resolution, obs.cells, obs.wind, top=est.flows.map_proposals
    )
    if [p.label() for p in props] != [h.label for h in hyps]:
        raise SystemExit(f"{name}: the proposals differ from dgse-phys's hypotheses")
    misfits = [_misfit(h, obs) for h in hyps]
    # at the episode's end: the proposals dgse-phys held then against all its readings
    obs_m = step_observations(steps)
    end_hyps = map_estimator_at_end(case, obs_m).hypotheses(obs_m)
    inlet = [_hits(p.inlets[0], case.meta["inlet"]) for p in props]
    outlet = [_hits(p.outlets[0], case.meta["outlet"]) for p in props]
    return {
        "case": name,
        "success": bool(row["metrics"]["success"]),
        "error_m": row["error_m"],
        "reason": row["reason"],
        "n_steps": row["n_steps"],
        "readings_used": n,
        "best_misfit": min(misfits),
        "end_misfit": min(_misfit(h, obs_m) for h in end_hyps),
        "true_inlet_proposed": any(inlet),
        "true_pair_proposed": any(i and o for i, o in zip(inlet, outlet, strict=True)),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("journals", type=Path, nargs="+", help="search journals written with --steps")
    ap.add_argument("-o", "--out", type=Path, required=True)
    args = ap.parse_args()
    rows = []
    for name, (case, row) in journal_episodes(args.journals).items():
        rows.append(episode_row(name, case, row))
        r = rows[-1]
        print(
            f"{r['case']}: {'found' if r['success'] else 'FAILED'} {r['error_m']:.2f} m ({r['reason']}), "
            f"misfit {r['best_misfit']:.2f} (end {r['end_misfit']:.2f}), "
            f"inlet proposed {r['true_inlet_proposed']}, pair {r['true_pair_proposed']}",
            flush=True,
        )
    summary = {}
    found_rows = [r for r in rows if r["success"]]
    failed_rows = [r for r in rows if not r["success"]]
    for label, group in (("found", found_rows), ("failed", failed_rows)):
        summary[label] = {
            "episodes": len(group),
            "true_inlet_proposed": sum(r["true_inlet_proposed"] for r in group),
            "true_pair_proposed": sum(r["true_pair_proposed"] for r in group),
            "best_misfit_median": float(np.median([r["best_misfit"] for r in group])) if group else None,
        }
    write_text(args.out, json.dumps({"readings": READINGS, "summary": summary, "episodes": rows}, indent=1))
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
