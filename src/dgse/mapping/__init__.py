"""Classical gas distribution mapping (GDM): the baselines of the paper's Sec. V-B comparison.

Methods (each a pure function ``f(occupancy, resolution, observations, **params) -> GasMap``
and an :class:`~dgse.belief.estimator.Estimator` class returning a
:class:`~dgse.belief.belief.Belief`; registry names in brackets):

====================  ==========================  ==========================================
method                module                      what it estimates
====================  ==========================  ==========================================
Kernel DM+V           :mod:`.kernel` (``kdmv``)   gas mean and DM+V variance, isotropic kernel
Kernel DM+V/W         :mod:`.kernel` (``kdmvw``)  same with a wind-stretched kernel per reading
G-GMRF                :mod:`.gmrf` (``ggmrf``)    gas mean and marginal variance of a GMRF
GW-GMRF               :mod:`.gwgmrf` (``gwgmrf``) joint gas + wind GMRF, Gauss-Newton
GaBP+                 :mod:`.gabp` (``gabp``)     the G-GMRF model solved by belief propagation
====================  ==========================  ==========================================

Conventions shared by every method here
---------------------------------------
* Grid of the physics spec: cell ``(i, j)`` has its centre at ``x = (j + 0.5) res``,
  ``y = (i + 0.5) res``; wind ``[u_x, u_y]`` in m/s; gas in ppm.
* Readings (:class:`~dgse.sensing.sensors.Observations`) must lie on free cells of
  the map; an empty set, a reading outside the map or in a wall, or a
  non-finite reading raises :class:`~dgse.errors.InputDataError`.  Negative gas
  readings are clipped to 0 (as :func:`dgse.data.rasterize.rasterize` does).
  Several readings at one cell are separate measurements (each adds its factor
  or kernel).
* Results (:class:`GasMap`) are in ppm on the ``(H, W)`` grid; solid cells hold
  mean 0 and variance 0 (none of these methods has a variable there).
* **Belief representation.**  The :class:`~dgse.belief.belief.Belief` stores a
  Gaussian over ``L = log(1 + c)``.  These methods produce a ppm mean ``m`` and
  variance ``v``; :meth:`GasMap.to_belief` moment-matches a lognormal ``1 + c``
  to them (:func:`ppm_to_log_moments`): ``s2 = log(1 + v / (1 + m)^2)``,
  ``mu = log(1 + m) - s2 / 2``, so ``Belief.conc_mean_ppm`` and
  ``Belief.conc_var_ppm`` give back ``m`` and ``v`` (to rounding).  The mean is
  clipped at 0 ppm first (a concentration is never negative).  A Gaussian NLL
  in ppm computed from ``conc_mean_ppm``/``conc_var_ppm`` is therefore the
  method's own; an NLL computed on ``log_conc_*`` is that of the moment-matched
  lognormal, not of the method.
* ``Belief.info`` carries ``method``, ``seconds``, ``variance_kind`` and
  ``nll_comparable``: False for Kernel DM+V(/W) (the variance is a
  confidence-weighted spread, paper Sec. V-B) and for GaBP+ (loopy-BP
  variances are overconfident, no global probability map); True for the GMRFs.
* **Source posterior.**  None of these methods has a source model; the Belief's
  ``source_probs`` is uniform over the free cells (``info["source_model"] =
  "none"``).  Do not use it for source localization.
* **Parameters** are the published defaults (spec ``baselines.md``) in units of
  the 0.1 m grid; they are used unchanged at other resolutions (no rescaling).
  A tuning file (``benchmarks/results/gdm_tuning.json``, written by
  ``python benchmarks/training.py gdm`` from the validation split) overrides them when
  passed as ``tuning=path`` to an estimator; explicit keyword arguments override
  both (:func:`resolve_params`).

Cost per estimate
-----------------
Measured on a 100 x 100 map (a random training layout, 9 746 free cells,
built-in solver) with 100 random readings (Table I noise), 3 reading sets,
on 2 CPU cores shared with other jobs (load ~8, so +-30 %), Belief
conversion included, numba caches warm:

=============  ============  ===============================================
method         seconds       notes
=============  ============  ===============================================
kdmv           0.04 - 0.07   dense kernel evaluation, 100 x 9 746
kdmvw          0.04 - 0.08
ggmrf          0.08          solve 0.03, Takahashi variance 0.05 (sampling,
                             200 draws: 0.13; blocked N solves: 6 - 14)
gwgmrf         3 - 10        0.4 - 0.5 per Gauss-Newton step, 4 to 15 steps;
                             variance 1.5 - 2 (3N system, 2.4e6 factor entries)
gabp           0.22          ~1e7 messages; wildfire alone reached epsilon
=============  ============  ===============================================

The first call in a fresh environment compiles the numba kernels (a few
seconds; cached on disk afterwards).

Heavy numerics live in the submodules, which are imported lazily
(``dgse.mapping.ggmrf`` etc. resolve on first access).
"""

from __future__ import annotations

