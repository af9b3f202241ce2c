r"""The predictive distribution of a gas reading the robot might take.

Every belief can say what a reading at a cell ``x`` would look like before it is taken:
``p(z at x | readings so far)``.  Both kinds of estimator answer it in one form, a
:class:`ReadingMixture`: ``K`` components with weights ``w_k`` (the same at every cell),
each a Gaussian reading ``N(mu_k(x), sigma_k(x)^2)`` clipped at 0 as the sensor clips it
(:func:`dgse.sensing.noise.gas_reading`: a point mass ``Phi(-mu / sigma)`` at 0 and the
Gaussian density above it):

``p(z | x) = sum_k w_k [Phi(-mu_k / sigma_k) delta(z) + 1{z > 0} N(z; mu_k, sigma_k^2)]``

* a physics posterior (``dgse-phys``, :class:`dgse.posterior.predictive.HypothesisPredictive`):
  one component per flow hypothesis and source cell, its mean the forward field of that
  source at the posterior's release rate, its spread the noise model of the likelihood;
  each component names its source cell (:attr:`ReadingMixture.sources`), so a planner can
  ask how much a reading would tell about the source;
* any belief with a log-concentration mean and variance (DGSE-S: the moment-matched
  mixture of its Monte Carlo samples, :func:`lognormal_predictive`): Gauss-Hermite nodes
  of ``log(1 + c)`` at each cell, with Table I noise; its components name no source (the
  network predicts the field, not the field of each source), so what a reading would tell
  is about the concentration there.

A belief carries the first kind in :attr:`~dgse.belief.belief.Belief.predictive`;
:meth:`~dgse.belief.belief.Belief.reading_predictive` answers either.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
from scipy import special

from dgse.errors import InputDataError

__all__ = [
    "TABLE_I_ALPHA",
    "TABLE_I_SIGMA_FRACTION",
    "ReadingMixture",
    "ReadingPredictive",
    "censored_moments",
    "lognormal_predictive",
]

#: Table I's mean proportional gas noise ``alpha_g`` (``U[0, 1]``): the noise a belief that
#: states none is read with.
TABLE_I_ALPHA = 0.5
#: Table I's mean noise floor as a share of the mean concentration (``U[0, 0.5]``).
TABLE_I_SIGMA_FRACTION = 0.25
#: Smallest noise spread, ppm (a component with none would make a reading's density infinite).
MIN_SIGMA = 1e-9


@dataclass(frozen=True, eq=False)
class ReadingMixture:
    """The predictive of one gas reading at each of ``C`` cells (module docstring).

    Attributes:
        weights: ``(K,)`` component weights, >= 0, summing to 1.
        mean: ``(C, K)`` each component's noise-free reading, ppm (>= 0).
        sigma: ``(C, K)`` each component's noise standard deviation, ppm (> 0).
        sources: ``(K,)`` the flat map index (row-major) of each component's source cell, or
            None where the components name no source.
    """

    weights: np.ndarray
    mean: np.ndarray
    sigma: np.ndarray
    sources: np.ndarray | None = None

    def __post_init__(self) -> None:
        w = np.asarray(self.weights, dtype=np.float64).reshape(-1)
        mu = np.atleast_2d(np.asarray(self.mean, dtype=np.float64))
        sd = np.broadcast_to(np.asarray(self.sigma, dtype=np.float64), mu.shape)
        if mu.shape[1] != w.size or w.size == 0:
            raise InputDataError(f"reading means {mu.shape} do not match {w.size} component weights")
        if (w < 0).any() or not abs(float(w.sum()) - 1.0) < 1e-6:
            raise InputDataError("component weights must be >= 0 and sum to 1")
        if not (np.isfinite(mu).all() and np.isfinite(sd).all()):
            raise InputDataError("reading means and spreads must be finite")
        object.__setattr__(self, "weights", w)
        object.__setattr__(self, "mean", np.maximum(mu, 0.0))
        object.__setattr__(self, "sigma", np.maximum(sd, MIN_SIGMA))
        if self.sources is not None:
            s = np.asarray(self.sources, dtype=np.int64).reshape(-1)
            if s.size != w.size:
                raise InputDataError(f"{s.size} component sources for {w.size} components")
            object.__setattr__(self, "sources", s)

    @property
    def n_cells(self) -> int:
        """``C``, the cells it predicts at."""
        return int(self.mean.shape[0])

    def zero_probability(self) -> np.ndarray:
        """``(C,)`` the probability that the reading is 0 (clipped)."""
        return special.ndtr(-self.mean / self.sigma) @ self.weights

    def moments(self) -> tuple[np.ndarray, np.ndarray]:
        """``(mean, variance)`` of the reading, ``(C,)`` each, ppm and ppm^2 (exact, clipping included)."""
        m1, m2 = censored_moments(self.mean, self.sigma)
        mean = m1 @ self.weights
        return mean, np.maximum(m2 @ self.weights - mean**2, 0.0)

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``(C, n)`` readings drawn from the predictive (a component, then its noise, clipped)."""
        k = rng.choice(self.weights.size, size=(self.n_cells, int(n)), p=self.weights)
        rows = np.arange(self.n_cells)[:, None]
        z = self.mean[rows, k] + self.sigma[rows, k] * rng.standard_normal(k.shape)
        return np.maximum(z, 0.0)

    def bin_probabilities(self, n_bins: int = 24, spread: float = 3.0) -> np.ndarray:
        """``(C, n_bins + 1, K)``: the probability of each reading bin given each component.

        Bin 0 is the reading 0 (the clipped mass, exactly); bins ``1 .. n_bins`` split
        ``(0, top]`` evenly, ``top`` the largest ``mean + spread * sigma`` over the cell's
        components, the last bin reaching to infinity.
        """
        B = max(int(n_bins), 1)
        top = np.max(self.mean + spread * self.sigma, axis=1)  # (C,)
        frac = np.arange(1, B) / B
        inner = top[:, None] * frac[None, :]
        C = self.n_cells
        edges = np.concatenate([np.zeros((C, 1)), inner, np.full((C, 1), np.inf)], axis=1)  # (C, B+1)
        cdf = special.ndtr((edges[:, :, None] - self.mean[:, None, :]) / self.sigma[:, None, :])
        P = np.diff(np.concatenate([np.zeros((C, 1, self.weights.size)), cdf], axis=1), axis=1)
        return np.clip(P, 0.0, 1.0)


