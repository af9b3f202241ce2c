"""Quick runs of the suites on the DGSE networks: variants, samples, calibration."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from dgse.bench import SUITES, run_suite
from dgse.bench.core import load_manifests
from dgse.errors import UnsupportedError
from tests.bench.baselines import below, pooled, quick_cases, uninformed_on_canvas


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
    """Every variant at every count, pooled over the two scenarios, beats what an estimate that
    ignores the readings scores there (:mod:`tests.bench.baselines`): the uniform source
    posterior's SL error and CE, still air's wind RMSE, the best constant concentration's RMSE
    and the best single Gaussians' NLLs.  The wind RMSE's bound is still air, not the wind's own
    mean: from 5 readings the networks' wind RMSE is within 2 % of that mean's."""
    m = _manifest(run_suite("variants", bench_root, quick=True))
    assert m["quick"] and m["suite"] == "variants" and m["wall_seconds"] > 0
    assert m["environment"]["versions"]["dgse"]
    rows = m["sections"][0]["tables"][0]["rows"]
    cols = m["sections"][0]["tables"][0]["columns"]
    methods = {r[cols.index("method")] for r in rows}
    assert methods == {"dgse-o", "dgse-p", "dgse-s"}
    evals = {v: json.loads((bench_root / "variants" / f"eval_{v}.json").read_text()) for v in methods}
    cases = quick_cases(bench_root)
    bounds = {
        "sl_error_m_mean": "sl_error_m",
        "ce_mean": "ce",
        "wf_rmse_mean": "wf_rmse_still",
        "wf_nll_mean": "wf_nll_constant",
        "cf_rmse_mean": "cf_rmse_constant",
        "cf_nll_mean": "cf_nll_constant",
    }
    for r in rows:
        method, n_obs = r[cols.index("method")], r[cols.index("n_obs")]
        records = [c for c in evals[method]["per_case"] if c["n_obs"] == n_obs]
        assert len(records) == r[cols.index("n_estimates")] == 2
        # DGSE-O predicts no fields
        fields = ("wf_rmse_mean", "wf_nll_mean", "cf_rmse_mean", "cf_nll_mean")
        assert all((r[cols.index(c)] is None) == (method == "dgse-o") for c in fields)
        for col, key in bounds.items():
            if method == "dgse-o" and col in fields:
                continue
            v, bound = r[cols.index(col)], pooled(records, cases, key)
            assert v is not None and below(v, bound), (method, n_obs, col, v, bound)
    # the three variants saw identical observations: equal case lists and counts
    assert len({tuple(e["cases"]) for e in evals.values()}) == 1
    assert not any("reused" in n for n in m["notes"])
    # a second run reuses the evaluations and says so
    again = json.loads(run_suite("variants", bench_root, quick=True).read_text())
    assert any("3 result(s) were reused" in n and "eval_dgse-s" in n for n in again["notes"])
    assert again["sections"][0]["tables"][0]["rows"] == m["sections"][0]["tables"][0]["rows"]


def test_samples_quick(bench_root: Path) -> None:
    """Every (K, T) beats the uniform source posterior's CE and the best single Gaussian's
    concentration NLL, pooled over the scenarios; the MC losses beat the same on the canvas."""
    m = _manifest(run_suite("samples", bench_root, quick=True))
    titles = [s["title"] for s in m["sections"]]
    assert len(titles) == 3
    quality = m["sections"][0]["tables"][0]
    cols = quality["columns"]
    k1 = quality["rows"][0]
    assert k1[:2] == [1, 1]
    # relative reductions are 0 against themselves
    for c, v in zip(cols, k1, strict=True):
        if "rel. reduction" in c and v is not None:
            assert v == pytest.approx(0.0)
    cases = quick_cases(bench_root)
    for r in quality["rows"]:
        K, T = r[:2]
        records = json.loads((bench_root / "samples" / f"eval_K{K}_T{T}.json").read_text())["per_case"]
        for col, key in (("ce all", "ce"), ("cf_nll all", "cf_nll_constant")):
            v, bound = r[cols.index(col)], pooled(records, cases, key)
            assert below(v, bound), (K, T, col, v, bound)
    # quick: the MC losses are those of the first scenario's canvas with 50 readings
    assert json.loads((bench_root / "samples" / "surrogate.json").read_text())["n_samples"] == 1
    canvas = uninformed_on_canvas(cases[min(cases)])
    sur = m["sections"][2]["tables"][0]
    for _, cf, sl in sur["rows"]:
        assert below(cf, canvas["conc_nll"]) and 0 < sl and below(sl, canvas["source_ce"])


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
    assert SUITES.names() == ["variants", "gdm", "gsl", "search", "samples", "calibration", "field"]
