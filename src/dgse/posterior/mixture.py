r"""Mixing source posteriors over flow hypotheses, and the wind readings' likelihood of a flow.

``p(s | z, w) = sum_h p(h | z, w) p(s | z, h)`` with ``p(h | z, w) ∝ p(w | h) p(z | h)``:
:func:`mix_posteriors` weighs each hypothesis's adjoint evidence
(:mod:`dgse.posterior.adjoint`) by its wind likelihood (:func:`wind_log_likelihood`)
and its gas evidence; :func:`field_error_variance` is the model error added to the
mixture's predicted fields.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from dgse.errors import InputDataError
from dgse.posterior.adjoint import CENSORED_TAIL, AdjointResponseModel, FlowModel, censored_correction

__all__ = [
    "FlowHypothesis",
    "censor_zeros",
    "field_error_variance",
    "fitted_wind_scale",
    "gas_misfit",
    "log_speed_priors",
    "logsumexp",
    "mix_posteriors",
    "predictive_sources",
    "relative_wind_misfit",
    "same_noise_weights",
    "speed_label",
    "standardized_residuals",
    "wind_log_likelihood",
    "with_given",
]


@dataclass(eq=False)
class FlowHypothesis:
    """One flow the readings are explained with.

    Attributes:
        label: what it is (``"v_in 1.7 m/s"``, ``"given wind"``).
        flow: the flow and its factorized transport (adjoint rows cached per sensor cell).
        prior: prior weight (the hypotheses' priors sum to 1).
    """

    label: str
    flow: FlowModel
    prior: float = 1.0


def speed_label(v: float) -> str:
    return f"v_in {v:.3g} m/s"


def log_speed_priors(hyps: list[FlowHypothesis]) -> list[FlowHypothesis]:
    """The hypotheses sorted by inlet speed, with a log-uniform prior over the speed.

    Each speed stands for the stretch of ``log v`` nearer to it than to the others (the
    end points' stretches reach half as far out as their inner neighbour), so adding
    speeds refines the quadrature of one prior instead of piling up weight where they
    were added.
    """
    hs = sorted(hyps, key=lambda h: h.flow.inlet_velocity)
    if len(hs) == 1:
        return [FlowHypothesis(hs[0].label, hs[0].flow, 1.0)]
    x = np.log([h.flow.inlet_velocity for h in hs])
    mid = 0.5 * (x[1:] + x[:-1])
    edges = np.concatenate([[x[0] - (mid[0] - x[0])], mid, [x[-1] + (x[-1] - mid[-1])]])
    width = np.diff(edges)
    width = width / width.sum()
    return [FlowHypothesis(h.label, h.flow, float(w)) for h, w in zip(hs, width, strict=True)]


def with_given(given: FlowHypothesis, prior: float, family: list[FlowHypothesis]) -> list[FlowHypothesis]:
    """The given field's hypothesis (prior ``prior``) first, then ``family`` with the rest of
    the prior in proportion to its own."""
    rest = [FlowHypothesis(h.label, h.flow, (1.0 - prior) * h.prior) for h in family]
    return [FlowHypothesis(given.label, given.flow, prior), *rest]


def logsumexp(x: np.ndarray) -> float:
    top = float(np.max(x))
    return top + math.log(float(np.exp(x - top).sum())) if math.isfinite(top) else top


def mix_posteriors(
    log_evidence: Sequence[np.ndarray],
    log_prior: Sequence[float] | np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """``(p(s | data), p(h | data))`` of a mixture over hypotheses ``h``.

    Args:
        log_evidence: per hypothesis, ``(N,)`` ``log p(data | s, h)`` up to one constant
            shared by all hypotheses.
        log_prior: ``(H,)`` log prior weights of the hypotheses (any data about ``h``
            besides the gas, e.g. the wind readings' log likelihood, added in).

    With one hypothesis holding all the prior weight the result is that
    hypothesis's own posterior.
    """
    L = [np.asarray(x, dtype=np.float64) for x in log_evidence]
    if not L:
        raise InputDataError("no flow hypotheses to mix")
    n = L[0].size
    lp = np.asarray(log_prior, dtype=np.float64)
    if lp.shape != (len(L),):
        raise InputDataError(f"{len(L)} hypotheses but {lp.size} prior weights")
    log_z = np.array([logsumexp(x) - math.log(n) for x in L]) + lp
    hw = np.exp(log_z - logsumexp(log_z))
    post = np.zeros(n)
    for w, x in zip(hw, L, strict=True):
        if w > 0:
            p = np.exp(x - x.max())
            post += w * p / p.sum()
    return post / post.sum(), hw


#: A flow whose wind log likelihood is this many nats below the best flow's gets no gas evidence.
WIND_HOPELESS_NATS = 30.0
#: The two noise models whose posteriors dgse-phys averages (the first's evidence also gives
#: the predictive fields): the proportional noise from the plug-in concentrations, and from
#: each candidate's own (:func:`~dgse.posterior.adjoint.adjoint_log_evidence`).
MIXED_NOISE_WEIGHTS = ("plug-in", "candidate")
#: A hypothesis whose evidence bound is this many nats below the best one's is left at its bound.
HOPELESS_NATS = 10.0
#: The most of its own mass the zeros' correction of a weak hypothesis may leave out (:func:`censor_zeros`).
CENSORED_TAIL_MAX = 0.5


def censor_zeros(
    log_ev: list[np.ndarray],
    log_prior: Sequence[float],
    details: Sequence[dict[str, Any]],
    temp: float,
    tilt: bool = True,
    memos: dict[int, dict[str, Any]] | None = None,
) -> list[np.ndarray]:
    """Add the zero readings' factor to each hypothesis's evidence, skipping hopeless ones.

    The factor is at most ``(1/2)`` per zero, so ``evidence + ceiling`` bounds a hypothesis
    from above; hypotheses are corrected best bound first, and one whose bound lies
    ``HOPELESS_NATS`` below the best corrected hypothesis is left at its bound.  The others
    are corrected to the mixture's precision: a hypothesis whose weight is at most ``w`` of
    the best one's (its bound against the best corrected total) leaves out at most
    ``CENSORED_TAIL / w`` of its own mass (at most :data:`CENSORED_TAIL_MAX`), which is
    ``CENSORED_TAIL`` of the mixture's.

    ``memos``: per hypothesis, the correction's memo of an earlier call with the same noise
    weights (another noise-weight mode's, :func:`~dgse.posterior.adjoint.censored_correction`;
    the caller checks the weights, :func:`same_noise_weights`): the factors computed there are
    reused.
    """
    out = list(log_ev)
    pending = [i for i, d in enumerate(details) if "censor" in d]
    if not pending:
        return out
    ceiling = -math.log(2.0) * int(details[pending[0]]["censored"])

    def total(i: int, x: np.ndarray) -> float:
        return log_prior[i] + logsumexp(x / temp)

    bounds = {i: total(i, log_ev[i] + ceiling) for i in pending}
    best = -math.inf
    for i in sorted(pending, key=lambda i: -bounds[i]):
        if bounds[i] < best - HOPELESS_NATS:
            out[i] = log_ev[i] + ceiling
            continue
        share = math.exp(min(bounds[i] - best, 0.0))
        tail = min(CENSORED_TAIL / share, CENSORED_TAIL_MAX)
        memo = None if memos is None else memos.setdefault(i, {})
        out[i] = log_ev[i] + censored_correction(
            logl=log_ev[i], tilt=tilt, tail=tail, memo=memo, **details[i]["censor"]
        )
        best = max(best, total(i, out[i]))
    return out


def same_noise_weights(modes: Sequence[Sequence[tuple[Any, dict[str, Any]]]]) -> bool:
    """Whether several noise-weight modes' evidence (``(rows, details)`` per hypothesis) leaves the
    zeros' factor of every hypothesis the same noise weights (and so the same factors)."""
    if len(modes) < 2:
        return False
    for per_mode in zip(*modes, strict=True):
        cs = [d["censor"] for _A, d in per_mode if "censor" in d]
        if 0 < len(cs) < len(per_mode):
            return False
        # the factor's inputs that depend on the weights: the zeros' weights and the positive
        # readings' weighted sums
        for c in cs[1:]:
            pairs = [(c["r"], cs[0]["r"]), *zip(c["sums"], cs[0]["sums"], strict=True)]
            if any(np.shape(a) != np.shape(b) or not np.array_equal(a, b) for a, b in pairs):
                return False
    return True


def wind_log_likelihood(
    predicted: np.ndarray, readings: np.ndarray, levels: Sequence[float], floor: float
) -> float:
    """``log p(readings | flow)``: isotropic noise ``sqrt((r |u|)^2 + floor^2)``, averaged over ``r``.

    ``predicted``, ``readings``: ``(m, 2)`` winds at the reading cells, m/s.
    """
    u = np.asarray(predicted, dtype=np.float64)
    w = np.asarray(readings, dtype=np.float64)
    d2 = ((w - u) ** 2).sum(axis=1)
    s2u = (u**2).sum(axis=1)
    vals = []
    for r in levels:
        var = (r * r) * s2u + floor * floor
        vals.append(float((-np.log(2.0 * math.pi * var) - 0.5 * d2 / var).sum()))
    return logsumexp(np.array(vals)) - math.log(len(vals))


def fitted_wind_scale(predicted: np.ndarray, readings: np.ndarray) -> float:
    """The non-negative factor that best fits a flow's winds to the readings (least squares).

    ``predicted``, ``readings``: ``(m, 2)`` winds at the reading cells, m/s.  1 where the flow
    is still at every reading (no factor changes it).  At knowledge ``map`` each proposal is
    solved at one inlet speed and scaled so.
    """
    u = np.asarray(predicted, dtype=np.float64)
    uu = float((u * u).sum())
    if uu <= 0:
        return 1.0
    return max(float((u * np.asarray(readings, dtype=np.float64)).sum()) / uu, 0.0)


def relative_wind_misfit(predicted: np.ndarray, readings: np.ndarray) -> float:
    """How much of the wind readings a flow leaves unexplained: ``sqrt(sum |w - u|^2 / sum |w|^2)``.

    ``predicted``, ``readings``: ``(m, 2)`` winds at the reading cells, m/s.  0: the flow
    reproduces every reading; 1: no better than a still room; inf: the readings are all zero
    and the flow is not.
    """
    u = np.asarray(predicted, dtype=np.float64)
    w = np.asarray(readings, dtype=np.float64)
    num = float(((w - u) ** 2).sum())
    den = float((w**2).sum())
    if den > 0:
        return math.sqrt(num / den)
    return 0.0 if num == 0 else math.inf


def field_error_variance(
    wind_mean: np.ndarray, log_conc_mean: np.ndarray, params: Sequence[float]
) -> tuple[np.ndarray, np.ndarray]:
    """Model-error variances of the predicted fields: ``(wind (H, W) per component, log(1 + c) (H, W))``.

    ``params = (a, b, c, d)``: a wind component errs by ``sqrt((a |u|)^2 + b^2)`` m/s
    (``|u|`` the predicted speed: a relative part, as a flow of the wrong shape misplaces
    jets, and a floor), ``log(1 + c)`` by ``sqrt((c L)^2 + d^2)`` (``L`` its predicted
    value: plumes are misplaced, clean air stays clean).  The spread between flow
    hypotheses leaves this out: with one flow it is zero however wrong the flow is.
    """
    a, b, c, d = (float(v) for v in params)
    speed2 = (np.asarray(wind_mean, dtype=np.float64) ** 2).sum(axis=0)
    L = np.asarray(log_conc_mean, dtype=np.float64)
    return a * a * speed2 + b * b, (c * L) ** 2 + d * d


def standardized_residuals(mean: np.ndarray, readings: np.ndarray, model: AdjointResponseModel) -> np.ndarray:
    """Gas ``readings`` (ppm) minus their predicted ``mean``, over ``model``'s noise
    (``model.reading_sigma``)."""
    mu = np.asarray(mean, dtype=np.float64)
    sig = np.maximum(model.reading_sigma(mu), 1e-12)
    return (np.asarray(readings, dtype=np.float64) - mu) / sig


def gas_misfit(mean: np.ndarray, readings: np.ndarray, model: AdjointResponseModel) -> float:
    """Mean squared standardized residual of gas ``readings`` (ppm) about their predicted
    ``mean`` under ``model``'s noise (:func:`standardized_residuals`): about 1 where the
    physics and the noise model explain the readings, more where they do not."""
    return float(np.mean(standardized_residuals(mean, readings, model) ** 2))


def predictive_sources(probs: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Up to ``k`` source cells (mesh indices) and weights that stand for the posterior ``probs``.

    Systematic sampling, deterministic: the quantiles ``(i + 1/2) / k`` of the
    posterior's cumulative sum in cell order; a cell drawn several times gets that
    many shares.  Every part of the posterior that holds ``1/k`` of the mass is
    represented, however flat it is, so the predictive's variance is the whole
    posterior's (the ``k`` most probable cells alone would all sit at the mode and
    hide a broad second region the planner should go and look at).
    """
    p = np.asarray(probs, dtype=np.float64)
    k = max(1, int(k))
    cdf = np.cumsum(p)
    picks = np.searchsorted(cdf, (np.arange(k) + 0.5) / k * cdf[-1])
    idx, counts = np.unique(np.minimum(picks, p.size - 1), return_counts=True)
    return idx, counts / counts.sum()
