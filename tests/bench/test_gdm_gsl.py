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
from tests.bench.baselines import below, pooled, quick_case_dir, quick_cases, uninformed


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
    """Every method's concentration map beats the map of no gas (:mod:`tests.bench.baselines`), per
    scenario in ppm and pooled in ``log(1 + ppm)``.  Not every method beats the best constant map
    on these two scenarios (the kernel and belief-propagation maps in log space, the GMRF NLLs
    against the best single Gaussian), so the NLLs are only checked finite."""
    files = {f["file"] for s in gdm["sections"] for f in s["figures"]}
    assert "fig8_gdm_rmse_nll.png" in files and "fig9_gdm_time.png" in files
    assert sum(f.startswith("fig7_maps_") for f in files) == 1  # quick: the first scenario only
    cases = quick_cases(bench_root)
    per_case = _table(gdm, "fig8_gdm_per_scenario")
    assert {r["method"] for r in per_case} == set(GDM_METHODS)
    for r in per_case:
        # every method has a ppm RMSE below the no-gas map's; a variance, hence an NLL, all of them
        zero = uninformed(cases[r["scenario"]])["cf_rmse_ppm_zero"]
        assert 0 <= r["cf_rmse_ppm_mean"] and below(r["cf_rmse_ppm_mean"], zero), (r, zero)
        assert _finite(r["cf_nll_ppm_mean"])
        assert r["nll_comparable"] == (r["method"] in NLL_METHODS)
    log_rows = _table(gdm, "gdm_overall_log")
    assert {r["method"] for r in log_rows} == set(GDM_METHODS)
    for r in log_rows:
        res = json.loads((bench_root / "gdm" / f"eval_{r['method']}.json").read_text())
        records = [c for c in res["per_case"] if c["n_obs"] == r["n_obs"]]
        assert len(records) == r["estimates"]
        zero = pooled(records, cases, "cf_rmse_zero")
        assert below(r["cf_rmse_mean"], zero), (r, zero)
        assert _finite(r["cf_nll_mean"])
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


#: Particle posteriors: they put (nearly) no mass on the exact true cell, so their CE is above the
#: uniform posterior's on these scenarios.
PARTICLE_METHODS = ("dualmode", "pmfs")


def test_gsl_quick(bench_root: Path) -> None:
    """Every method's SL error, pooled over the scenarios it ran on, is below the uniform source
    posterior's there (:mod:`tests.bench.baselines`); per scenario a 50-reading estimate may land
    farther off than the free cells' centroid (DGSE-S does on one of the two).  The CE of every
    method but the particle filters is below the uniform posterior's in every row.  The particle
    filters' CE is no better than uniform here: for them the test asserts the floor's range and
    that a second evaluation with the same seed reproduces the dual-mode filter's numbers exactly.
    """
    from dgse.evaluation import evaluate

    # at 'wind' every method of the comparison works (the oracle needs the flow)
    m = _manifest(run_suite("gsl", bench_root, quick=True, knowledge="wind"))
    assert m["knowledge"] == "wind"
    files = {f["file"] for s in m["sections"] for f in s["figures"]}
    assert {"fig_gsl_only.png", "gsl_time.png"} <= files
    text = m["sections"][0]["text"]
    assert "grgsl is excluded" in text and "lower-bound" in text and "Knowledge: 'wind'" in text
    rows = _table(m, "gsl_only")
    assert {r["method"] for r in rows} == set(GSL_METHODS)
    cases = quick_cases(bench_root)
    evals = {k: json.loads((bench_root / "gsl-wind" / f"eval_{k}.json").read_text()) for k in GSL_METHODS}
    for r in rows:
        assert r["oracle"] == (r["method"] in ORACLES)
        records = [c for c in evals[r["method"]]["per_case"] if r["scenario"] in ("all", c["case"])]
        assert len(records) == r["trials"]
        assert _finite(r["sl_error_m_mean"]) and r["sl_error_m_mean"] >= 0
        if r["scenario"] == "all":
            bound = pooled(records, cases, "sl_error_m")
            assert below(r["sl_error_m_mean"], bound), (r, bound)
        # CE is -log p(true cell) with p floored at 1e-12
        assert _finite(r["ce_mean"]) and 0 <= r["ce_mean"] <= -math.log(1e-12) + 1e-9
        if r["method"] not in PARTICLE_METHODS:
            bound = pooled(records, cases, "ce")
            assert below(r["ce_mean"], bound), (r, bound)
        assert r["seconds_median"] > 0
    by_method = {r["method"]: r for r in rows if r["scenario"] == "all"}
    assert set(by_method) == set(GSL_METHODS)
    # the oracle sees the same readings as DGSE-S: the same number of estimates, 2 scenarios x 1 trial
    assert by_method["adjoint-oracle"]["trials"] == by_method["dgse-s"]["trials"] == 2
    # the dual-mode filter's numbers are its seed's: a second evaluation gives them to the bit
    first = evals["dualmode"]
    again = evaluate(
        quick_case_dir(bench_root),
        "dualmode",
        first["observation_counts"],
        trials=first["trials"],
        seed=first["seed"],
        knowledge=first["knowledge"],
    )
    keys = ("case", "n_obs", "trial", "sl_error_m", "ce", "source_estimate_xy")
    assert [{k: c[k] for k in keys} for c in again["per_case"]] == [
        {k: c[k] for k in keys} for c in first["per_case"]
    ]
