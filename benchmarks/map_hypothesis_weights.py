"""What weighs the opening hypotheses of journaled ``map`` searches: wind or gas?

For each search journaled with ``--steps`` (``benchmarks/phys_search.py``), the
estimate after its last reading (or its first ``--at`` readings) is made again
with the opening proposals the search held then, and every hypothesis is
listed with its weight, the wind readings' log likelihood, the tempered gas
log evidence, the relative wind misfit, whether its inlet and outlet are the
scenario's (centre within 1 m, same side: ``T`` both, ``i`` inlet only,
``o`` outlet only) and how far its own posterior's peak is from the source.

    python benchmarks/map_hypothesis_weights.py \\
        benchmarks/results/phys_search/validation3-files23_*_prop15-s0-partial.journal.jsonl \\
        --cases 953 954 -E flows.map_proposals=15 \\
        -o benchmarks/results/phys_search/map_hypothesis_weights_prop15.json
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

from opening_proposals import _near
from phys_search import journal_episodes, map_estimator_at_end, step_observations

from dgse.cli.common import parse_params
from dgse.files import write_text
from dgse.world.layout import Opening


def _match(label: str, layout: Any) -> str:
    """``T``/``i``/``o``/``-``: which of a proposal's openings (its label) are the layout's."""
    try:
        inlet, outlet = label.removeprefix("in ").split(" m, out ")
        (s_in, r_in), (s_out, r_out) = inlet.split(" "), outlet.split(" ")[:2]
        a, b = map(float, r_in.split("-"))
        c, d = map(float, r_out.removesuffix("m").split("-"))
    except ValueError:
        return "?"
    ok_in, ok_out = _near(Opening(s_in, a, b), layout.inlets), _near(Opening(s_out, c, d), layout.outlets)
    return "T" if ok_in and ok_out else "i" if ok_in else "o" if ok_out else "-"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("journals", nargs="+", type=Path)
    ap.add_argument("--cases", nargs="*", default=[], help="only episodes whose case name holds one of these")
    ap.add_argument("--at", type=int, default=None, help="the first N readings (default: all)")
    ap.add_argument("-E", dest="options", action="append", default=[], help="dgse-phys option key=json")
    ap.add_argument("-o", "--out", type=Path, required=True)
    args = ap.parse_args()
    options = parse_params(args.options, "-E")
    rows = {}
    for name, (case, row) in sorted(journal_episodes(args.journals).items()):
        if args.cases and not any(c in name for c in args.cases):
            continue
        obs = step_observations(row["steps"][: args.at])
        est = map_estimator_at_end(case, obs, **options)
        b = est.estimate(case.occupancy, case.resolution, obs)
        sx, sy = map(float, case.source)
        hyps = []
        for h in b.info["hypotheses"]:
            mode = h["source_mode_xy"]
            hyps.append(
                {
                    **{k: h[k] for k in ("label", "weight", "wind_log_likelihood", "wind_misfit")},
                    "gas_log_evidence": h["gas_log_evidence"],
                    "openings": _match(h["label"], case.layout),
                    "mode_error_m": None if mode is None else math.hypot(mode[0] - sx, mode[1] - sy),
                }
            )
        rows[name] = {
            "readings": len(obs),
            "search_error_m": row["error_m"],
            "reason": row["reason"],
            "estimate_error_m": b.localization_error((sx, sy)),
            "temperature": b.info["temperature"],
            "hypotheses": hyps,
        }
        print(
            f"{name}: {len(obs)} readings, search {row['error_m']:.2f} m ({row['reason']}), "
            f"estimate again {rows[name]['estimate_error_m']:.2f} m, T = {b.info['temperature']:.1f}"
        )
        for h in sorted(hyps, key=lambda h: -h["weight"]):
            gas = "-" if h["gas_log_evidence"] is None else f"{h['gas_log_evidence']:8.1f}"
            err = "-" if h["mode_error_m"] is None else f"{h['mode_error_m']:.2f}"
            print(
                f"  {h['openings']} w {h['weight']:.3f}  wind {h['wind_log_likelihood']:9.1f}  gas {gas}  "
                f"misfit {h['wind_misfit']:.2f}  peak {err} m  {h['label']}"
            )
    errors = [r["estimate_error_m"] for r in rows.values()]
    true_weight = [sum(h["weight"] for h in r["hypotheses"] if h["openings"] == "T") for r in rows.values()]
    summary = {
        "episodes": len(rows),
        "estimate_error_m_mean": sum(errors) / max(len(errors), 1),
        "estimates_within_2m": sum(e <= 2.0 for e in errors),
        "true_pair_proposed": sum(any(h["openings"] == "T" for h in r["hypotheses"]) for r in rows.values()),
        "true_pair_weight_mean": sum(true_weight) / max(len(true_weight), 1),
    }
    print(json.dumps(summary))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    result = {"journals": [str(j) for j in args.journals], "options": options, "at": args.at}
    write_text(args.out, json.dumps({**result, "summary": summary, "episodes": rows}, indent=1))


if __name__ == "__main__":
    main()