import dataclasses
import importlib
import json
import math
import os
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dgse.belief.belief import Belief, log_moments_from_ppm, normalize_source_probs
from dgse.belief.knowledge import KnowledgeUser
from dgse.errors import InputDataError
from dgse.options import check_options
from dgse.sensing.sensors import Observations, check_sensor_cells

__all__ = [
    "TUNING_FORMAT",
    "GasMap",
    "MappingEstimator",
    "MappingInputs",
    "check_inputs",
    "load_tuning",
    "positive",
    "ppm_to_log_moments",
    "resolve_params",
]

#: ``format`` field of a tuning file.
TUNING_FORMAT = "dgse-gdm-tuning"

# lazily resolved public names -> module
_LAZY = {
    "kdmv": "kernel",
    "kdmvw": "kernel",
    "KernelDMV": "kernel",
    "KernelDMVW": "kernel",
    "KernelParams": "kernel",
    "ggmrf": "gmrf",
    "GGMRF": "gmrf",
    "GGMRFParams": "gmrf",
    "diag_of_inverse": "gmrf",
    "selected_inverse_diag": "gmrf",
    "gwgmrf": "gwgmrf",
    "GWGMRF": "gwgmrf",
    "GWGMRFParams": "gwgmrf",
    "gabp": "gabp",
    "GaBPPlus": "gabp",
    "GaBPParams": "gabp",
}


def __getattr__(name: str) -> Any:
    mod = _LAZY.get(name)
    if mod is None:
        raise AttributeError(f"module 'dgse.mapping' has no attribute {name!r}")
    return getattr(importlib.import_module(f"dgse.mapping.{mod}"), name)


# -- inputs --------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class MappingInputs:
    """Validated inputs of a mapping method.

    Attributes:
        free: ``bool (H, W)``, true on free cells.
        resolution: cell size in m.
        cells: ``int64 (n, 2)`` reading cells ``(i, j)``, all free.
        gas: ``float64 (n,)`` gas readings in ppm, clipped at 0.
        wind: ``float64 (n, 2)`` wind readings ``[u_x, u_y]`` in m/s.
    """

    free: np.ndarray
    resolution: float
    cells: np.ndarray
    gas: np.ndarray
    wind: np.ndarray

    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.free.shape[0]), int(self.free.shape[1]))

    @property
    def positions(self) -> np.ndarray:
        """``(n, 2)`` reading positions ``(x, y)`` in m (cell centres)."""
        c = self.cells
        return np.stack([c[:, 1] + 0.5, c[:, 0] + 0.5], axis=1) * self.resolution

    def gas_scale(self, scale: float | None) -> float:
        """``scale`` if given (must be > 0), else the largest reading (1 when all are 0)."""
        if scale is not None:
            s = float(scale)
            if not (s > 0 and math.isfinite(s)):
                raise InputDataError(f"gas_scale must be positive and finite, got {scale}")
            return s
        top = float(self.gas.max())
        return top if top > 0 else 1.0


def check_inputs(occupancy: np.ndarray, resolution: float, observations: Observations) -> MappingInputs:
    """Validate a map and its readings for a mapping method.

    The arguments of every mapping function (:func:`~dgse.mapping.kernel.kdmv`,
    :func:`~dgse.mapping.gmrf.ggmrf`, ...):

    Args:
        occupancy: ``(H, W)`` map, 1 solid, 0 free.
        resolution: cell size in m.
        observations: at least one reading, all on free cells.

    Raises:
        InputDataError: a map that is not 2-D or has no free cell, a bad
            resolution, something that is not :class:`Observations`, no readings,
            a reading outside the map or in a wall, or a non-finite reading.
    """
    occ = np.asarray(occupancy)
    if occ.ndim != 2 or min(occ.shape) < 1:
        raise InputDataError(f"occupancy must be a non-empty 2-D array, got shape {occ.shape}")
    free = occ == 0
    if not free.any():
        raise InputDataError("the map has no free cell")
    res = float(resolution)
    if not (res > 0 and math.isfinite(res)):
        raise InputDataError(f"resolution must be positive and finite, got {resolution}")
    if not isinstance(observations, Observations):
        raise InputDataError(f"observations must be an Observations, got {type(observations).__name__}")
    if len(observations) == 0:
        raise InputDataError("no observations: a gas distribution map needs at least one reading")
    gas = np.asarray(observations.gas, dtype=np.float64)
    wind = np.asarray(observations.wind, dtype=np.float64)
    if not (np.isfinite(gas).all() and np.isfinite(wind).all()):
        raise InputDataError("observations contain non-finite (NaN or infinite) readings")
    cells = check_sensor_cells(occ, observations.cells)
    return MappingInputs(free, res, cells, np.maximum(gas, 0.0), wind)


# -- results -------------------------------------------------------------------------------
#: Mean and variance of ``L = log(1 + c)`` of a lognormal ``1 + c`` with given ppm moments
#: (:func:`~dgse.belief.belief.log_moments_from_ppm`, the belief's own conversion).
ppm_to_log_moments = log_moments_from_ppm


