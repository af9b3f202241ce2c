"""dgse.bench.parallel: one case and count per process, journal parts joined."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from dgse.bench.parallel import evaluate_parallel, join_journal
from dgse.errors import InputDataError
from dgse.evaluation.evaluate import evaluate
from dgse.world.case import Case


def _cases(folder: Path) -> Path:
    """Two analytic plumes on a 12 x 16 map (no solver needed)."""
    H, W, res = 12, 16, 0.1
    occ = np.zeros((H, W), np.uint8)
    wind = np.zeros((2, H, W), np.float32)
    wind[0] = 0.8
    i, j = np.mgrid[0:H, 0:W]
    folder.mkdir()
    for k, (si, sj) in enumerate([(3, 3), (8, 12)]):
        conc = 100.0 * np.exp(-((i - si) ** 2 + (j - sj) ** 2) / 18.0)
        meta = {"name": f"tiny_src{k}", "inlet_velocity": 0.8, "release_rate_gps": 1.0}
        Case(occ, wind, conc, ((sj + 0.5) * res, (si + 0.5) * res), res, meta).save(
            folder / f"tiny_src{k}.npz"
        )
    return folder


def test_parallel_run_keeps_the_serial_runs_estimates(tmp_path):
    cases = _cases(tmp_path / "cases")
    out = tmp_path / "out"
    out.mkdir()
    done = evaluate_parallel([("kdmv", "map")], {"tiny": cases}, out, [5, 10], 3, 2, 2, None)
    assert done and not list((out / "_parts").iterdir())
    journal = out / "tiny_kdmv_map.journal.jsonl"
    lines = journal.read_text().splitlines()
    records = {
        (e["record"]["case"], e["record"]["n_obs"], e["record"]["trial"]) for e in map(json.loads, lines[1:])
    }
    assert records == {(f"tiny_src{k}", n, t) for k in (0, 1) for n in (5, 10) for t in range(3)}
    # the serial evaluation finds every estimate in the joined journal and agrees with a fresh one
    kept = evaluate(cases, "kdmv", [5, 10], trials=3, journal=journal)
    fresh = evaluate(cases, "kdmv", [5, 10], trials=3)
    key = lambda r: (r["case"], r["n_obs"], r["trial"])  # noqa: E731
    for a, b in zip(sorted(kept["per_case"], key=key), sorted(fresh["per_case"], key=key), strict=True):
        assert a["sl_error_m"] == pytest.approx(b["sl_error_m"])
    assert len(journal.read_text().splitlines()) == len(lines)  # nothing was estimated again


def test_join_drops_torn_lines_and_duplicates_and_refuses_other_settings(tmp_path):
    header = {"format": "dgse-journal", "identity": {"method": "m"}}

    def entry(trial: int) -> str:
        return json.dumps({"record": {"case": "c", "n_obs": 5, "trial": trial}})

    journal, part = tmp_path / "j.jsonl", tmp_path / "p.jsonl"
    journal.write_text(json.dumps(header) + "\n" + entry(0) + "\n")
    part.write_text(json.dumps(header) + "\n" + entry(0) + "\n" + entry(1) + '\n{"record": {"ca')
    assert join_journal(journal, [part]) == 2 and not part.exists()
    other = tmp_path / "o.jsonl"
    other.write_text(json.dumps({**header, "identity": {"method": "x"}}) + "\n" + entry(2) + "\n")
    with pytest.raises(InputDataError, match="other settings"):
        join_journal(journal, [other])
