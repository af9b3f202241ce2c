"""Suite ``calibration``: are the predicted uncertainties honest? (no paper here reports it)

For every method and estimate on the test scenarios (the same seeded
observations as :func:`dgse.evaluation.evaluate`), this suite pools

* the wind components and ``log(1 + c)`` over free cells: observed coverage of
  the central Gaussian intervals at nominal levels 10 % ... 99 % (reliability
  diagram), in particular 1 and 2 sigma;
* the credible level of the true source cell under the source posterior
  (:func:`dgse.evaluation.calibration.credible_level`): coverage of the
  highest-density credible sets and their expected calibration error.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from dgse.bench.core import BenchContext
from dgse.bench.plots import plt, style_of
from dgse.errors import UnsupportedError
from dgse.evaluation.calibration import (
    DEFAULT_LEVELS,
    SIGMA_LEVELS,
    calibration_error,
    coverage_curve,
    credible_level,
    interval_hits,
)

__all__ = ["FIELD_METHODS", "SOURCE_METHODS", "run"]

#: Methods with probabilistic wind and/or concentration fields.
FIELD_METHODS = ("dgse-s", "dgse-phys", "dgse-p", "gwgmrf", "ggmrf")
#: Methods with a source posterior.
SOURCE_METHODS = ("dgse-s", "dgse-phys", "dgse-p", "dgse-o", "adjoint", "dualmode")


def _collect(ctx: BenchContext, method: str, files: list[Path], counts: list[int], trials: int) -> dict:
    from dgse.belief.knowledge import Knowledge
    from dgse.estimators.registry import get_estimator
    from dgse.evaluation.evaluate import draw_observations, estimator_seed
    from dgse.world.case import Case

    est = get_estimator(method)  # published defaults; the shipped weights for DGSE
    levels = list(DEFAULT_LEVELS)
    acc: dict[str, Any] = {
        str(n): {"wind_hits": np.zeros(len(levels), np.int64), "wind_n": 0,
                 "conc_hits": np.zeros(len(levels), np.int64), "conc_n": 0, "source_levels": []}
        for n in counts
    }  # fmt: skip
    for f in files:
        case = Case.load(f)
        est.set_knowledge(Knowledge.from_case(case, ctx.knowledge))
        free = case.occupancy == 0
        logc = np.log1p(np.maximum(case.concentration, 0.0))
        for n in counts:
            a = acc[str(n)]
            for t in range(trials):
                obs = draw_observations(case, n, ctx.seed, case_id=f.stem, trial=t)
                est.seed = estimator_seed(ctx.seed, f.stem, n, t)
                b = est.estimate(case.occupancy, case.resolution, obs)
                if b.wind_mean is not None and b.wind_var is not None:
                    h, k = interval_hits(case.wind, b.wind_mean, b.wind_var, levels, mask=free)
                    a["wind_hits"] += h
                    a["wind_n"] += k
                if b.log_conc_mean is not None and b.log_conc_var is not None:
                    h, k = interval_hits(logc, b.log_conc_mean, b.log_conc_var, levels, mask=free)
                    a["conc_hits"] += h
                    a["conc_n"] += k
                a["source_levels"].append(credible_level(b.source_probs, case.source_cell))
    out: dict[str, Any] = {"method": method, "levels": levels, "by_count": {}}
    for n, a in acc.items():
        row: dict[str, Any] = {"n_estimates": len(a["source_levels"])}
        for fld in ("wind", "conc"):
            row[f"{fld}_coverage"] = (a[f"{fld}_hits"] / a[f"{fld}_n"]).tolist() if a[f"{fld}_n"] else None
        row["source_levels"] = a["source_levels"]
        row["source_coverage"] = coverage_curve(a["source_levels"], levels).tolist()
        out["by_count"][n] = row
    return out


def _sigma_coverage(levels: list[float], cov: list[float] | None) -> tuple[float | None, float | None]:
    if cov is None:
        return None, None
    lv = np.asarray(levels)
    c = np.asarray(cov)
    return float(np.interp(SIGMA_LEVELS[0], lv, c)), float(np.interp(SIGMA_LEVELS[1], lv, c))


def _reliability_figure(results: dict[str, dict], key: str, title: str, counts: list[int]) -> Any:
    fig, axes = plt.subplots(1, len(counts), figsize=(3.6 * len(counts), 3.5), squeeze=False)
    for ax, n in zip(axes[0], counts, strict=True):
        ax.plot([0, 1], [0, 1], color="k", lw=0.8, ls="--", label="calibrated")
        for method, res in results.items():
            cov = res["by_count"][str(n)].get(key)
            if cov is None:
                continue
            st = style_of(method)
            ax.plot(res["levels"], cov, marker=st["marker"], color=st["color"], label=st["label"], ms=3)
        ax.set_title(f"{n} observations")
        ax.set_xlabel("nominal level")
        ax.set_ylabel("observed coverage")
        ax.set_xlim(0, 1)
        ax.set_ylim(0, 1)
        ax.grid(alpha=0.3)
    axes[0, -1].legend(fontsize=7, loc="lower right")
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def run(ctx: BenchContext) -> None:
    """Reliability diagrams and coverage tables for fields and source posteriors."""
    counts = ctx.pick([25, 100, 300], [25])
    n_scen = ctx.pick(20, 2)
    trials = ctx.pick(2, 1)
    files = sorted(ctx.scenarios(n_scen, "test").glob("*.npz"))
    results: dict[str, dict] = {}
    methods, _ = ctx.methods_at_level(list(dict.fromkeys(FIELD_METHODS + SOURCE_METHODS)))
    for method in methods:
        try:
            results[method] = ctx.cached(
                f"calibration_{method}",
                lambda m=method: _collect(ctx, m, files, counts, trials),
            )
        except UnsupportedError as e:  # e.g. no shipped weights for a variant
            ctx.note(f"{method} left out: {e}")
    rows = []
    for method, res in results.items():
        for n, r in res["by_count"].items():
            w1, w2 = _sigma_coverage(res["levels"], r["wind_coverage"])
            c1, c2 = _sigma_coverage(res["levels"], r["conc_coverage"])
            lv = res["levels"]
            has_src = method in SOURCE_METHODS
            wc, cc = r["wind_coverage"], r["conc_coverage"]
            rows.append(
                {
                    "method": method,
                    "n_obs": int(n),
                    "n_estimates": r["n_estimates"],
                    "wind_cov_1sigma": w1,
                    "wind_cov_2sigma": w2,
                    "conc_cov_1sigma": c1,
                    "conc_cov_2sigma": c2,
                    "wind_cal_error": None if wc is None else calibration_error(wc, lv),
                    "conc_cal_error": None if cc is None else calibration_error(cc, lv),
                    # methods without a source model (GMRFs: uniform posterior) get no source columns
                    "source_cal_error": calibration_error(r["source_coverage"], lv) if has_src else None,
                    "source_median_level": float(np.median(r["source_levels"])) if has_src else None,
                }
            )
    field = {m: results[m] for m in FIELD_METHODS if m in results}
    src = {m: results[m] for m in SOURCE_METHODS if m in results}
    sec = ctx.section(
        "Field uncertainty",
        f"{n_scen} test scenarios x {trials} random sensor configuration(s) per count. Observed coverage of "
        "the central Gaussian intervals of the predicted mean and variance over free cells (wind: both "
        "components pooled; concentration: log(1 + ppm)). On the diagonal: calibrated; below: "
        "overconfident; above: underconfident. The nominal 1 and 2 sigma coverages are 68.3 % and 95.4 %.",
    )
    sec.figure(
        _reliability_figure(field, "wind_coverage", "wind field", counts), "reliability_wind",
        "Reliability of the predicted wind uncertainty.",
    )  # fmt: skip
    sec.figure(
        _reliability_figure(field, "conc_coverage", "concentration field (log(1+ppm))", counts),
        "reliability_concentration",
        "Reliability of the predicted concentration uncertainty.",
    )
    sec2 = ctx.section(
        "Source posterior",
        "Coverage of the highest-density credible sets of the source posterior: the fraction of estimates "
        "whose true source cell lies in the smallest set of most probable cells holding the nominal mass. "
        "Calibration error: mean absolute gap to the diagonal over the levels; median level of the "
        "truth: 0.5 for a calibrated posterior, lower when the truth sits in the high-probability core.",
    )
    sec2.figure(
        _reliability_figure(src, "source_coverage", "source posterior credible sets", counts),
        "reliability_source",
        "Reliability of the source posteriors.",
    )
    sec2.table(
        "calibration",
        rows,
        "Coverage of the 1 and 2 sigma intervals (nominal 0.683 and 0.954), calibration errors (0 is ideal).",
    )
