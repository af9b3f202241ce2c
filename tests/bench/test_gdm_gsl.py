"""Quick runs of the ``gdm`` (fig8, fig7, fig9) and ``gsl`` (fig:gsl_only) suites."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import pytest

from dgse.bench import run_suite
from dgse.bench.gdm import METHODS as GDM_METHODS
from dgse.bench.gdm import NLL_METHODS
from dgse.bench.gsl import METHODS as GSL_METHODS
from dgse.bench.gsl import ORACLES


def _manifest(path: Path) -> dict:
    m = json.loads(path.read_text())
    assert m["format"] == "dgse-bench-suite" and m["quick"]
    for sec in m["sections"]:
        assert sec["text"]
        for fig in sec["figures"]:
            assert (path.parent / fig["file"]).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
            assert fig["caption"]
        for tab in sec["tables"]:
            with (path.parent / tab["file"]).open() as f:
                rows = list(csv.reader(f))
            assert rows[0] == tab["columns"] and len(rows) == len(tab["rows"]) + 1
    return m


def _table(m: dict, name: str) -> list[dict]:
    for sec in m["sections"]:
        for tab in sec["tables"]:
            if tab["file"] == f"{name}.csv":
                return [dict(zip(tab["columns"], r, strict=True)) for r in tab["rows"]]
    raise AssertionError(f"no table {name}")


def _finite(v) -> bool:
    return v is not None and math.isfinite(float(v))


@pytest.fixture(scope="module")
def gdm(bench_root: Path) -> dict:
    return _manifest(run_suite("gdm", bench_root, quick=True))


def test_gdm_quick_figures_and_tables(gdm: dict, bench_root: Path) -> None:
    files = {f["file"] for s in gdm["sections"] for f in s["figures"]}
    assert "fig8_gdm_rmse_nll.png" in files and "fig9_gdm_time.png" in files
    assert sum(f.startswith("fig7_maps_") for f in files) == 1  # quick: the first scenario only
    per_case = _table(gdm, "fig8_gdm_per_scenario")
    assert {r["method"] for r in per_case} == set(GDM_METHODS)
    for r in per_case:
        # every method has a finite ppm RMSE; a variance, hence an NLL, all of them
        assert _finite(r["cf_rmse_ppm_mean"]) and r["cf_rmse_ppm_mean"] >= 0
        assert _finite(r["cf_nll_ppm_mean"])
        assert r["nll_comparable"] == (r["method"] in NLL_METHODS)
    log_rows = _table(gdm, "gdm_overall_log")
    assert all(_finite(r["cf_rmse_mean"]) and _finite(r["cf_nll_mean"]) for r in log_rows)
    times = _table(gdm, "fig9_gdm_time")
    assert {r["method"] for r in times} == set(GDM_METHODS)
    assert all(r["seconds_median"] > 0 for r in times)
    # the ppm-choice check: finite scores, and the lognormal mean is never below the median
    for r in _table(gdm, "ppm_choice"):
        assert _finite(r["rmse_median_ppm"]) and _finite(r["nll_exact_density"])
        assert r["max_mean_over_median"] >= 1.0
    # every method saw the same scenarios and counts
    evals = [json.loads((bench_root / "gdm" / f"eval_{m}.json").read_text()) for m in GDM_METHODS]
    assert len({tuple(e["cases"]) for e in evals}) == 1
    assert len({tuple(e["observation_counts"]) for e in evals}) == 1


def test_gdm_evaluations_are_reused_only_for_the_same_plan(gdm: dict, bench_root: Path) -> None:
    from dgse.bench.core import BenchContext
    from dgse.bench.gdm import evaluate_cached

    ctx = BenchContext("gdm", bench_root, quick=True)
    cases = ctx.scenarios(2, "test")
    first = json.loads((bench_root / "gdm" / "eval_kdmvw.json").read_text())
    same = evaluate_cached(ctx, "eval_kdmvw", cases, "kdmvw", first["observation_counts"], first["trials"])
    assert same["created"] == first["created"]
    assert ctx.reused == [f"eval_kdmvw of {first['created'][:10]}"]  # the manifest's note says so
    other = evaluate_cached(ctx, "eval_kdmvw_other", cases, "kdmvw", [20], 1)
    assert other["observation_counts"] == [20] and other["trials"] == 1
    (bench_root / "gdm" / "eval_kdmvw_other.json").unlink()


def test_methods_at_a_knowledge_level_are_named(bench_root: Path) -> None:
    from dgse.bench.core import BenchContext

    ctx = BenchContext("gsl", bench_root, quick=True)
    kept, left = ctx.methods_at_level(GSL_METHODS)
    assert ctx.knowledge == "map" and set(left) == {"adjoint", "adjoint-oracle"}
    assert "dgse-s" in kept and "openings" in left["adjoint"] and ctx.notes


def test_gsl_quick(bench_root: Path) -> None:
    # at 'wind' every method of the comparison works (the oracle needs the flow)
    m = _manifest(run_suite("gsl", bench_root, quick=True, knowledge="wind"))
    assert m["knowledge"] == "wind"
    files = {f["file"] for s in m["sections"] for f in s["figures"]}
    assert {"fig_gsl_only.png", "gsl_time.png"} <= files
    text = m["sections"][0]["text"]
    assert "grgsl is excluded" in text and "lower-bound" in text and "Knowledge: 'wind'" in text
    rows = _table(m, "gsl_only")
    assert {r["method"] for r in rows} == set(GSL_METHODS)
    for r in rows:
        assert r["oracle"] == (r["method"] in ORACLES)
        assert _finite(r["sl_error_m_mean"]) and 0 <= r["sl_error_m_mean"] < 20
        # CE is -log p(true cell) with p floored at 1e-12
        assert _finite(r["ce_mean"]) and 0 <= r["ce_mean"] <= -math.log(1e-12) + 1e-9
        assert r["seconds_median"] > 0
    pooled = {r["method"]: r for r in rows if r["scenario"] == "all"}
    assert set(pooled) == set(GSL_METHODS)
    # the oracle sees the same readings as DGSE-S: the same number of estimates
    assert pooled["adjoint-oracle"]["trials"] == pooled["dgse-s"]["trials"] == 2  # 2 scenarios x 1 trial
