"""Estimator evaluation on solved cases from random sparse observations (paper Sec. V-A to V-C).

:func:`evaluate` runs one estimator (any name of the registry,
:func:`dgse.estimators.get_estimator`, or an estimator object) on every case
of a set, for several observation counts and ``trials`` random sensor
configurations each, and scores every estimate with
:func:`dgse.evaluation.metrics.evaluate_belief`.

Cases: a directory of case files (``*.npz``, sorted by name), one case file,
a dataset store (``.h5``, one split, ``test`` by default; its stored fixed
configurations are not used: the observation counts here are explicit), a
:class:`~dgse.data.store.DatasetStore`, a :class:`~dgse.world.case.Case` or
a sequence of cases.  Each case has an id: the file stem, ``<layout>_src<k>``
in a store, else ``case.name`` (``#2``, ``#3``, ... appended to repeats).

Observations (:func:`draw_observations`): ``n`` distinct free cells drawn
uniformly, readings with Table I noise (:func:`dgse.sensing.sensors.random_observations`:
noise parameters drawn per configuration, then cells, then readings).  For a
case with ``frames`` (a time-varying, e.g. GADEN, case) each sensor reads
its gas value from the frame at an independent uniform random time in
``[0, T * frame_dt)`` (:func:`dgse.sensing.sensors.measure`); the wind is the
steady field.  The random stream is seeded from ``(seed, case id, n, trial)``
only (``numpy.random.SeedSequence``), so the same ``(case, n, trial)``
gets the same observations whatever the method, the other cases or counts in
the run, and the order of the loops: methods are compared on identical
readings.  ``dgse estimate CASE --observations N --seed S`` draws the
observations of trial 0.

Estimators with a ``seed`` attribute (the DGSE estimators, whose DGSE-S
draws Monte Carlo samples) get a per-estimate seed derived from the same
``(seed, case id, n, trial)`` (:func:`estimator_seed`) unless
``estimator_kwargs`` sets ``seed``, so a run is reproducible; an estimator
object's own ``seed`` is restored afterwards.  Time per estimate: ``time.perf_counter`` around
``estimator.estimate`` only (not the observation draws, not the metrics).

Result (:func:`evaluate` returns it; :func:`write_json` writes it), JSON-ready
(metrics a method does not provide are ``None``, ``null`` in the file)::

    {
      "format": "dgse-evaluation", "format_version": 1,
      "method": "dgse-s", "estimator": {...}, "estimator_kwargs": {...},
      "cases_source": "...", "split": "test" | null,
      "observation_counts": [50, 100], "trials": 20, "seed": 0,
      "n_cases": 5, "cases": ["env1_src0", ...],
      "protocol": {...}, "metrics": {name: description},
      "created": "...", "dgse_version": "...", "seconds_total": 12.3,
      "per_case": [
        {"case": "env1_src0", "n_obs": 50, "trial": 0, "seconds": 0.41,
         "sl_error_m": 0.52, "map_error_m": ..., "ce": 4.1, "entropy": ...,
         "normalized_entropy": ..., "wf_rmse": ..., "wf_nll": ..., "cf_rmse": ...,
         "cf_nll": ..., "cf_rmse_ppm": ..., "cf_nll_ppm": ...,
         "source_estimate_xy": [x, y], "true_source_xy": [x, y]},
        ...
      ],
      "aggregate": {"50": {"n_estimates": 100,
                           "sl_error_m_mean": ..., "sl_error_m_median": ...,
                           "sl_error_m_std": ..., "sl_error_m_count": ...,
                           ... the same four for every metric ...,
                           "seconds_per_estimate_mean": ..., "seconds_per_estimate_median": ...,
                           "seconds_per_estimate_std": ..., "seconds_per_estimate_count": ...},
                    "100": {...}},
      "by_case": {"env1_src0": {"50": {... as in aggregate ...}}, ...}
    }

``std`` is the population standard deviation (``ddof = 0``); ``count`` is the
number of estimates that had the metric (NaN/None values are left out of
the statistics, which are None when the count is 0).  ``by_case`` is what the
paper's per-environment figures (Fig. 8, Fig. gsl_only: 20 trials per
environment) plot.

Keeping and resuming (``journal=``): every finished estimate is appended at
once to a JSON-lines journal (:class:`dgse.journal.Journal`, kind
``"evaluate"``) with the fingerprint of its case; a rerun with the same
journal skips the ``(case id, n_obs, trial)`` it finds there and returns what
an uninterrupted run returns (up to ``seconds``, ``seconds_total`` and
``created``), since the observations and estimator seeds depend on those
only.  The journal's identity is the method, the estimator (its description
and ``estimator_kwargs``), the seed and the noise model: a journal written
with others is refused with an :class:`~dgse.errors.InputDataError` naming the
difference (``restart=True`` discards it); other counts, trials, cases or
limits reuse what fits.  A case whose contents changed since is refused too.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import hashlib
import json
import math
import os
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as _pkg_version
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from dgse.belief.belief import Belief
from dgse.belief.estimator import Estimator
from dgse.belief.knowledge import DEFAULT_LEVEL, Knowledge, check_level, require_level
from dgse.errors import DGSEError, InputDataError
from dgse.estimators.registry import get_estimator
from dgse.evaluation.metrics import METRIC_KEYS, EstimateMetrics, evaluate_belief
from dgse.files import atomic_open, is_temporary, write_text
from dgse.options import Settings
from dgse.sensing.noise import NoiseModel, NoiseParams
from dgse.sensing.sensors import Observations, random_observations
from dgse.world.case import Case

if TYPE_CHECKING:
    from dgse.journal import Journal

__all__ = [
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "STAT_KEYS",
    "CaseRef",
    "ProgressCallback",
    "aggregate",
    "draw_observations",
    "estimator_seed",
    "evaluate",
    "load_estimate",
    "observation_seed",
    "open_cases",
    "save_estimate",
    "summarize",
    "write_json",
]

FORMAT_NAME = "dgse-evaluation"
FORMAT_VERSION = 1
#: Statistics per metric in ``aggregate`` / ``by_case`` (key ``<metric>_<stat>``).
STAT_KEYS = ("mean", "median", "std", "count")
#: Metric descriptions written into the result (``metrics``).
METRIC_DESCRIPTIONS: dict[str, str] = {
    "sl_error_m": "distance (m) from the probability-weighted mean position to the true source",
    "map_error_m": "distance (m) from the most probable cell's centre to the true source",
    "ce": "-log max(p(true cell), 1e-12) of the source posterior (nats)",
    "entropy": "entropy of the source posterior (nats)",
    "normalized_entropy": "entropy / log(number of free cells)",
    "wf_rmse": "wind RMSE over both components at free cells (m/s)",
    "wf_nll": "wind Gaussian NLL per component, mean over free cells (nats)",
    "cf_rmse": "RMSE of log(1 + ppm) at free cells",
    "cf_nll": "Gaussian NLL of log(1 + ppm), mean over free cells (nats)",
    "cf_rmse_ppm": "concentration RMSE at free cells (ppm) of the belief's ppm point map "
    "(median expm1(mu) for log-space beliefs, the mean for ppm-space ones)",
    "cf_nll_ppm": "NLL of the true ppm values under the belief's own density: the exact "
    "lognormal density for log-space beliefs, the Gaussian for ppm-space ones (nats)",
    "seconds": "wall time of estimator.estimate (s)",
}

#: ``callback(done, total, record)`` after every estimate (``done`` counts resumed estimates too).
ProgressCallback = Callable[[int, int, dict[str, Any]], None]


# -- cases --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class CaseRef:
    """A case of an evaluation set, loaded on demand.

    Attributes:
        id: the case id (seeds the observations; see the module docstring).
        load: returns the :class:`Case`.
    """

    id: str
    load: Callable[[], Case]


def _unique_ids(ids: Sequence[str]) -> list[str]:
    seen: dict[str, int] = {}
    out = []
    for i in ids:
        seen[i] = seen.get(i, 0) + 1
        out.append(i if seen[i] == 1 else f"{i}#{seen[i]}")
    return out


def _case_loader(path: Path) -> Callable[[], Case]:
    return lambda: Case.load(path)


def _const(case: Case) -> Callable[[], Case]:
    return lambda: case


@contextlib.contextmanager
def open_cases(
    cases_or_store: Any, split: str | None = "test", limit: int | None = None
) -> Iterator[tuple[list[CaseRef], dict[str, Any]]]:
    """The cases of an evaluation set as :class:`CaseRef` s, plus a description of the set.

    A context manager (a dataset store stays open while it is used)::

        with open_cases("data/test.h5") as (refs, info):
            case = refs[0].load()

    Args:
        cases_or_store: a directory of case files, a case file (``.npz``), a
            dataset store file or :class:`~dgse.data.store.DatasetStore`, a
            :class:`Case`, or a sequence of cases.
        split: the split of a dataset store (None: all); ignored otherwise.
        limit: only the first ``limit`` cases (in id order for files and stores).

    Yields:
        ``(refs, info)`` with ``info = {"cases_source": str, "split": str | None}``.

    Raises:
        InputDataError: a missing path, an empty directory or split, a file that
            is neither a case file nor a dataset store.
    """
    if limit is not None and int(limit) < 1:
        raise InputDataError(f"limit must be at least 1, got {limit}")
    with contextlib.ExitStack() as stack:
        refs: list[CaseRef] = []
        info: dict[str, Any] = {"split": None}
        store = None
        if isinstance(cases_or_store, Case):
            refs = [CaseRef(cases_or_store.name, _const(cases_or_store))]
            info["cases_source"] = f"case {cases_or_store.name}"
        elif isinstance(cases_or_store, (str, os.PathLike)):
            path = Path(cases_or_store)
            info["cases_source"] = str(path)
            if not path.exists():
                raise InputDataError(f"{path}: no such file or directory")
            if path.is_dir():
                files = sorted(p for p in path.glob("*.npz") if p.is_file() and not is_temporary(p))
                if not files:
                    raise InputDataError(f"{path}: no case files (*.npz) in this directory")
                refs = [CaseRef(p.stem, _case_loader(p)) for p in files]
            elif path.suffix.lower() == ".npz":
                refs = [CaseRef(path.stem, _case_loader(path))]
            else:
                import h5py

                if not h5py.is_hdf5(path):
                    raise InputDataError(
                        f"{path}: neither a case file (.npz), a directory of case files nor a "
                        "dataset store (.h5)"
                    )
                from dgse.data.store import DatasetStore

                store = stack.enter_context(DatasetStore(path, "r"))
        else:
            from dgse.data.store import DatasetStore

            if isinstance(cases_or_store, DatasetStore):
                store = cases_or_store
                info["cases_source"] = str(store.path)
            elif isinstance(cases_or_store, Iterable):
                items = list(cases_or_store)
                if not items or not all(isinstance(c, Case) for c in items):
                    raise InputDataError("expected a non-empty sequence of Case objects")
                ids = _unique_ids([c.name for c in items])
                refs = [CaseRef(i, _const(c)) for i, c in zip(ids, items, strict=True)]
                info["cases_source"] = f"{len(items)} cases"
            else:
                raise InputDataError(
                    f"cannot evaluate on a {type(cases_or_store).__name__}: give a directory of case "
                    "files, a case file, a dataset store or Case objects"
                )
        if store is not None:
            info["split"] = split
            refs = []
            for lid in store.layouts(split):
                for k in range(store.n_sources(lid)):
                    refs.append(CaseRef(f"{lid}_src{k}", _store_loader(store, lid, k)))
            if not refs:
                which = f"split {split!r}" if split is not None else "the store"
                raise InputDataError(f"{store.path}: no cases in {which}")
        if limit is not None:
            refs = refs[: int(limit)]
        yield refs, info


def _store_loader(store: Any, layout_id: str, k: int) -> Callable[[], Case]:
    return lambda: store.case(layout_id, k)


# -- observations -------------------------------------------------------------------------------
def _id_words(case_id: str) -> list[int]:
    digest = hashlib.sha256(case_id.encode("utf-8")).digest()
    return [int.from_bytes(digest[k : k + 4], "little") for k in range(0, 16, 4)]


def observation_seed(seed: int, case_id: str, n_obs: int, trial: int) -> np.random.SeedSequence:
    """The seed sequence of the observations of ``(case_id, n_obs, trial)`` in a run seeded ``seed``."""
    for name, v in (("seed", seed), ("n_obs", n_obs), ("trial", trial)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or int(v) < 0:
            raise InputDataError(f"{name} must be a non-negative integer, got {v!r}")
    return np.random.SeedSequence([int(seed), *_id_words(str(case_id)), int(n_obs), int(trial)])


def _check_count(case: Case, case_id: str, n_obs: int) -> None:
    n_free = int(case.free.sum())
    if n_obs > n_free:
        raise InputDataError(
            f"case {case_id!r} has only {n_free} free cells: cannot place {n_obs} sensors "
            "(use fewer observations)"
        )


def draw_observations(
    case: Case,
    n_obs: int,
    seed: int,
    case_id: str | None = None,
    trial: int = 0,
    noise_model: NoiseModel | None = None,
) -> Observations:
    """The observations of trial ``trial`` with ``n_obs`` sensors on ``case`` (module docstring).

    Args:
        case: the true scenario.
        n_obs: number of sensors (distinct free cells), ``1 <= n_obs <= free cells``.
        seed: the run's seed (>= 0).
        case_id: the case's id in the run (default ``case.name``).
        trial: trial index (>= 0).
        noise_model: Table I noise by default.

    Raises:
        InputDataError: ``n_obs`` larger than the number of free cells, or bad seeds.
    """
    cid = case.name if case_id is None else case_id
    if isinstance(n_obs, bool) or int(n_obs) < 1:
        raise InputDataError(f"the number of observations must be at least 1, got {n_obs}")
    _check_count(case, cid, int(n_obs))
    obs_ss, time_ss = observation_seed(seed, cid, int(n_obs), trial).spawn(2)
    t = None
    if case.frames is not None:
        period = case.frames.shape[0] * float(case.meta["frame_dt"])
        t = np.random.default_rng(time_ss).uniform(0.0, period, size=int(n_obs))
    return random_observations(case, int(n_obs), np.random.default_rng(obs_ss), noise_model, t=t)


# -- statistics ---------------------------------------------------------------------------------
def _nan_to_none(v: Any) -> Any:
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def summarize(values: Iterable[float | None]) -> dict[str, float | int | None]:
    """``mean``, ``median``, ``std`` (ddof 0) and ``count`` of the finite values (None when none)."""
    a = np.array([float(v) for v in values if v is not None and math.isfinite(float(v))], dtype=np.float64)
    if a.size == 0:
        return {"mean": None, "median": None, "std": None, "count": 0}
    return {
        "mean": float(a.mean()),
        "median": float(np.median(a)),
        "std": float(a.std()),
        "count": int(a.size),
    }


def aggregate(records: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """Statistics of a group of per-estimate records (module docstring, ``aggregate`` entries)."""
    out: dict[str, Any] = {"n_estimates": len(records)}
    for key in METRIC_KEYS:
        for stat, v in summarize(r.get(key) for r in records).items():
            out[f"{key}_{stat}"] = v
    for stat, v in summarize(r.get("seconds") for r in records).items():
        out[f"seconds_per_estimate_{stat}"] = v
    return out


def _group_by_count(records: Sequence[Mapping[str, Any]], counts: Sequence[int]) -> dict[str, Any]:
    return {str(n): aggregate([r for r in records if r["n_obs"] == n]) for n in counts}


# -- evaluation ---------------------------------------------------------------------------------
def _jsonable(value: Any) -> Any:
    if value is None or isinstance(value, (bool, int, str)):
        return value
    if isinstance(value, float):
        return _nan_to_none(value)
    if isinstance(value, (np.integer, np.floating)):
        return _jsonable(value.item())
    if isinstance(value, os.PathLike):
        return str(value)
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, Settings):  # a settings object: every field
        return _jsonable(value.to_dict())
    text = repr(value)  # e.g. a network object: its type, not its whole architecture
    return text if len(text) <= 120 and "\n" not in text else f"<{type(value).__name__}>"


def _dgse_version() -> str:
    try:
        return _pkg_version("dgse")
    except PackageNotFoundError:
        return ""


def _check_counts(observation_counts: int | Sequence[int]) -> list[int]:
    raw = [observation_counts] if isinstance(observation_counts, (int, np.integer)) else observation_counts
    counts: list[int] = []
    for n in raw:
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or int(n) < 1:
            raise InputDataError(f"observation counts must be positive integers, got {n!r}")
        if int(n) not in counts:
            counts.append(int(n))
    if not counts:
        raise InputDataError("give at least one observation count")
    return counts


def _estimator_info(est: Estimator) -> dict[str, Any]:
    """The estimator's class and settings (:meth:`~dgse.belief.estimator.Estimator.describe`:
    defaults included, so that a journal written before a default changed is refused rather
    than mixed with estimates of the new default)."""
    return {"class": type(est).__name__, "settings": _jsonable(est.describe())}


#: ``before(case_id, n_obs, trial, trials)``: the built-in bar's note of the estimate about to run.
_Before = Callable[[str, int, int, int], None]


def _make_progress(
    progress: bool | ProgressCallback, total: int, start: int = 0
) -> tuple[ProgressCallback | None, _Before | None, Any]:
    """``(after, before, context)``: the callbacks and the context manager that shows the bar."""
    if callable(progress):
        return progress, None, contextlib.nullcontext()
    if not progress:
        return None, None, contextlib.nullcontext()
    from rich import get_console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    bar = Progress(
        TextColumn("[progress.description]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        transient=True,
        disable=not get_console().is_terminal,  # a log gets no bar (rich would leave an empty line)
    )
    first = "evaluating" if not start else f"evaluating ({start} kept from an earlier run)"
    task = bar.add_task(first, total=total, completed=start)

    def before(case_id: str, n_obs: int, trial: int, trials: int) -> None:
        bar.update(task, description=f"{case_id} n={n_obs} trial {trial + 1}/{trials}")

    def update(done: int, total: int, record: dict[str, Any]) -> None:
        bar.update(task, completed=done)

    return update, before, bar


def evaluate(
    cases_or_store: Any,
    method: str | Estimator,
    observation_counts: int | Sequence[int],
    trials: int = 1,
    seed: int = 0,
    estimator_kwargs: Mapping[str, Any] | None = None,
    progress: bool | ProgressCallback = False,
    *,
    split: str | None = "test",
    noise_model: NoiseModel | None = None,
    limit: int | None = None,
    journal: str | os.PathLike[str] | None = None,
    restart: bool = False,
    knowledge: str = DEFAULT_LEVEL,
    on_start: Callable[[int, int], None] | None = None,
) -> dict[str, Any]:
    """Evaluate one estimator on a set of cases (see the module docstring for protocol and result).

    Args:
        cases_or_store: directory of case files, case file, dataset store (path or
            :class:`~dgse.data.store.DatasetStore`), a :class:`Case` or a sequence of cases.
        method: a registered estimator name (built with
            ``get_estimator(method, **estimator_kwargs)``) or an estimator object.
        observation_counts: numbers of sensors (e.g. ``[50, 100, 150, 200, 250]``).
        trials: random sensor configurations per case and count (the paper: 20).
        seed: the run's seed (>= 0); equal seeds give equal observations.
        estimator_kwargs: keyword arguments of the estimator factory (e.g.
            ``{"model": "path.safetensors", "K": 5, "T": 5}``); not allowed with an
            estimator object.
        progress: True for a progress bar on the terminal, or a
            :data:`ProgressCallback`.
        split: the split of a dataset store (default ``"test"``; None: all).
        noise_model: sensor noise (Table I ranges by default).
        limit: evaluate only the first ``limit`` cases.
        journal: keep every finished estimate in this JSON-lines file and skip
            those already there (module docstring); None keeps nothing.
        restart: discard an existing journal instead of resuming it.
        knowledge: what the estimator is told about each case besides the readings
            (:mod:`dgse.belief.knowledge`: ``"map"``, ``"openings"`` or ``"wind"``);
            recorded in the result.
        on_start: called as ``on_start(kept, total)`` once, after every check and before the
            first estimate: ``kept`` of the ``total`` estimates come from the journal.

    Returns:
        The result dict (JSON-ready; :func:`write_json` writes it).

    Raises:
        InputDataError: bad counts/trials/seed, missing or unreadable cases, more
            observations than a case has free cells, a journal written with other
            settings or for a case that has changed since.
        UnsupportedError: an unknown method name (the message lists the known ones), or
            a knowledge level the estimator does not work at.
    """
    level = check_level(knowledge)
    counts = _check_counts(observation_counts)
    if isinstance(trials, bool) or not isinstance(trials, (int, np.integer)) or int(trials) < 1:
        raise InputDataError(
            f"{{trials}} must be a positive integer, got {trials!r}", names={"trials": "trials"}
        )
    trials = int(trials)
    observation_seed(seed, "", 1, 0)  # validates the seed
    kwargs = dict(estimator_kwargs or {})
    if isinstance(method, str):
        est: Any = get_estimator(method, **kwargs)
        method_name = method
    else:
        if kwargs:
            raise InputDataError("estimator_kwargs apply to a method name, not to an estimator object")
        if not isinstance(method, Estimator):
            raise InputDataError(
                f"{type(method).__name__} is not an estimator (derive it from dgse.belief.KnowledgeUser "
                "and give it estimate())"
            )
        est = method
        method_name = method.name
    require_level(est, method_name, level)
    reseed = "seed" not in kwargs
    original_seed = est.seed
    noise = "Table I" if noise_model is None else _jsonable(vars(noise_model.ranges))
    identity = {
        "method": method_name,
        "estimator": _estimator_info(est),
        "estimator_kwargs": _jsonable(kwargs),
        "seed": int(seed),
        "noise": noise,
        "knowledge": level,
    }
    t_start = time.perf_counter()
    records: list[dict[str, Any]] = []
    book: Journal | None = None
    try:
        with open_cases(cases_or_store, split, limit) as (refs, info):
            kept: dict[tuple[Any, Any, Any], dict[str, Any]] = {}
            if journal is not None:
                from dgse.journal import Journal

                book = Journal(journal, "evaluate", identity, restart=restart, unit="estimate")
                for entry in book.records:
                    rec = entry.get("record")
                    if isinstance(rec, dict):
                        kept[(rec.get("case"), rec.get("n_obs"), rec.get("trial"))] = entry
            total = len(refs) * len(counts) * trials
            start = sum((r.id, n, t) in kept for r in refs for n in counts for t in range(trials))
            if on_start is not None:
                on_start(start, total)
            callback, before, bar = _make_progress(progress, total, start)
            with bar:
                for ref in refs:
                    records += _evaluate_case(
                        est, ref, counts, trials, seed, noise_model, reseed, book, kept, before, callback,
                        done=len(records), total=total, level=level,
                    )  # fmt: skip
            case_ids = [r.id for r in refs]
    finally:
        if book is not None:
            book.close()
        if reseed:
            est.seed = original_seed  # an estimator object is handed back as it came
    by_case = {cid: _group_by_count([r for r in records if r["case"] == cid], counts) for cid in case_ids}
    return {
        "format": FORMAT_NAME,
        "format_version": FORMAT_VERSION,
        "method": method_name,
        "estimator": _estimator_info(est),
        "estimator_kwargs": _jsonable(kwargs),
        "cases_source": info["cases_source"],
        "split": info["split"],
        "observation_counts": counts,
        "trials": trials,
        "seed": int(seed),
        "knowledge": level,
        "n_cases": len(case_ids),
        "cases": case_ids,
        "protocol": {
            "observations": "n distinct free cells drawn uniformly; Table I noise drawn per "
            "configuration; cases with frames: gas from the frame at a uniform random time per sensor",
            "seeding": "numpy SeedSequence([seed, sha256(case id)[:16], n_obs, trial])",
            "timing": "perf_counter around estimator.estimate",
            "cells": "field metrics over the free cells of each case",
            "noise": noise,
        },
        "metrics": METRIC_DESCRIPTIONS,
        "created": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "dgse_version": _dgse_version(),
        "seconds_total": time.perf_counter() - t_start,
        "per_case": records,
        "aggregate": _group_by_count(records, counts),
        "by_case": by_case,
    }


def _evaluate_case(
    est: Any,
    ref: CaseRef,
    counts: Sequence[int],
    trials: int,
    seed: int,
    noise_model: NoiseModel | None,
    reseed: bool,
    book: Journal | None,
    kept: Mapping[tuple[Any, Any, Any], Mapping[str, Any]],
    before: _Before | None,
    callback: ProgressCallback | None,
    *,
    done: int,
    total: int,
    level: str,
) -> list[dict[str, Any]]:
    """The records of one case in loop order: kept ones from the journal, the others estimated."""
    from dgse.journal import case_fingerprint, check_kept_case

    case = ref.load()
    fingerprint = None if book is None else case_fingerprint(case)
    est.set_knowledge(Knowledge.from_case(case, level))  # what it may know besides the readings
    for n in counts:
        _check_count(case, ref.id, n)
    out: list[dict[str, Any]] = []
    for n in counts:
        for trial in range(trials):
            old = kept.get((ref.id, n, trial))
            if old is not None and book is not None:
                check_kept_case(
                    old,
                    fingerprint,
                    f"case {ref.id!r} differs from the one whose estimates {book.path} keeps "
                    "(re-solved?): start afresh with {restart}, or give another path",
                )
                out.append(dict(old["record"]))
                continue
            if before is not None:
                before(ref.id, n, trial, trials)
            rec = _jsonable(_one_estimate(est, case, ref.id, n, trial, seed, noise_model, reseed))
            if book is not None:
                book.append({"case_fingerprint": fingerprint, "record": rec})
            out.append(rec)
            if callback is not None:
                callback(done + len(out), total, rec)
    return out


def estimator_seed(seed: int, case_id: str, n_obs: int, trial: int) -> int:
    """The seed an estimator with a ``seed`` attribute gets for ``(case_id, n_obs, trial)``."""
    ss = observation_seed(seed, case_id, n_obs, trial).spawn(3)[2]
    return int(ss.generate_state(1, np.uint32)[0])


@dataclass(frozen=True)
class Estimate:
    """One estimate from random readings: the readings, the belief, its scores and its time (s)."""

    observations: Observations
    belief: Belief
    metrics: EstimateMetrics
    seconds: float


def estimate_once(
    est: Estimator,
    case: Case,
    case_id: str,
    n_obs: int,
    seed: int,
    trial: int = 0,
    noise_model: NoiseModel | None = None,
    reseed: bool = True,
) -> Estimate:
    """Draw trial ``trial``'s ``n_obs`` readings of ``case`` (:func:`draw_observations`), estimate
    and score the belief against the case: what :func:`evaluate` does for every estimate.

    ``reseed``: seed the estimator's draws by ``(seed, case_id, n_obs, trial)``
    (:func:`estimator_seed`), so that the same call gives the same belief.
    """
    obs = draw_observations(case, n_obs, seed, case_id, trial, noise_model)
    if reseed:
        est.seed = estimator_seed(seed, case_id, n_obs, trial)
    t0 = time.perf_counter()
    belief = est.estimate(case.occupancy, case.resolution, obs)
    seconds = time.perf_counter() - t0
    if not isinstance(belief, Belief):
        raise InputDataError(f"the estimator returned a {type(belief).__name__}, not a Belief")
    return Estimate(obs, belief, evaluate_belief(belief, case), seconds)


def _one_estimate(
    est: Any,
    case: Case,
    case_id: str,
    n_obs: int,
    trial: int,
    seed: int,
    noise_model: NoiseModel | None,
    reseed: bool,
) -> dict[str, Any]:
    e = estimate_once(est, case, case_id, n_obs, seed, trial, noise_model, reseed)
    x, y = e.belief.source_estimate()
    rec: dict[str, Any] = {"case": case_id, "n_obs": int(n_obs), "trial": int(trial), "seconds": e.seconds}
    rec.update({k: _nan_to_none(v) for k, v in e.metrics.to_dict().items()})
    rec["source_estimate_xy"] = [x, y]
    rec["true_source_xy"] = [float(case.source[0]), float(case.source[1])]
    return rec


def write_json(result: Mapping[str, Any], path: str | os.PathLike[str]) -> Path:
    """Write an evaluation result as strict JSON (no NaN), atomically; returns the path."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    text = json.dumps(_jsonable(result), indent=1, allow_nan=False)
    return write_text(p, text + "\n")


