"""The belief every estimator returns (DGSE variants and classical baselines alike).

A :class:`Belief` lives on the map grid ``(H, W)`` (not on a network canvas;
spec section 1: cell ``(i, j)`` has its centre at ``x = (j + 0.5) * res``,
``y = (i + 0.5) * res``).  It holds

* the source posterior ``source_probs`` (``(H, W)``, sums to 1 over the free
  cells, exactly 0 on solid cells);
* optionally a Gaussian wind field (mean and variance per component);
* optionally a Gaussian over the log-concentration ``L = log(1 + c)``
  (``c`` in ppm) per cell, the networks' scale.  Then ``1 + c`` is lognormal
  and its moments give the concentration in ppm:

  ``E[c] = exp(m + v / 2) - 1``,  ``Var[c] = (exp(v) - 1) * exp(2 m + v)``

  with ``m``, ``v`` the mean and variance of ``L`` (``v = 0`` when a method
  gives no variance: then ``E[c] = exp(m) - 1`` and no variance).

Methods without a wind or concentration estimate leave those fields None.

Native space of the concentration (:attr:`Belief.conc_space`)
-------------------------------------------------------------
Two kinds of methods fill ``log_conc_*``:

* ``"log"``: the Gaussian over ``L`` *is* the method's prediction (the DGSE
  networks are trained with a Gaussian NLL on ``L``).  Its ppm point map
  (:attr:`Belief.conc_point_ppm`) is the median ``exp(m) - 1``, the
  back-transformed mean of ``L``: the lognormal mean ``exp(m + v/2) - 1``
  grows like ``exp(v/2)`` and explodes where the network is unsure (log-space
  variances of 10 to 20 occur near unseen plumes: a factor of 150 to 22 000),
  so it is not a usable map.  Its density in ppm is the exact change of
  variables ``p(c) = N(log(1 + c); m, v) / (1 + c)`` (no moment matching).
* ``"ppm"``: the method predicts a ppm mean and variance (the GDM baselines,
  whose ``log_conc_*`` is a lognormal moment match of them,
  :func:`dgse.mapping.ppm_to_log_moments`).  Its point map is the mean
  :attr:`Belief.conc_mean_ppm` (its own mean, given back exactly) and its
  density is its own Gaussian ``N(c; mean, var)``.

``info["conc_space"]`` (``"log"`` or ``"ppm"``) says which; without it a
belief whose ``info["conc_representation"]`` starts with ``"ppm"`` (what
:meth:`dgse.mapping.GasMap.to_belief` writes) is ``"ppm"``, every other one
``"log"``.  :func:`dgse.evaluation.metrics.concentration_metrics` scores
``cf_rmse_ppm`` and ``cf_nll_ppm`` this way, so both are the methods' own
predictions and densities in ppm and comparable across the two kinds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dgse.belief.predictive import ReadingMixture, ReadingPredictive, lognormal_predictive
from dgse.errors import InputDataError
from dgse.world.grid import Grid

__all__ = [
    "CONC_SPACES",
    "Belief",
    "log_moments_from_ppm",
    "normalize_source_probs",
    "probs_from_log",
    "uniform_probs",
]

#: Tolerance on ``sum(source_probs) == 1``.
PROB_TOL = 1e-6
#: The native spaces of a concentration prediction (module docstring).
CONC_SPACES = ("log", "ppm")


def normalize_source_probs(probs: np.ndarray, occupancy: np.ndarray) -> np.ndarray:
    """``probs`` (``(H, W)``, >= 0) set to 0 on solid cells and rescaled to sum 1 over free cells.

    Raises:
        InputDataError: on a shape mismatch, negative or non-finite values, or
            no mass on any free cell.
    """
    p = np.array(probs, dtype=np.float64)
    occ = np.asarray(occupancy)
    if p.shape != occ.shape:
        raise InputDataError(f"source probabilities {p.shape} do not match the map {occ.shape}")
    if not np.isfinite(p).all() or (p < 0).any():
        raise InputDataError("source probabilities must be finite and >= 0")
    p[occ != 0] = 0.0
    total = p.sum()
    if not total > 0:
        raise InputDataError("source probabilities have no mass on a free cell")
    return p / total


def _field(
    value: np.ndarray | None, shape: tuple[int, ...], name: str, nonneg: bool = False
) -> np.ndarray | None:
    if value is None:
        return None
    a = np.asarray(value, dtype=np.float64)
    if a.shape != shape:
        raise InputDataError(f"{name} has shape {a.shape}, expected {shape}")
    if not np.isfinite(a).all():
        raise InputDataError(f"{name} has non-finite values")
    if nonneg and (a < 0).any():
        raise InputDataError(f"{name} has negative values")
    return a


@dataclass(frozen=True, eq=False)
class Belief:
    """An estimator's belief about the source (and the fields) on the map grid.

    Attributes:
        occupancy: ``uint8 (H, W)`` map, 1 solid, 0 free.
        resolution: cell size in m.
        source_probs: ``float64 (H, W)`` source posterior: >= 0, 0 on solid
            cells, sums to 1 (build it with :func:`normalize_source_probs`).
        wind_mean: ``float64 (2, H, W)`` ``[u_x, u_y]`` in m/s, or None.
        wind_var: ``float64 (2, H, W)`` its variance, or None.
        log_conc_mean: ``float64 (H, W)`` mean of ``log(1 + c)``, or None.
        log_conc_var: ``float64 (H, W)`` its variance, or None.
        wind_var_reducible, log_conc_var_reducible: the part of ``wind_var`` /
            ``log_conc_var`` that readings can reduce (the spread between an
            estimator's hypotheses), when the variance also holds a model-error part
            that more readings do not shrink; None: all of it.  Planners that go where
            a reading teaches most use this part; scores and plots use the whole.
        info: bookkeeping, at least ``method`` (name) and ``seconds`` (time to estimate).
        predictive: the estimator's own predictive of a gas reading at any cell, whose
            components name their source cells (:mod:`dgse.belief.predictive`), or None;
            :meth:`reading_predictive` answers without it from the concentration's moments.
    """

    occupancy: np.ndarray
    resolution: float
    source_probs: np.ndarray
    wind_mean: np.ndarray | None = None
    wind_var: np.ndarray | None = None
    log_conc_mean: np.ndarray | None = None
    log_conc_var: np.ndarray | None = None
    info: dict[str, Any] = field(default_factory=dict)
    wind_var_reducible: np.ndarray | None = None
    log_conc_var_reducible: np.ndarray | None = None
    predictive: ReadingPredictive | None = None

    def __post_init__(self) -> None:
        occ = np.asarray(self.occupancy)
        if occ.ndim != 2 or min(occ.shape) < 1:
            raise InputDataError(f"occupancy must be a non-empty 2-D array, got shape {occ.shape}")
        occ = (occ != 0).astype(np.uint8)
        if not (occ == 0).any():
            raise InputDataError("the map has no free cell")
        res = float(self.resolution)
        if not (res > 0 and math.isfinite(res)):
            raise InputDataError(f"resolution must be positive, got {self.resolution}")
        H, W = occ.shape
        p = _field(self.source_probs, (H, W), "source_probs", nonneg=True)
        assert p is not None
        if (p[occ != 0] != 0).any():
            raise InputDataError("source_probs must be 0 on solid cells (use normalize_source_probs)")
        if abs(p.sum() - 1.0) > PROB_TOL:
            raise InputDataError(f"source_probs sum to {p.sum():.9g}, not 1 (use normalize_source_probs)")
        object.__setattr__(self, "occupancy", occ)
        object.__setattr__(self, "resolution", res)
        object.__setattr__(self, "source_probs", p)
        object.__setattr__(self, "wind_mean", _field(self.wind_mean, (2, H, W), "wind_mean"))
        object.__setattr__(self, "wind_var", _field(self.wind_var, (2, H, W), "wind_var", nonneg=True))
        object.__setattr__(self, "log_conc_mean", _field(self.log_conc_mean, (H, W), "log_conc_mean"))
        object.__setattr__(
            self, "log_conc_var", _field(self.log_conc_var, (H, W), "log_conc_var", nonneg=True)
        )
        for name, total, shape in (
            ("wind_var", self.wind_var, (2, H, W)),
            ("log_conc_var", self.log_conc_var, (H, W)),
        ):
            part = _field(getattr(self, name + "_reducible"), shape, name + "_reducible", nonneg=True)
            if part is not None and total is None:
                raise InputDataError(f"{name}_reducible given without {name}")
            if part is not None and (part > getattr(self, name) * (1 + 1e-9) + 1e-300).any():
                raise InputDataError(f"{name}_reducible exceeds {name}")
            object.__setattr__(self, name + "_reducible", part)
        if self.wind_var is not None and self.wind_mean is None:
            raise InputDataError("wind_var given without wind_mean")
        if self.log_conc_var is not None and self.log_conc_mean is None:
            raise InputDataError("log_conc_var given without log_conc_mean")
        info = dict(self.info)
        info.setdefault("method", "unknown")
        info.setdefault("seconds", float("nan"))
        space = info.get("conc_space")
        if space is not None and space not in CONC_SPACES:
            raise InputDataError(f"info['conc_space'] must be one of {CONC_SPACES}, got {space!r}")
        object.__setattr__(self, "info", info)
        if self.predictive is not None and not isinstance(self.predictive, ReadingPredictive):
            raise InputDataError(f"predictive must be a ReadingPredictive, got {self.predictive!r}")

    # -- geometry ------------------------------------------------------------------------
    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)`` of the map."""
        return (int(self.occupancy.shape[0]), int(self.occupancy.shape[1]))

    @property
    def grid(self) -> Grid:
        """The map's :class:`~dgse.world.grid.Grid`."""
        return Grid(self.shape, self.resolution)

    @property
    def free(self) -> np.ndarray:
        """``bool (H, W)``: the candidate source cells (free cells)."""
        return self.occupancy == 0

    @property
    def method(self) -> str:
        """The estimator's name (``info["method"]``)."""
        return str(self.info["method"])

    @property
    def wind_var_to_explore(self) -> np.ndarray | None:
        """``(2, H, W)`` the wind variance readings can reduce (:attr:`wind_var_reducible`, else all)."""
        return self.wind_var if self.wind_var_reducible is None else self.wind_var_reducible

    @property
    def log_conc_var_to_explore(self) -> np.ndarray | None:
        """``(H, W)`` the log-concentration variance readings can reduce (as :attr:`wind_var_to_explore`)."""
        return self.log_conc_var if self.log_conc_var_reducible is None else self.log_conc_var_reducible

    # -- concentration in ppm ----------------------------------------------------------
    @property
    def conc_mean_ppm(self) -> np.ndarray | None:
        """``(H, W)`` mean concentration in ppm: ``exp(m + v/2) - 1`` (lognormal ``1 + c``), or None."""
        if self.log_conc_mean is None:
            return None
        v = 0.0 if self.log_conc_var is None else self.log_conc_var
        return np.expm1(self.log_conc_mean + 0.5 * v)

    @property
    def conc_space(self) -> str:
        """``"log"`` or ``"ppm"``: where the concentration prediction is native (module docstring)."""
        space = self.info.get("conc_space")
        if space is not None:
            return str(space)
        rep = self.info.get("conc_representation")
        return "ppm" if isinstance(rep, str) and rep.startswith("ppm") else "log"

    @property
    def conc_median_ppm(self) -> np.ndarray | None:
        """``(H, W)`` median concentration in ppm, ``exp(m) - 1`` (the back-transformed mean of ``L``)."""
        if self.log_conc_mean is None:
            return None
        return np.expm1(self.log_conc_mean)

    @property
    def conc_point_ppm(self) -> np.ndarray | None:
        """``(H, W)`` ppm map to plot and score: the median of ``"log"``, the mean of ``"ppm"`` beliefs."""
        return self.conc_mean_ppm if self.conc_space == "ppm" else self.conc_median_ppm

    def conc_interval_ppm(self, z: float = 1.0) -> tuple[np.ndarray, np.ndarray] | None:
        """``(lower, upper)`` ppm maps of the central interval of ``+-z`` standard deviations.

        ``"log"`` beliefs: ``exp(m +- z sqrt(v)) - 1`` (the quantiles of the
        lognormal); ``"ppm"`` beliefs: ``mean +- z sqrt(var)``.  None without a
        variance.  Half its width is a spread in ppm that stays finite where the
        lognormal standard deviation explodes (for a Gaussian it is ``z`` sigma).
        """
        if self.log_conc_mean is None or self.log_conc_var is None:
            return None
        if self.conc_space == "ppm":
            mean, var = self.conc_mean_ppm, self.conc_var_ppm
            assert mean is not None and var is not None
            s = z * np.sqrt(var)
            return mean - s, mean + s
        s = z * np.sqrt(self.log_conc_var)
        return np.expm1(self.log_conc_mean - s), np.expm1(self.log_conc_mean + s)

    @property
    def conc_var_ppm(self) -> np.ndarray | None:
        """``(H, W)`` concentration variance (ppm^2) ``(exp(v) - 1) exp(2m + v)``; None without a variance."""
        if self.log_conc_mean is None or self.log_conc_var is None:
            return None
        m, v = self.log_conc_mean, self.log_conc_var
        return np.expm1(v) * np.exp(2.0 * m + v)

    # -- readings ----------------------------------------------------------------------
    def reading_predictive(self, cells: np.ndarray) -> ReadingMixture | None:
        """The predictive of a gas reading at each of ``cells`` (``(C, 2)``): the estimator's
        own (:attr:`predictive`), else the lognormal of :attr:`log_conc_mean` and
        :attr:`log_conc_var` with the belief's stated noise floor (``info["noise_floor_ppm"]``,
        else Table I's mean, :func:`~dgse.belief.predictive.lognormal_predictive`); None for a
        belief with neither."""
        c = np.asarray(cells, dtype=np.int64).reshape(-1, 2)
        if self.predictive is not None:
            return self.predictive.at(c)
        if self.log_conc_mean is None:
            return None
        var = np.zeros(self.shape) if self.log_conc_var is None else self.log_conc_var
        floor = self.info.get("noise_floor_ppm")
        floor = float(floor) if isinstance(floor, int | float) and math.isfinite(floor) else None
        return lognormal_predictive(self.log_conc_mean, var, c, noise_floor_ppm=floor, free=self.free)

    # -- source ------------------------------------------------------------------------
    def source_estimate(self) -> tuple[float, float]:
        """Probability-weighted mean source position ``(x, y)`` in m (paper Sec. III-D, ``s_hat``)."""
        H, W = self.shape
        x = (np.arange(W) + 0.5) * self.resolution
        y = (np.arange(H) + 0.5) * self.resolution
        p = self.source_probs
        return float(p.sum(axis=0) @ x), float(p.sum(axis=1) @ y)

    def source_variance(self) -> float:
        """``var x + var y`` of the source posterior, m^2 (its spread around :meth:`source_estimate`)."""
        H, W = self.shape
        x = (np.arange(W) + 0.5) * self.resolution
        y = (np.arange(H) + 0.5) * self.resolution
        px, py = self.source_probs.sum(axis=0), self.source_probs.sum(axis=1)
        mx, my = float(px @ x), float(py @ y)
        return max(float(px @ (x - mx) ** 2) + float(py @ (y - my) ** 2), 0.0)

    def most_likely_cell(self) -> tuple[int, int]:
        """``(i, j)`` of the most probable source cell (first one on ties)."""
        i, j = np.unravel_index(int(np.argmax(self.source_probs)), self.shape)
        return int(i), int(j)

    def localization_error(self, source_xy: tuple[float, float]) -> float:
        """Distance (m) from :meth:`source_estimate` to the true source ``(x, y)`` (spec section 6)."""
        x, y = self.source_estimate()
        return float(math.hypot(x - float(source_xy[0]), y - float(source_xy[1])))

    def entropy(self) -> float:
        """Shannon entropy of the source posterior in nats."""
        p = self.source_probs[self.source_probs > 0]
        return float(-(p * np.log(p)).sum())

    @property
    def n_candidates(self) -> int:
        """Number of candidate (free) cells ``N``."""
        return int(self.free.sum())

    @property
    def max_entropy(self) -> float:
        """``log N``: the entropy of the uniform posterior over the free cells."""
        return math.log(self.n_candidates)

    def normalized_entropy(self) -> float:
        """``entropy() / max_entropy`` in [0, 1] (0 for a single candidate cell); the paper's ``eta`` test."""
        m = self.max_entropy
        return self.entropy() / m if m > 0 else 0.0


def uniform_probs(occupancy: np.ndarray) -> np.ndarray:
    """The uniform posterior over the free cells, ``float64 (H, W)``."""
    occ = np.asarray(occupancy)
    return normalize_source_probs((occ == 0).astype(np.float64), occ)


def probs_from_log(log_p: np.ndarray, free: np.ndarray) -> np.ndarray:
    """``exp(log_p - max)`` normalized over ``free`` cells (``-inf`` allowed), 0 elsewhere."""
    lp = np.where(free, np.asarray(log_p, dtype=np.float64), -np.inf)
    top = lp.max()
    if not np.isfinite(top):
        raise InputDataError("the log posterior has no finite value on a free cell")
    p = np.exp(lp - top)
    return p / p.sum()


def log_moments_from_ppm(
    mean_ppm: np.ndarray, var_ppm: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray | None]:
    """Lognormal moment match of ``1 + c``: ppm mean/variance -> mean/variance of ``log(1 + c)``.

    Returns ``(mu, s2)``: ``s2 = log(1 + v / (1 + m)^2)``, ``mu = log(1 + m) - s2 / 2``
    (the mean is clipped at 0 first; ``s2`` is None when ``var_ppm`` is), the exact
    inverse of :attr:`Belief.conc_mean_ppm` / :attr:`Belief.conc_var_ppm`.
    """
    m = np.maximum(np.asarray(mean_ppm, dtype=np.float64), 0.0)
    if var_ppm is None:
        return np.log1p(m), None
    v = np.maximum(np.asarray(var_ppm, dtype=np.float64), 0.0)
    s2 = np.log1p(v / (1.0 + m) ** 2)
    return np.log1p(m) - 0.5 * s2, s2
