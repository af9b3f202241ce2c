"""Metrics of one estimate against the truth (spec section 6, paper Sec. V-A to V-C).

Every function is pure: it takes a :class:`~dgse.belief.belief.Belief`
and the true :class:`~dgse.world.case.Case` (same grid) and returns a float.
A metric the belief cannot provide (no wind estimate, no variance, ...) is
``NaN``, never an error, so classical baselines with partial outputs are
scored on what they have.

Definitions (``F`` = the free cells of the case, ``|F|`` their number):

* **source-localization error** ``sl_error_m`` (m): Euclidean distance
  between the probability-weighted mean position
  ``s_hat = sum_ij pi_ij (x_j, y_i)`` (:meth:`Belief.source_estimate`, paper
  Sec. III-D) and the true source position ``case.source``.
* **cross-entropy** ``ce`` (nats): ``-log max(pi[i*, j*], PROB_FLOOR)`` at
  the true source cell ``(i*, j*) = case.source_cell``.  The floor
  (``1e-12``, so at most ``27.63`` nats) keeps the value finite for
  posteriors that put exactly zero (or a float32-underflowed) mass on the
  true cell, e.g. particle filters; it is far below any useful posterior
  (uniform over a 10 x 10 m map: ``1e-4``).
* **wind** ``wf_rmse`` (m/s) and ``wf_nll`` (nats): over the ``2 |F|``
  scalar components ``(u_x, u_y)`` at free cells,
  ``RMSE = sqrt(mean (mu - w)^2)`` and the Gaussian NLL *per component*
  ``mean 0.5 [log(2 pi v) + (w - mu)^2 / v]``.  (The training loss of
  :func:`dgse.models.objectives.gaussian_nll` sums the two components of a
  cell and averages over the valid cells, walls included: on free cells it
  is twice ``wf_nll``.)
* **concentration, log space** ``cf_rmse``, ``cf_nll``: the same on
  ``L = log(1 + c)`` (``c`` in ppm) at free cells, against the belief's
  ``log_conc_mean`` / ``log_conc_var`` (the networks' scale, paper Fig. 5).
* **concentration, ppm space** ``cf_rmse_ppm`` (ppm), ``cf_nll_ppm`` (nats
  per cell, density in ppm^-1): each belief's own prediction in ppm, by its
  native space (:attr:`Belief.conc_space`; paper Sec. V-B, Fig. 8: "DGSE-S
  predictions were transformed back to the original scale"):

  - ``"log"`` beliefs (DGSE): the RMSE of the median map ``exp(m) - 1``
    (:attr:`Belief.conc_point_ppm`) and the NLL of the exact density of
    ``c = exp(L) - 1`` with ``L ~ N(m, v)``:
    ``-log p(c) = NLL_log(log(1 + c)) + log(1 + c)`` (:func:`lognormal_nll_ppm`,
    the change of variables ``dL/dc = 1 / (1 + c)``).  The lognormal *mean*
    ``exp(m + v/2) - 1`` is not used: it grows like ``exp(v/2)`` where the
    log-space variance is large, and a Gaussian with the lognormal moments
    misstates a skewed density;
  - ``"ppm"`` beliefs (the GDM baselines, whose outputs are Gaussians in
    ppm): the RMSE of their mean and the Gaussian NLL ``N(c; mean, var)``
    with their own mean and variance (:attr:`Belief.conc_mean_ppm`,
    :attr:`Belief.conc_var_ppm`).

  Both NLLs are densities of the same variable ``c`` in ppm^-1, so they are
  comparable.  A belief without a concentration variance has
  ``cf_nll = cf_nll_ppm = NaN``.

Variances are floored at ``VAR_FLOOR`` (``1e-12`` in the field's squared
unit) inside the NLL so that a zero variance gives a large finite value
rather than infinity; the DGSE networks never come close (their log-variance
is clamped at -12, a variance of 6e-6).

The truth: ``case.wind`` and ``case.concentration`` (the steady field; for a
case with ``frames`` that is the field the case file stores as its steady or
time-averaged concentration).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from dgse.belief.belief import Belief
from dgse.errors import InputDataError
from dgse.world.case import Case

__all__ = [
    "LOG_2PI",
    "METRIC_KEYS",
    "PROB_FLOOR",
    "VAR_FLOOR",
    "EstimateMetrics",
    "concentration_metrics",
    "evaluate_belief",
    "gaussian_nll",
    "lognormal_nll_ppm",
    "rmse",
    "source_cross_entropy",
    "source_localization_error",
    "wind_metrics",
]

#: Smallest probability used in the cross-entropy (CE is at most ``-log(1e-12) = 27.63`` nats).
PROB_FLOOR = 1e-12
#: Smallest variance used in a Gaussian NLL (in the squared unit of the field).
VAR_FLOOR = 1e-12
LOG_2PI = math.log(2.0 * math.pi)

NAN = float("nan")


def rmse(estimate: np.ndarray, truth: np.ndarray) -> float:
    """Root mean square of ``estimate - truth`` over all elements (NaN for no elements)."""
    e = np.asarray(estimate, dtype=np.float64)
    t = np.asarray(truth, dtype=np.float64)
    if e.shape != t.shape:
        raise InputDataError(f"rmse: shapes {e.shape} and {t.shape} differ")
    if e.size == 0:
        return NAN
    return float(np.sqrt(np.mean(np.square(e - t))))


def _gaussian_nll_terms(
    what: str, t: np.ndarray, mean: np.ndarray, var: np.ndarray, var_floor: float
) -> np.ndarray | None:
    """Each element's ``0.5 [log(2 pi v) + (t - mu)^2 / v]`` (nats), ``v`` raised to ``var_floor``;
    None for no elements.  ``what`` names the metric when the shapes differ."""
    m = np.asarray(mean, dtype=np.float64)
    v = np.asarray(var, dtype=np.float64)
    if not (t.shape == m.shape == v.shape):
        raise InputDataError(f"{what}: shapes {t.shape}, {m.shape}, {v.shape} differ")
    if t.size == 0:
        return None
    v = np.maximum(v, var_floor)
    return 0.5 * (LOG_2PI + np.log(v) + np.square(t - m) / v)


def gaussian_nll(truth: np.ndarray, mean: np.ndarray, var: np.ndarray, var_floor: float = VAR_FLOOR) -> float:
    """Mean Gaussian negative log-likelihood ``0.5 [log(2 pi v) + (t - mu)^2 / v]`` in nats.

    Args:
        truth, mean, var: equal shapes; the mean is taken over all elements.
        var_floor: variances below it are raised to it.
    """
    t = np.asarray(truth, dtype=np.float64)
    terms = _gaussian_nll_terms("gaussian_nll", t, mean, var, var_floor)
    return NAN if terms is None else float(np.mean(terms))


def lognormal_nll_ppm(
    truth_ppm: np.ndarray, log_mean: np.ndarray, log_var: np.ndarray, var_floor: float = VAR_FLOOR
) -> float:
    """Mean NLL (nats, density in ppm^-1) of ``c`` when ``log(1 + c) ~ N(log_mean, log_var)``.

    The exact density by the change of variables:
    ``-log p(c) = 0.5 [log(2 pi v) + (log(1 + c) - m)^2 / v] + log(1 + c)``
    (``c >= 0``; negative truths are clipped at 0).
    """
    t = np.log1p(np.maximum(np.asarray(truth_ppm, dtype=np.float64), 0.0))
    terms = _gaussian_nll_terms("lognormal_nll_ppm", t, log_mean, log_var, var_floor)
    return NAN if terms is None else float(np.mean(terms + t))


def _check_same_grid(belief: Belief, case: Case) -> None:
    if belief.shape != tuple(case.occupancy.shape):
        raise InputDataError(
            f"the belief's map {belief.shape} and the case's map {tuple(case.occupancy.shape)} differ"
        )
    if not math.isclose(belief.resolution, case.resolution, rel_tol=1e-6):
        raise InputDataError(
            f"the belief's cell size {belief.resolution} m and the case's {case.resolution} m differ"
        )


def source_localization_error(belief: Belief, source_xy: tuple[float, float] | np.ndarray) -> float:
    """Distance (m) from the probability-weighted mean position to the true source ``(x, y)``."""
    xy = np.asarray(source_xy, dtype=np.float64).reshape(-1)
    if xy.shape != (2,):
        raise InputDataError(f"source position must be (x, y), got shape {xy.shape}")
    return belief.localization_error((float(xy[0]), float(xy[1])))


def source_cross_entropy(
    belief: Belief, source_cell: tuple[int, int], prob_floor: float = PROB_FLOOR
) -> float:
    """``-log max(pi[source_cell], prob_floor)`` in nats (see the module docstring)."""
    i, j = int(source_cell[0]), int(source_cell[1])
    H, W = belief.shape
    if not (0 <= i < H and 0 <= j < W):
        raise InputDataError(f"source cell ({i}, {j}) lies outside the map ({H} x {W})")
    return float(-math.log(max(float(belief.source_probs[i, j]), prob_floor)))


def wind_metrics(belief: Belief, case: Case) -> tuple[float, float]:
    """``(wf_rmse, wf_nll)`` per wind component over the free cells (NaN where unavailable)."""
    _check_same_grid(belief, case)
    if belief.wind_mean is None:
        return NAN, NAN
    free = case.free
    truth = case.wind[:, free].astype(np.float64)  # (2, |F|)
    mean = belief.wind_mean[:, free]
    err = rmse(mean, truth)
    nll = NAN if belief.wind_var is None else gaussian_nll(truth, mean, belief.wind_var[:, free])
    return err, nll


def concentration_metrics(belief: Belief, case: Case) -> tuple[float, float, float, float]:
    """``(cf_rmse, cf_nll, cf_rmse_ppm, cf_nll_ppm)`` over the free cells (NaN where unavailable).

    Log space against ``log(1 + c)``; ppm space against ``c`` with the belief's
    own prediction in its native space (module docstring): ``"log"`` beliefs by
    their median map and exact lognormal density, ``"ppm"`` beliefs by their
    mean and Gaussian (:attr:`Belief.conc_mean_ppm`, :attr:`Belief.conc_var_ppm`).
    """
    _check_same_grid(belief, case)
    if belief.log_conc_mean is None:
        return NAN, NAN, NAN, NAN
    free = case.free
    c = np.maximum(case.concentration[free].astype(np.float64), 0.0)
    logc = np.log1p(c)
    m = belief.log_conc_mean[free]
    cf_rmse = rmse(m, logc)
    cf_nll = NAN if belief.log_conc_var is None else gaussian_nll(logc, m, belief.log_conc_var[free])
    point = belief.conc_point_ppm
    assert point is not None
    cf_rmse_ppm = rmse(point[free], c)
    if belief.log_conc_var is None:
        cf_nll_ppm = NAN
    elif belief.conc_space == "ppm":
        mean_ppm, var_ppm = belief.conc_mean_ppm, belief.conc_var_ppm
        assert mean_ppm is not None and var_ppm is not None
        cf_nll_ppm = gaussian_nll(c, mean_ppm[free], var_ppm[free])
    else:
        cf_nll_ppm = lognormal_nll_ppm(c, m, belief.log_conc_var[free])
    return cf_rmse, cf_nll, cf_rmse_ppm, cf_nll_ppm


@dataclass(frozen=True)
class EstimateMetrics:
    """All metrics of one estimate (units in the field names; NaN = not provided by the method).

    Attributes:
        sl_error_m: source-localization error of the probability-weighted mean, m.
        map_error_m: distance from the most probable cell's centre to the true source, m.
        ce: cross-entropy of the source posterior at the true cell, nats.
        entropy: entropy of the source posterior, nats.
        normalized_entropy: ``entropy / log(number of free cells)`` (the paper's eta test).
        wf_rmse, wf_nll: wind RMSE (m/s) and Gaussian NLL per component (nats).
        cf_rmse, cf_nll: log(1 + ppm) concentration RMSE and Gaussian NLL (nats).
        cf_rmse_ppm, cf_nll_ppm: concentration RMSE (ppm) of the belief's point map and NLL of its
            density in ppm (nats; module docstring).
    """

    sl_error_m: float
    map_error_m: float
    ce: float
    entropy: float
    normalized_entropy: float
    wf_rmse: float
    wf_nll: float
    cf_rmse: float
    cf_nll: float
    cf_rmse_ppm: float
    cf_nll_ppm: float

    def to_dict(self) -> dict[str, float]:
        """The metrics by name (floats, NaN where unavailable)."""
        return {k: float(v) for k, v in asdict(self).items()}


#: Names of the :class:`EstimateMetrics` fields, in order.
METRIC_KEYS: tuple[str, ...] = tuple(EstimateMetrics.__dataclass_fields__)


def evaluate_belief(belief: Belief, case: Case, prob_floor: float = PROB_FLOOR) -> EstimateMetrics:
    """Every metric of ``belief`` against the true ``case`` (same map and cell size).

    Raises:
        InputDataError: the belief and the case are on different grids.
    """
    _check_same_grid(belief, case)
    source = (float(case.source[0]), float(case.source[1]))
    i, j = belief.most_likely_cell()
    res = belief.resolution
    map_err = math.hypot((j + 0.5) * res - source[0], (i + 0.5) * res - source[1])
    wf_rmse, wf_nll = wind_metrics(belief, case)
    cf = concentration_metrics(belief, case)
    return EstimateMetrics(
        sl_error_m=source_localization_error(belief, source),
        map_error_m=float(map_err),
        ce=source_cross_entropy(belief, case.source_cell, prob_floor),
        entropy=belief.entropy(),
        normalized_entropy=belief.normalized_entropy(),
        wf_rmse=wf_rmse,
        wf_nll=wf_nll,
        cf_rmse=cf[0],
        cf_nll=cf[1],
        cf_rmse_ppm=cf[2],
        cf_nll_ppm=cf[3],
    )
