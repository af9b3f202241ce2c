"""What an estimate that learned nothing from the readings scores on a bench scenario.

The suites' scores are bounded by these, computed here from each case's own arrays (not with
:mod:`dgse.evaluation.metrics`, so a wrong metric cannot move its bound with it):

* ``sl_error_m``: the uniform source posterior over the free cells, whose probability-weighted
  mean is the free cells' centroid;
* ``ce``: the same posterior at the true cell, ``log |F|``;
* ``wf_rmse_still``: still air, the RMS of the true wind components over the free cells;
* ``cf_rmse_constant``: the best constant ``log(1 + c)``, the field's standard deviation;
* ``wf_nll_constant``, ``cf_nll_constant``: the best single Gaussian for every free cell (the
  field's own mean and variance), ``0.5 (log(2 pi var) + 1)`` per component;
* ``cf_rmse_zero``, ``cf_rmse_ppm_zero``: no gas anywhere, the RMS of ``log(1 + c)`` and of
  ``c`` in ppm.

:func:`uninformed_on_canvas` gives the same for the training losses, on the network's canvas.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from dgse.bench.core import BenchContext
from dgse.world.case import Case


def quick_case_dir(root: Path) -> Path:
    """The directory of the two quick ``test`` scenarios the suites run on."""
    return BenchContext("setup", root, quick=True).scenarios(2, "test")


def quick_cases(root: Path) -> dict[str, Case]:
    """The two quick ``test`` scenarios the suites run on, by case id."""
    return {p.stem: Case.load(p) for p in sorted(quick_case_dir(root).glob("*.npz"))}


def _gaussian_nll(values: np.ndarray) -> float:
    return 0.5 * (math.log(2 * math.pi * float(values.var())) + 1.0)


def uninformed(case: Case) -> dict[str, float]:
    """The scores of the module docstring on ``case``."""
    free = case.free
    i, j = np.nonzero(free)
    centroid = np.array([(j + 0.5).mean(), (i + 0.5).mean()]) * case.resolution
    wind = case.wind[:, free].astype(np.float64)
    ppm = np.maximum(case.concentration[free].astype(np.float64), 0.0)
    logc = np.log1p(ppm)
    return {
        "sl_error_m": float(np.hypot(*(centroid - case.source.astype(np.float64)))),
        "ce": math.log(int(free.sum())),
        "wf_rmse_still": math.sqrt(float((wind**2).mean())),
        "wf_nll_constant": _gaussian_nll(wind),
        "cf_rmse_constant": float(logc.std()),
        "cf_nll_constant": _gaussian_nll(logc),
        "cf_rmse_zero": math.sqrt(float((logc**2).mean())),
        "cf_rmse_ppm_zero": math.sqrt(float((ppm**2).mean())),
    }


def pooled(records: Iterable[Mapping[str, Any]], cases: Mapping[str, Case], key: str) -> float:
    """The mean of ``uninformed(case)[key]`` over the records' cases, one term per record (as the
    suites' means over records weigh them)."""
    cids = [r["case"] for r in records]
    assert cids, "no records to pool"
    return float(np.mean([uninformed(cases[c])[key] for c in cids]))


def uninformed_on_canvas(case: Case) -> dict[str, float]:
    """The training losses' terms on ``case``'s canvas for an estimate that ignores the readings:
    ``source_ce``, the uniform source posterior over the canvas's valid cells (the cells the
    network's softmax runs over), ``log |valid|``; ``conc_nll``, the best single Gaussian for
    every valid cell's ``log(1 + c)``."""
    from dgse.data.rasterize import make_sample
    from dgse.evaluation.evaluate import draw_observations

    targets = make_sample(case, draw_observations(case, 5, 0)).targets  # the same for any readings
    logc = targets.log_concentration[targets.valid].astype(np.float64)
    return {"source_ce": math.log(int(targets.valid.sum())), "conc_nll": _gaussian_nll(logc)}


def below(value: float, bound: float) -> bool:
    """``value`` is finite and under ``bound`` by more than float rounding: the uninformed estimate
    itself scores its bound to within rounding, either side."""
    return math.isfinite(value) and value < bound and not math.isclose(value, bound, rel_tol=1e-9)
