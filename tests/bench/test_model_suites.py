"""Quick runs of the suites on the DGSE networks: variants, samples, calibration."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import pytest

from dgse.bench import SUITES, run_suite
from dgse.bench.core import load_manifests
from dgse.errors import UnsupportedError


def _manifest(path: Path) -> dict:
    m = json.loads(path.read_text())
    for sec in m["sections"]:
        for fig in sec["figures"]:
            png = path.parent / fig["file"]
            assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        for tab in sec["tables"]:
            with (path.parent / tab["file"]).open() as f:
                rows = list(csv.reader(f))
            assert rows[0] == tab["columns"] and len(rows) == len(tab["rows"]) + 1
    return m


def test_variants_quick(bench_root: Path) -> None:
    m = _manifest(run_suite("variants", bench_root, quick=True))
    assert m["quick"] and m["suite"] == "variants" and m["wall_seconds"] > 0
    assert m["environment"]["versions"]["dgse"]
    rows = m["sections"][0]["tables"][0]["rows"]
    cols = m["sections"][0]["tables"][0]["columns"]
    methods = {r[cols.index("method")] for r in rows}
    assert methods == {"dgse-o", "dgse-p", "dgse-s"}
    for r in rows:
        err = r[cols.index("sl_error_m_mean")]
        assert err is not None and 0 <= err < 20
        wf = r[cols.index("wf_rmse_mean")]
        assert (wf is None) == (r[cols.index("method")] == "dgse-o")
    # the three variants saw identical observations: equal case lists and counts
    evals = [json.loads((bench_root / "variants" / f"eval_{v}.json").read_text()) for v in methods]
    assert len({tuple(e["cases"]) for e in evals}) == 1
    assert not any("reused" in n for n in m["notes"])
    # a second run reuses the evaluations and says so
    again = json.loads(run_suite("variants", bench_root, quick=True).read_text())
    assert any("3 result(s) were reused" in n and "eval_dgse-s" in n for n in again["notes"])
    assert again["sections"][0]["tables"][0]["rows"] == m["sections"][0]["tables"][0]["rows"]


def test_samples_quick(bench_root: Path) -> None:
    m = _manifest(run_suite("samples", bench_root, quick=True))
    titles = [s["title"] for s in m["sections"]]
    assert len(titles) == 3
    quality = m["sections"][0]["tables"][0]
    k1 = quality["rows"][0]
    assert k1[:2] == [1, 1]
    # relative reductions are 0 against themselves
    for c, v in zip(quality["columns"], k1, strict=True):
        if "rel. reduction" in c and v is not None:
            assert v == pytest.approx(0.0)
    sur = m["sections"][2]["tables"][0]
    for _, cf, sl in sur["rows"]:
        assert math.isfinite(cf) and sl > 0


def test_calibration_quick(bench_root: Path) -> None:
    m = _manifest(run_suite("calibration", bench_root, quick=True, knowledge="openings"))
    tab = m["sections"][1]["tables"][0]
    cols = tab["columns"]
    seen = set()
    for r in tab["rows"]:
        seen.add(r[cols.index("method")])
        for c in ("wind_cov_1sigma", "conc_cov_2sigma", "source_median_level"):
            v = r[cols.index(c)]
            assert v is None or 0.0 <= v <= 1.0
        src_err = r[cols.index("source_cal_error")]
        assert (src_err is None) == (r[cols.index("method")] in ("ggmrf", "gwgmrf"))
        assert src_err is None or 0.0 <= src_err <= 1.0
    assert {"dgse-s", "gwgmrf", "adjoint"} <= seen
    names = {m["suite"] for m in load_manifests(bench_root)}
    assert "calibration" in names


def test_unknown_suite_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(UnsupportedError, match="unknown suite 'nope'; known suites: variants, gdm"):
        run_suite("nope", tmp_path)
    assert SUITES.names() == ["variants", "gdm", "gsl", "search", "samples", "calibration"]