def censored_moments(mean: np.ndarray, sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(E[max(X, 0)], E[max(X, 0)^2])`` of ``X ~ N(mean, sigma^2)``, elementwise."""
    mu = np.asarray(mean, dtype=np.float64)
    s = np.maximum(np.asarray(sigma, dtype=np.float64), MIN_SIGMA)
    a = mu / s
    Phi, phi = special.ndtr(a), np.exp(-0.5 * a * a) / math.sqrt(2.0 * math.pi)
    return mu * Phi + s * phi, (mu * mu + s * s) * Phi + mu * s * phi


@runtime_checkable
class ReadingPredictive(Protocol):
    """What a belief that predicts readings carries: the predictive at any cells."""

    def at(self, cells: np.ndarray) -> ReadingMixture:
        """The predictive of a reading at each of ``cells`` (``(C, 2)`` map cells ``(i, j)``)."""
        ...


def lognormal_predictive(
    log_conc_mean: np.ndarray,
    log_conc_var: np.ndarray,
    cells: np.ndarray,
    *,
    noise_floor_ppm: float | None = None,
    alpha: float = TABLE_I_ALPHA,
    nodes: int = 8,
    free: np.ndarray | None = None,
) -> ReadingMixture:
    """The predictive of a reading from a Gaussian over ``L = log(1 + c)`` at each cell.

    ``nodes`` Gauss-Hermite nodes of ``L ~ N(m, v)`` at each cell stand for the
    concentration (the components, the same weights at every cell), each with Table I's
    noise ``sigma = alpha c + sigma_env``; ``sigma_env`` is ``noise_floor_ppm``, or where
    that is None :data:`TABLE_I_SIGMA_FRACTION` of the mean predicted concentration over the
    ``free`` cells (all cells when None), Table I's mean.

    Args:
        log_conc_mean, log_conc_var: ``(H, W)`` the belief's mean and variance of ``L``.
        cells: ``(C, 2)`` cells ``(i, j)``.
    """
    m = np.asarray(log_conc_mean, dtype=np.float64)
    v = np.maximum(np.asarray(log_conc_var, dtype=np.float64), 0.0)
    c = np.asarray(cells, dtype=np.int64).reshape(-1, 2)
    x, w = special.roots_hermite(max(int(nodes), 1))
    w = w / w.sum()
    L = m[c[:, 0], c[:, 1], None] + np.sqrt(2.0 * v[c[:, 0], c[:, 1], None]) * x[None, :]
    conc = np.maximum(np.expm1(L), 0.0)  # (C, K)
    if noise_floor_ppm is None:
        mean_field = np.expm1(m + 0.5 * v)
        sel = mean_field if free is None else mean_field[np.asarray(free, dtype=bool)]
        noise_floor_ppm = TABLE_I_SIGMA_FRACTION * float(np.mean(np.maximum(sel, 0.0))) if sel.size else 0.0
    return ReadingMixture(w, conc, alpha * conc + float(noise_floor_ppm))
