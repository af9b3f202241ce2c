"""Suite ``variants``: DGSE-O, DGSE-P and DGSE-S against the number of observations (paper fig5).

Each variant (the shipped default weights, float32, DGSE-S with ``K = T = 5``)
is evaluated with :func:`dgse.evaluation.evaluate` on the same test scenarios
and the same random noisy observations: wind and concentration RMSE and NLL
(concentration in ``log(1 + ppm)``, the space the networks predict), and the
source-localization error and cross-entropy of the source posterior.
"""

from __future__ import annotations

from typing import Any

from dgse.bench.core import BenchContext
from dgse.bench.plots import curves_vs_observations, style_of

__all__ = ["METHODS", "run"]

METHODS = ("dgse-o", "dgse-p", "dgse-s")
_PANELS = [
    ("wf_rmse", "wind RMSE (m/s)"),
    ("wf_nll", "wind NLL"),
    ("cf_rmse", "concentration RMSE (log(1+ppm))"),
    ("cf_nll", "concentration NLL (log(1+ppm))"),
    ("sl_error_m", "source-localization error (m)"),
    ("ce", "source cross-entropy (nats)"),
]
_COLUMNS = [
    "method", "n_obs", "n_estimates", "sl_error_m_mean", "sl_error_m_median", "ce_mean",
    "wf_rmse_mean", "wf_nll_mean", "cf_rmse_mean", "cf_nll_mean", "seconds_per_estimate_median",
]  # fmt: skip


def _rows(results: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
    rows = []
    for method, res in results.items():
        for n, a in sorted(res["aggregate"].items(), key=lambda kv: int(kv[0])):
            rows.append({"method": method, "n_obs": int(n), **{c: a.get(c) for c in _COLUMNS[2:]}})
    return rows


def _ordering_text(results: dict[str, dict[str, Any]]) -> str:
    """Which variant has the lowest mean SL error at each count (computed, not asserted)."""
    counts = sorted(int(k) for k in results[METHODS[-1]]["aggregate"])
    wins: dict[str, list[int]] = {m: [] for m in results}
    paper_order = 0
    for c in counts:
        errs = {m: r["aggregate"][str(c)]["sl_error_m_mean"] for m, r in results.items()}
        best = min(errs, key=lambda m: errs[m])
        wins[best].append(c)
        if all(m in errs for m in METHODS) and errs["dgse-s"] < errs["dgse-p"] < errs["dgse-o"]:
            paper_order += 1
    parts = [
        f"{style_of(m)['label']} has the lowest mean error at {len(v)} of {len(counts)} counts"
        + (f" ({', '.join(map(str, v))})" if v else "")
        for m, v in wins.items()
    ]
    return (
        "; ".join(parts)
        + f". The paper's ordering S < P < O in mean SL error holds at {paper_order} of {len(counts)} counts."
    )


def _training_text() -> str:
    """The epoch and optimizer steps of each shipped checkpoint, and whether their budgets differ."""
    from dgse.estimators.dgse import default_model_path
    from dgse.models.checkpoint import read_checkpoint_info

    parts, steps = [], []
    for m in METHODS:
        t = read_checkpoint_info(default_model_path(m)).training
        ep, st = t.get("epoch"), t.get("global_step")
        ep_text = "?" if ep is None else ep
        st_text = "?" if st is None else st
        parts.append(f"{style_of(m)['label']} epoch {ep_text} ({st_text} steps)")
        if st:
            steps.append(int(st))
    text = (
        "Checkpoints (0-based epoch of the lowest validation source loss, optimizer steps taken): "
        + ", ".join(parts)
        + "."
    )
    if len(steps) < len(METHODS) or max(steps) > 1.1 * min(steps):
        text += (
            " Their training budgets differ by more than 10 %: compare them at equal steps with the "
            "validation curves of benchmarks/training.py curves."
        )
    return text


def run(ctx: BenchContext) -> None:
    """Evaluate the three variants and write fig5's panels and table."""
    from dgse.evaluation import evaluate

    counts = ctx.pick([5, 10, 25, 50, 100, 150, 200, 300], [5, 50])
    n_scen = ctx.pick(60, 2)
    trials = ctx.pick(2, 1)
    cases = ctx.scenarios(n_scen, "test")
    results: dict[str, dict[str, Any]] = {}
    for method in METHODS:
        results[method] = ctx.cached(
            f"eval_{method}",
            lambda m=method: evaluate(
                cases,
                m,
                counts,
                trials=trials,
                seed=ctx.seed,
                estimator_kwargs={"model": "default"},
                progress=ctx.progress,
            ),
        )
    sec = ctx.section(
        "DGSE-O vs DGSE-P vs DGSE-S",
        f"{n_scen} test scenarios x {trials} random sensor configuration(s) per observation count, "
        "Table I noise, identical observations for the three variants; shipped default weights; "
        "DGSE-S with K = T = 5. Field metrics over free cells; concentration in log(1 + ppm). "
        "Bands: standard error of the mean. " + _training_text() + "\n\n" + _ordering_text(results),
    )
    sec.figure(
        curves_vs_observations(results, _PANELS),
        "fig5_variants",
        "Wind field (WF), concentration field (CF) and source localization (SL) against the number of "
        "observations, like the paper's fig5.",
    )
    sec.table("variants", _rows(results), "Means over scenarios and trials per variant and count.", _COLUMNS)
