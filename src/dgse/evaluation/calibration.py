"""Calibration of predicted uncertainty: are the error bars and the source posterior honest?

Pure functions on arrays (no estimator, no I/O):

* Gaussian fields (wind, ``log(1 + c)``): the central interval of nominal
  level ``p`` is ``|truth - mean| <= z_p * std`` with ``z_p = Phi^-1((1 + p) / 2)``;
  :func:`interval_hits` counts how many cells fall inside it for each level.
  A calibrated predictor covers a fraction ``p`` (1 sigma: 68.3 %, 2 sigma:
  95.4 %); less means overconfident, more underconfident.
* A source posterior over cells: :func:`credible_level` is the smallest
  highest-density credible level whose set contains the true cell (the
  probability mass of the cells more probable than it, plus half the mass of
  ties).  For a calibrated posterior it is uniform on ``[0, 1]``, so the
  fraction of cases with level ``<= p`` is ``p`` for every ``p``
  (:func:`coverage_curve`); :func:`calibration_error` is the mean absolute gap
  over a grid of levels (an expected calibration error of the credible sets).
  On a few cases that error is mostly sampling noise:
  :func:`chance_calibration_error` is what a calibrated posterior would show.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.special import ndtri
from scipy.stats import binom

from dgse.errors import InputDataError

__all__ = [
    "DEFAULT_LEVELS",
    "SIGMA_LEVELS",
    "calibration_error",
    "chance_calibration_error",
    "coverage_curve",
    "credible_level",
    "interval_hits",
]

#: Nominal levels of the reliability diagrams.
DEFAULT_LEVELS = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 0.95, 0.99)
#: The levels of the 1 and 2 sigma intervals of a Gaussian.
SIGMA_LEVELS = (0.6826894921370859, 0.9544997361036416)


def _levels(levels: Sequence[float]) -> np.ndarray:
    lv = np.asarray(levels, dtype=float)
    if lv.ndim != 1 or lv.size == 0 or not ((lv > 0) & (lv < 1)).all():
        raise InputDataError(f"levels must be in (0, 1), got {levels}")
    return lv


def interval_hits(
    truth: np.ndarray,
    mean: np.ndarray,
    var: np.ndarray,
    levels: Sequence[float] = DEFAULT_LEVELS,
    mask: np.ndarray | None = None,
    var_floor: float = 1e-12,
) -> tuple[np.ndarray, int]:
    """How many values lie inside the central Gaussian intervals of each level.

    Args:
        truth, mean, var: arrays of one shape (variance clipped at ``var_floor``).
        levels: nominal levels in (0, 1).
        mask: boolean array of that shape (or of its trailing dims, broadcast):
            which values count (e.g. free cells).

    Returns:
        ``(hits, n)``: ``hits[k]`` values inside the level-``k`` interval, out of ``n``.
    """
    t, m, v = (np.asarray(a, dtype=float) for a in (truth, mean, var))
    if not (t.shape == m.shape == v.shape):
        raise InputDataError(f"truth, mean and var differ in shape: {t.shape}, {m.shape}, {v.shape}")
    lv = _levels(levels)
    z = np.abs(t - m) / np.sqrt(np.maximum(v, var_floor))
    if mask is not None:
        z = z[np.broadcast_to(np.asarray(mask, dtype=bool), z.shape)]
    z = z[np.isfinite(z)].ravel()
    bounds = ndtri(0.5 * (1.0 + lv))
    hits = (z[None, :] <= bounds[:, None]).sum(axis=1)
    return hits.astype(np.int64), int(z.size)


def credible_level(probs: np.ndarray, true_index: int | tuple[int, ...]) -> float:
    """The highest-density credible level at which the set first contains the true cell.

    ``sum(p[p > p_true]) + 0.5 * sum(p[p == p_true])`` for normalized ``probs``.
    """
    p = np.asarray(probs, dtype=float)
    total = p.sum()
    if not (np.isfinite(total) and total > 0) or (p < 0).any():
        raise InputDataError("probs must be non-negative with a positive finite sum")
    p = p / total
    pt = p[true_index]
    return float(p[p > pt].sum() + 0.5 * p[p == pt].sum())


def coverage_curve(levels_of_truth: Sequence[float], levels: Sequence[float] = DEFAULT_LEVELS) -> np.ndarray:
    """Fraction of cases whose credible level is at most each nominal level."""
    u = np.asarray(levels_of_truth, dtype=float)
    if u.size == 0:
        raise InputDataError("no cases")
    lv = _levels(levels)
    return (u[None, :] <= lv[:, None]).mean(axis=1)


def calibration_error(observed: Sequence[float], levels: Sequence[float] = DEFAULT_LEVELS) -> float:
    """Mean absolute gap between observed and nominal coverage over the levels."""
    o = np.asarray(observed, dtype=float)
    lv = _levels(levels)
    if o.shape != lv.shape:
        raise InputDataError(f"{o.size} observed coverages for {lv.size} levels")
    return float(np.abs(o - lv).mean())


def chance_calibration_error(n_cases: int, levels: Sequence[float] = DEFAULT_LEVELS) -> float:
    """The calibration error a perfectly calibrated posterior shows on ``n_cases`` cases, on average.

    Its credible levels are uniform on ``[0, 1]``, so the number of cases covered at
    level ``p`` is binomial ``(n_cases, p)`` and the error measured on a finite sample
    is sampling noise alone: a measured error near this value says nothing about
    miscalibration.  Exact (a sum over the binomial's outcomes).
    """
    if n_cases < 1:
        raise InputDataError(f"n_cases must be positive, got {n_cases}")
    lv = _levels(levels)
    k = np.arange(n_cases + 1)
    pmf = binom.pmf(k[None, :], n_cases, lv[:, None])
    return float((pmf * np.abs(k[None, :] / n_cases - lv[:, None])).sum(axis=1).mean())


def calibration_difference(
    levels_a: Sequence[float],
    levels_b: Sequence[float],
    groups: Sequence[object],
    *,
    n_boot: int = 2000,
    coverage: float = 0.9,
    seed: int = 0,
    levels: Sequence[float] = DEFAULT_LEVELS,
) -> dict[str, float]:
    """The calibration error of ``a`` minus that of ``b`` on the same estimates, with a
    bootstrap interval that resamples whole groups (scenarios).

    Trials of one scenario share its flow and source, so their credible levels are not
    independent: :func:`chance_calibration_error`, which assumes they are, understates how
    much a difference between two methods moves from one set of scenarios to another.
    Resampling the groups with replacement keeps that dependence.  ``levels_a[i]`` and
    ``levels_b[i]`` are the truth's credible levels of estimate ``i`` under the two methods,
    ``groups[i]`` its scenario.

    Returns ``{"a", "b", "difference", "low", "high", "groups"}``: both errors, their
    difference, its central ``coverage`` bootstrap interval and the number of groups.
    """
    a = np.asarray(levels_a, dtype=float)
    b = np.asarray(levels_b, dtype=float)
    g = np.asarray([str(x) for x in groups])
    if a.size == 0 or a.shape != b.shape or g.shape != a.shape:
        raise InputDataError(f"{a.size}, {b.size} and {g.size} levels and groups: need as many, at least one")
    if not (0.0 < coverage < 1.0) or int(n_boot) < 1:
        raise InputDataError(f"coverage must be in (0, 1) and n_boot >= 1, got {coverage} and {n_boot}")
    names, idx = np.unique(g, return_inverse=True)
    members = [np.flatnonzero(idx == k) for k in range(names.size)]

    def error(x: np.ndarray) -> float:
        return calibration_error(coverage_curve(x, levels), levels)

    rng = np.random.default_rng(seed)
    diffs = np.empty(int(n_boot))
    for t in range(diffs.size):
        pick = np.concatenate([members[k] for k in rng.integers(0, names.size, names.size)])
        diffs[t] = error(a[pick]) - error(b[pick])
    tail = 0.5 * (1.0 - coverage)
    low, high = np.quantile(diffs, [tail, 1.0 - tail])
    ea, eb = error(a), error(b)
    out = {"a": ea, "b": eb, "difference": ea - eb, "low": float(low), "high": float(high)}
    return {**out, "groups": float(names.size)}
