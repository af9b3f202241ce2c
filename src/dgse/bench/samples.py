"""Suite ``samples``: Monte Carlo sample counts of DGSE-S (paper App. C) and the surrogate objective (App. B).

* **Quality**: DGSE-S with several ``(K, T)`` on the same scenarios and
  observations; the relative reduction ``100 (M(1,1) - M(K,T)) / |M(1,1)|`` of
  the concentration NLL (log space) and of the source cross-entropy, for all
  counts, sparse (<= 50 observations) and dense (>= 200) ones (App. C fig. a).
* **Latency**: one full DGSE-S estimate (``estimate`` on the map: rasterize,
  networks, moment matching, cropping) against ``K = T`` and the map size,
  float32 and bfloat16 autocast with channels-last, on this machine's CPU
  threads (App. C fig. b; the paper measures on an embedded GPU).
* **Surrogate objective** (App. B, table ``object``): the Monte Carlo estimate
  of the original marginal losses, ``-log mean_i p(c_true | w_i)`` per valid
  cell and ``-log mean_ij p(s_true | w_i, c_ij)``, for ``S_c = S_s`` samples
  (:func:`dgse.models.objectives.mc_marginal_nll`), against the Jensen
  surrogate (one sample, the training loss' terms).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from dgse.bench.core import BenchContext, mean_std
from dgse.bench.plots import plt

__all__ = ["run"]


def _quality(ctx: BenchContext, cases: Path, settings: list[tuple[int, int]], counts: list[int], trials: int):
    from dgse.evaluation import evaluate

    out = {}
    for K, T in settings:
        res = ctx.cached(
            f"eval_K{K}_T{T}",
            lambda K=K, T=T: evaluate(
                cases, "dgse-s", counts, trials=trials, seed=ctx.seed,
                estimator_kwargs={"model": "default", "K": K, "T": T}, progress=ctx.progress,
            ),
        )  # fmt: skip
        out[(K, T)] = res
    return out


def _group_mean(res: dict[str, Any], metric: str, keep) -> float | None:
    vals = [r[metric] for r in res["per_case"] if keep(r["n_obs"]) and r.get(metric) is not None]
    return mean_std(vals)[0]


def _latency(ctx: BenchContext, sizes: list[int], ks: list[int], repeats: int) -> list[dict[str, Any]]:
    import torch

    from dgse.estimators.registry import get_estimator
    from dgse.sensing.sensors import Observations

    rows = []
    rng = np.random.default_rng(ctx.seed)
    for size in sizes:
        occ = np.zeros((size, size), np.uint8)
        occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = 1
        free = np.argwhere(occ == 0)
        pick = free[rng.choice(len(free), 50, replace=False)]
        obs = Observations(cells=pick, gas=rng.uniform(0, 50, 50), wind=rng.normal(0, 0.3, (50, 2)))
        for label, kw in (
            ("float32", {}),
            ("bf16+channels_last", {"dtype": "bfloat16", "channels_last": True}),
        ):
            for k in ks:
                est = get_estimator("dgse-s", model="default", K=k, T=k, seed=0, **kw)
                est.estimate(occ, 0.1, obs)  # warm-up
                times = []
                for _ in range(repeats):
                    t0 = time.perf_counter()
                    est.estimate(occ, 0.1, obs)
                    times.append(time.perf_counter() - t0)
                rows.append(
                    {"map_cells": f"{size}x{size}", "K=T": k, "precision": label,
                     "seconds_median": float(np.median(times)), "seconds_min": float(np.min(times)),
                     "threads": torch.get_num_threads()}
                )  # fmt: skip
    return rows


def _surrogate(ctx: BenchContext, files: list[Path], n_obs: list[int], sizes: list[int]) -> dict[str, Any]:
    import torch

    from dgse.data.rasterize import make_sample
    from dgse.estimators.dgse import default_model_path
    from dgse.evaluation.evaluate import draw_observations
    from dgse.models.checkpoint import load_checkpoint
    from dgse.models.objectives import TargetBatch, mc_marginal_nll
    from dgse.world.case import Case

    model, _ = load_checkpoint(default_model_path("dgse-s"), variant="dgse-s")
    groups: dict[tuple[int, int], list] = {}
    for f in files:
        case = Case.load(f)
        for i, n in enumerate(n_obs):
            s = make_sample(case, draw_observations(case, n, ctx.seed, case_id=f.stem, trial=i))
            groups.setdefault(s.canvas_shape, []).append(s)
    out: dict[str, Any] = {
        "S": sizes,
        "conc_nll": [],
        "source_ce": [],
        "n_samples": sum(map(len, groups.values())),
    }
    for S in sizes:
        conc, ce = [], []
        for samples in groups.values():
            x = torch.from_numpy(np.stack([s.inputs for s in samples]))
            tb = TargetBatch.from_targets([s.targets for s in samples])
            r = mc_marginal_nll(model, x, tb, S_c=S, S_s=S, seed=ctx.seed + S, max_batch=64, reduction="none")
            conc += r["conc_nll"].tolist()
            ce += r["source_ce"].tolist()
        out["conc_nll"].append(float(np.mean(conc)))
        out["source_ce"].append(float(np.mean(ce)))
    return out


def run(ctx: BenchContext) -> None:
    """Sample-count quality, latency and the surrogate objective check."""
    import torch

    settings = ctx.pick([(1, 1), (2, 2), (5, 1), (1, 5), (5, 5), (10, 10)], [(1, 1), (2, 2)])
    counts = ctx.pick([10, 25, 50, 200, 300], [10, 200])
    n_scen = ctx.pick(20, 2)
    trials = ctx.pick(1, 1)
    cases = ctx.scenarios(n_scen, "test")
    q = _quality(ctx, cases, settings, counts, trials)
    groups = {
        "all": lambda n: True,
        "sparse (<= 50)": lambda n: n <= 50,
        "dense (>= 200)": lambda n: n >= 200,
    }
    base = q[(1, 1)]
    rows = []
    for (K, T), res in q.items():
        row: dict[str, Any] = {"K": K, "T": T}
        for g, keep in groups.items():
            for metric, label in (("cf_nll", "cf_nll"), ("ce", "ce")):
                m0, m = _group_mean(base, metric, keep), _group_mean(res, metric, keep)
                row[f"{label} {g}"] = m
                row[f"{label} rel. reduction % {g}"] = (
                    None if m0 is None or m is None or m0 == 0 else 100.0 * (m0 - m) / abs(m0)
                )
        row["seconds_per_estimate_median"] = float(np.median([r["seconds"] for r in res["per_case"]]))
        rows.append(row)
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    xs = [f"{K},{T}" for K, T in q]
    for ax, metric, title in ((axes[0], "ce", "source CE"), (axes[1], "cf_nll", "concentration NLL")):
        for (g, _), color in zip(groups.items(), ("k", "tab:red", "tab:blue"), strict=True):
            ax.plot(xs, [r[f"{metric} rel. reduction % {g}"] for r in rows], marker="o", color=color, label=g)
        ax.set_xlabel("K, T")
        ax.set_ylabel("reduction vs K = T = 1 (%)")
        ax.set_title(title)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    sec = ctx.section(
        "Quality against the number of samples",
        f"DGSE-S (shipped weights, float32) on {n_scen} test scenarios, observation counts "
        f"{', '.join(map(str, counts))}, identical observations for every (K, T). Relative reduction of "
        "the mean metric against single-sample inference (App. C); positive is better. The concentration "
        "NLL depends on K only.",
    )
    sec.figure(
        fig, "samples_quality", "Relative reduction of source CE and concentration NLL against (K, T)."
    )
    sec.table("samples_quality", rows, "Mean metrics and relative reductions per (K, T).")

    lat = ctx.cached(
        "latency", lambda: _latency(ctx, ctx.pick([100, 160, 200], [100]), ctx.pick([1, 2, 5, 10], [1, 5]),
                                    ctx.pick(7, 2))
    )  # fmt: skip
    fig, ax = plt.subplots(figsize=(5.5, 3.6))
    for (size, prec), color in zip(
        sorted({(r["map_cells"], r["precision"]) for r in lat}), plt.cm.tab10.colors, strict=False
    ):
        rr = [r for r in lat if r["map_cells"] == size and r["precision"] == prec]
        ax.plot([r["K=T"] for r in rr], [r["seconds_median"] for r in rr], marker="o", color=color,
                label=f"{size}, {prec}")  # fmt: skip
    ax.axhline(0.1, color="k", ls=":", lw=0.8, label="0.1 s goal")
    ax.set_xlabel("K = T")
    ax.set_ylabel("seconds per estimate (median)")
    ax.set_yscale("log")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    sec = ctx.section(
        "Latency",
        f"One full DGSE-S estimate (50 observations) on square maps, {torch.get_num_threads()} CPU "
        "thread(s), "
        "median of repeated runs after a warm-up; the networks' cost grows with K for the concentration "
        "stage and with K x T for the source stage.",
    )
    sec.figure(fig, "samples_latency", "Latency of one DGSE-S estimate against K = T and map size.")
    sec.table("samples_latency", lat, "Latency per estimate.")

    files = sorted(cases.glob("*.npz"))[: ctx.pick(10, 1)]
    sur = ctx.cached(
        "surrogate",
        lambda: _surrogate(ctx, files, ctx.pick([10, 50, 200], [50]), ctx.pick([1, 2, 5, 10, 50], [1, 2])),
    )
    rows = [
        {"S_c = S_s": S, "CF loss": c, "SL loss": s}
        for S, c, s in zip(sur["S"], sur["conc_nll"], sur["source_ce"], strict=True)
    ]
    sec = ctx.section(
        "Surrogate objective (App. B)",
        f"Monte Carlo estimates of the original marginal losses of the shipped DGSE-S on {sur['n_samples']} "
        "test samples (field-joint concentration likelihood divided by the valid cells, as the training "
        "loss). S = 1 is the Jensen surrogate the network is trained on; the losses should fall "
        "slightly and level off as S grows (the paper's table object).",
    )
    sec.table(
        "surrogate_objective", rows, "MC-estimated original losses (lower is better) against S_c = S_s."
    )