@dataclass(frozen=True, eq=False)
class GasMap:
    """A gas distribution map on the ``(H, W)`` grid.

    Attributes:
        mean_ppm: ``float64 (H, W)`` mean concentration in ppm (0 on solid cells).
        var_ppm: ``float64 (H, W)`` its variance in ppm^2 (what kind: ``info["variance_kind"]``),
            or None.
        wind_mean: ``float64 (2, H, W)`` ``[u_x, u_y]`` in m/s (GW-GMRF only), else None.
        wind_var: ``float64 (2, H, W)`` its variance, or None.
        info: method name, timings, solver statistics.
    """

    mean_ppm: np.ndarray
    var_ppm: np.ndarray | None
    wind_mean: np.ndarray | None = None
    wind_var: np.ndarray | None = None
    info: dict[str, Any] = field(default_factory=dict)

    def to_belief(self, occupancy: np.ndarray, resolution: float) -> Belief:
        """The :class:`Belief`: lognormal moment match of the ppm moments, uniform source posterior."""
        occ = np.asarray(occupancy)
        mu, s2 = ppm_to_log_moments(self.mean_ppm, self.var_ppm)
        probs = normalize_source_probs((occ == 0).astype(np.float64), occ)
        info = dict(self.info)
        info.setdefault("source_model", "none")
        info.setdefault("conc_representation", "ppm moments, lognormal moment match of 1 + c")
        return Belief(
            occupancy=occ,
            resolution=float(resolution),
            source_probs=probs,
            wind_mean=self.wind_mean,
            wind_var=self.wind_var,
            log_conc_mean=mu,
            log_conc_var=s2,
            info=info,
        )


# -- parameters ----------------------------------------------------------------------------
def load_tuning(path: str | os.PathLike[str]) -> dict[str, dict[str, Any]]:
    """The per-method parameter overrides of a tuning file (``{"methods": {name: {param: value}}}``).

    Raises:
        InputDataError: a missing or malformed file.
    """
    p = Path(path)
    try:
        doc = json.loads(p.read_text())
    except FileNotFoundError:
        raise InputDataError(f"{p}: no such tuning file") from None
    except (OSError, json.JSONDecodeError) as e:
        raise InputDataError(f"{p}: cannot read the tuning file: {e}") from None
    if not isinstance(doc, dict) or doc.get("format") != TUNING_FORMAT:
        raise InputDataError(f"{p}: not a GDM tuning file (format must be {TUNING_FORMAT!r})")
    methods = doc.get("methods")
    if not isinstance(methods, dict) or not all(isinstance(v, dict) for v in methods.values()):
        raise InputDataError(f"{p}: 'methods' must map method names to parameter objects")
    return {str(k): dict(v) for k, v in methods.items()}


def resolve_params(
    params_cls: type,
    method: str,
    tuning: str | os.PathLike[str] | Mapping[str, Any] | None,
    overrides: Mapping[str, Any],
) -> Any:
    """``params_cls`` built from its defaults, then ``tuning[method]``, then ``overrides``.

    ``tuning`` is a tuning file path, an already loaded ``{method: {...}}``
    mapping, or None.  Unknown parameter names raise :class:`InputDataError`.
    """
    values: dict[str, Any] = {}
    if tuning is not None:
        table = load_tuning(tuning) if isinstance(tuning, str | os.PathLike) else dict(tuning)
        values.update(table.get(method, {}))
    values.update(overrides)
    values = check_options(method, params_cls, values)
    try:
        return params_cls(**values)
    except (TypeError, ValueError) as e:
        raise InputDataError(f"bad {method} parameters: {e}") from None


def positive(name: str, value: float, *, allow_zero: bool = False) -> float:
    """``float(value)``, checked finite and > 0 (>= 0 with ``allow_zero``)."""
    v = float(value)
    ok = math.isfinite(v) and (v >= 0 if allow_zero else v > 0)
    if not ok:
        raise InputDataError(f"{name} must be {'>= 0' if allow_zero else 'positive'} and finite, got {value}")
    return v


class MappingEstimator(KnowledgeUser):
    """An :class:`~dgse.belief.estimator.Estimator` around a mapping function.

    Subclasses set ``name`` and implement :meth:`map`; :meth:`estimate` times
    it and converts the :class:`GasMap` with :meth:`GasMap.to_belief`.
    """

    name = "gdm"
    #: the method's parameter set (a dataclass), set by the subclass's constructor
    params: Any

    def describe(self) -> dict[str, Any]:
        """The method's name and its parameter set (defaults and tuning file applied)."""
        return {"name": self.name, "params": dataclasses.asdict(self.params)}

    def map(self, occupancy: np.ndarray, resolution: float, observations: Observations) -> GasMap:
        """The gas distribution map (ppm) given the readings."""
        raise NotImplementedError

    def estimate(self, occupancy: np.ndarray, resolution: float, observations: Observations) -> Belief:
        """The :class:`Belief` (see the module docstring for the representation)."""
        t0 = time.perf_counter()
        gm = self.map(occupancy, resolution, observations)
        info = dict(gm.info)
        info["method"] = self.name
        info["n_observations"] = len(observations)
        gm = dataclasses.replace(gm, info=info)
        belief = gm.to_belief(occupancy, resolution)
        belief.info["seconds"] = time.perf_counter() - t0
        return belief
