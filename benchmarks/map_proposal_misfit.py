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

from dgse.estimators.knowledge import Knowledge
from dgse.estimators.phys import relative_wind_misfit
from dgse.estimators.registry import get_estimator
from dgse.physics.openings import potential_flow_proposals
from dgse.sensing.sensors import Observations
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


def _misfit(hyp, cells: np.ndarray, wind: np.ndarray) -> float:
    """``dgse-phys``'s ``wind_misfit`` of one proposal: its flow scaled to fit the readings."""
    u = hyp.flow.wind[:, cells[:, 0], cells[:, 1]].T
    scale = max(float((u * wind).sum() / max(float((u * u).sum()), 1e-12)), 0.0)
    return relative_wind_misfit(scale * u, wind)


def episode_row(name: str, case: Case, row: dict) -> dict:
    steps = row["steps"]
    n = min(READINGS, len(steps))
    cells = np.array([s["cell"] for s in steps[:n]], dtype=np.int64)
    wind = np.array([s["wind"] for s in steps[:n]], dtype=np.float64)
    gas = np.array([s["gas"] for s in steps[:n]], dtype=np.float64)
    est = get_estimator("dgse-phys", knowledge=Knowledge.from_case(case, "map"))
    hyps = est.hypotheses(Observations(cells, gas, wind))
    # the same call the estimator makes, for the openings themselves (its hypotheses keep labels)
    props = potential_flow_proposals(case.occupancy, case.resolution, cells, wind, top=est.map_proposals)
    if [p.label() for p in props] != [h.label for h in hyps]:
        raise SystemExit(f"{name}: the proposals differ from dgse-phys's hypotheses")
    misfits = [_misfit(h, cells, wind) for h in hyps]
    # at the episode's end: the proposals dgse-phys held then (made at the last power of two
    # readings, see PhysicsGuidedEstimator._map_hypotheses) against all its readings
    m = len(steps)
    held = 1 << (m.bit_length() - 1)
    cells_m = np.array([s["cell"] for s in steps], dtype=np.int64)
    wind_m = np.array([s["wind"] for s in steps], dtype=np.float64)
    gas_m = np.array([s["gas"] for s in steps], dtype=np.float64)
    est_end = get_estimator("dgse-phys", knowledge=Knowledge.from_case(case, "map"))
    est_end.hypotheses(Observations(cells_m[:held], gas_m[:held], wind_m[:held]))
    end_hyps = est_end.hypotheses(Observations(cells_m, gas_m, wind_m))
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
        "end_misfit": min(_misfit(h, cells_m, wind_m) for h in end_hyps),
        "true_inlet_proposed": any(inlet),
        "true_pair_proposed": any(i and o for i, o in zip(inlet, outlet, strict=True)),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("journals", type=Path, nargs="+", help="search journals written with --steps")
    ap.add_argument("-o", "--out", type=Path, required=True)
    args = ap.parse_args()
    rows = []
    for journal in args.journals:
        lines = journal.read_text().splitlines()
        for line in lines[1:]:
            entry = json.loads(line)
            if "steps" not in entry["row"]:
                raise SystemExit(f"{journal}: no steps recorded; run the search with --steps")
            found = sorted(journal.parent.glob(f"_cases_*/{entry['case']}.npz"))
            if not found:
                raise SystemExit(f"no case file {entry['case']}.npz beside {journal}")
            rows.append(episode_row(entry["case"], Case.load(found[0]), entry["row"]))
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
    args.out.write_text(json.dumps({"readings": READINGS, "summary": summary, "episodes": rows}, indent=1))
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