# -- one estimate as a file ---------------------------------------------------------------------
def save_estimate(
    path: str | os.PathLike[str],
    belief: Belief,
    observations: Observations,
    metrics: EstimateMetrics | None = None,
    extra: Mapping[str, Any] | None = None,
) -> Path:
    """Write a belief, its observations and (optionally) its metrics to an ``.npz`` file.

    Keys: ``occupancy`` (uint8), ``resolution``, ``source_probs``, ``source_estimate``
    (``(x, y)`` m), the belief fields that exist (``wind_mean``, ``wind_var``,
    ``log_conc_mean``, ``log_conc_var``, ``conc_mean_ppm``, ``conc_var_ppm``, the reducible
    variances),
    ``obs_cells`` (int64 ``(n, 2)``), ``obs_gas`` (ppm), ``obs_wind`` (m/s),
    ``obs_times`` (s, when known), and JSON strings ``info`` (the belief's info),
    ``metrics`` (``{}`` without metrics; NaN as null), ``obs_noise`` (noise
    parameters or null) and ``extra``.  No pickles: read it with
    ``np.load(path)`` or :func:`load_estimate`.
    """
    p = Path(path)
    if p.suffix != ".npz":
        p = p.with_name(p.name + ".npz")
    arrays: dict[str, Any] = {
        "occupancy": belief.occupancy.astype(np.uint8),
        "resolution": np.array(belief.resolution, dtype=np.float64),
        "source_probs": belief.source_probs,
        "source_estimate": np.array(belief.source_estimate()),
    }
    for key in ("wind_mean", "wind_var", "log_conc_mean", "log_conc_var", "conc_mean_ppm", "conc_var_ppm",
                "wind_var_reducible", "log_conc_var_reducible"):  # fmt: skip
        value = getattr(belief, key)
        if value is not None:
            arrays[key] = np.asarray(value)
    arrays["obs_cells"] = observations.cells
    arrays["obs_gas"] = observations.gas
    arrays["obs_wind"] = observations.wind
    if observations.times is not None:
        arrays["obs_times"] = observations.times
    noise = None if observations.noise is None else observations.noise.to_dict()
    arrays["obs_noise"] = np.array(json.dumps(noise))
    arrays["info"] = np.array(json.dumps(_jsonable(belief.info)))
    arrays["metrics"] = np.array(json.dumps(_jsonable(metrics.to_dict() if metrics else {})))
    arrays["extra"] = np.array(json.dumps(_jsonable(dict(extra or {}))))
    p.parent.mkdir(parents=True, exist_ok=True)
    with atomic_open(p, "wb") as fh:
        np.savez_compressed(fh, **arrays)
    return p


def load_estimate(path: str | os.PathLike[str]) -> tuple[Belief, Observations, dict[str, Any]]:
    """Read a file of :func:`save_estimate`: ``(belief, observations, {"metrics", "extra"})``.

    Raises:
        InputDataError: a missing or malformed file.
    """
    p = Path(path)
    if not p.is_file():
        raise InputDataError(f"{p}: no such file")
    try:
        with np.load(p, allow_pickle=False) as d:
            a = {k: d[k] for k in d.files}
        info = json.loads(str(a["info"]))
        belief = Belief(
            occupancy=a["occupancy"],
            resolution=float(a["resolution"]),
            source_probs=a["source_probs"],
            wind_mean=a.get("wind_mean"),
            wind_var=a.get("wind_var"),
            log_conc_mean=a.get("log_conc_mean"),
            log_conc_var=a.get("log_conc_var"),
            info=info,
            wind_var_reducible=a.get("wind_var_reducible"),
            log_conc_var_reducible=a.get("log_conc_var_reducible"),
        )
        noise = json.loads(str(a["obs_noise"]))
        obs = Observations(
            a["obs_cells"],
            a["obs_gas"],
            a["obs_wind"],
            a.get("obs_times"),
            NoiseParams(**noise) if noise else None,
        )
        meta = {"metrics": json.loads(str(a["metrics"])), "extra": json.loads(str(a["extra"]))}
    except DGSEError:
        raise
    except (KeyError, ValueError, OSError, TypeError) as e:
        raise InputDataError(f"{p}: not a readable estimate file ({e})") from None
    return belief, obs, meta
