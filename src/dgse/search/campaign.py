"""Search campaigns: many episodes over a set of cases, the per-case and overall metrics.

:func:`run_trials` runs ``trials`` episodes (:func:`~dgse.search.episode.run_episode`)
on every case with one estimator and one planner and returns a JSON-ready
dict (what ``dgse search --json`` writes):

* ``settings``: method, model, planner, options, trials, seed, time limit, ...
  (``sample_rate_hz`` only when the robot reads on the way, so a journal of the paper's
  protocol written before that option existed still resumes);
* ``aggregate``: :func:`~dgse.search.metrics.aggregate` over all trials of all cases;
* ``per_case``: one entry per case: ``case``, ``file``, ``metrics`` (the
  aggregate of its trials) and ``trials`` (each episode's summary,
  :meth:`~dgse.search.episode.EpisodeResult.to_dict`, with ``trial`` and
  ``metrics``).

NaN and infinities are written as None, numpy scalars as Python numbers.

Seeds: trial ``r`` of the case file ``<stem>.npz`` uses
``SeedSequence([seed, crc32(stem), r])`` (:func:`trial_seed`), so the start
cells and the sensor noise depend neither on the method, the planner nor the
other cases: every method meets the same starts.

Fixed starts (:func:`fixed_start`): ``start_m`` (m, the grid frame) or a case
file's ``meta["start_m"]`` (e.g. from ``dgse import-gaden-scenario``) is the
start of every trial on that case instead of a drawn one; it must be a free
cell from which the source can be reached.

For DGSE methods (``dgse-*``) the estimator gets ``model="default"`` (the
shipped weights) and ``seed=`` unless given (:func:`estimator_options`).

Keeping and resuming (``journal=``): every finished episode is appended to a
JSON-lines journal (:class:`~dgse.journal.Journal`, kind ``"search"``)
as soon as it finishes, with its case file's stem, trial index, the case's
fingerprint and its row of ``per_case[...]["trials"]``.  A rerun with the
same journal skips the (stem, trial) pairs it finds there, and (as the trial
seeds depend only on the seed, the stem and the trial) returns what an
uninterrupted run returns, up to the measured computation times.  The
journal's identity is ``settings`` without ``trials`` plus ``steps``: a
journal written with another method, planner, options, seed, time limit, ...
is refused with an :class:`~dgse.errors.InputDataError` that names the
difference (``restart=True`` discards it); more or fewer trials, or other
cases, reuse what fits.  A case file whose contents changed since its episodes
were kept is refused too.  :func:`dgse.journal.journal_path` is where ``dgse search``
keeps the journal of its JSON file.
"""

from __future__ import annotations

import functools
import math
import os
import zlib
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from dgse.belief.estimator import Estimator
from dgse.belief.knowledge import DEFAULT_LEVEL, check_level, require_level
from dgse.errors import InputDataError
from dgse.files import is_temporary, json_safe
from dgse.planning.planners import Planner
from dgse.presets import PROTOCOL
from dgse.search.episode import EpisodeResult, StepRecord
from dgse.world.case import Case

__all__ = [
    "EpisodeCallback",
    "Progress",
    "StartCallback",
    "TrialStepCallback",
    "estimator_options",
    "json_safe",
    "load_cases",
    "run_trials",
    "trial_seed",
]

#: ``progress(description, done, total)``: called before every episode and once when all are done.
Progress = Callable[[str, int, int], None]
#: ``on_episode(path, case, trial, result)``: called after every episode (after it is kept).
EpisodeCallback = Callable[[Path, Case, int, EpisodeResult], None]
#: ``on_step(path, trial, record)``: called after every step of every episode run.
TrialStepCallback = Callable[[Path, int, StepRecord], None]
#: ``on_start(kept, total)``: called once, after every check and before the first episode;
#: ``kept`` of the ``total`` episodes come from the journal.
StartCallback = Callable[[int, int], None]


def load_cases(path: str | os.PathLike[str]) -> list[tuple[Path, Case]]:
    """The case files at ``path``: one file, or every case ``.npz`` in a directory (sorted by name).

    Layout files in a directory are skipped.

    Raises:
        InputDataError: no such path, or no case file in the directory.
    """
    from dgse.world.layout_io import npz_kind

    path = Path(path)
    if path.is_dir():
        files = sorted(p for p in path.glob("*.npz") if p.is_file() and not is_temporary(p))
        out = [(p, Case.load(p)) for p in files if npz_kind(p) == "case"]
        if not out:
            raise InputDataError(f"{path}: no case files (.npz with wind, concentration, source)")
        return out
    if not path.exists():
        raise InputDataError(f"{path}: no such file or directory")
    if npz_kind(path) != "case":
        raise InputDataError(f"{path} is a layout file; dgse search needs case files (solve it first)")
    return [(path, Case.load(path))]


def trial_seed(seed: int, stem: str, trial: int) -> np.random.SeedSequence:
    """The seed of trial ``trial`` on the case file named ``stem`` (see the module docstring)."""
    return np.random.SeedSequence([int(seed) & 0xFFFFFFFF, zlib.crc32(stem.encode()), int(trial)])


def _made(
    given: Any, factory: Callable[..., Any], options: dict[str, Any], name: str | None
) -> tuple[Any, str]:
    """An estimator or planner given by registry name (made by ``factory`` with ``options``) or
    as an object, and the name a run records for it (``name``, else the given one's)."""
    if isinstance(given, str):
        return factory(given, **options), name or given
    return given, name or given.name


def estimator_options(
    method: str, *, model: str | None = None, seed: int = 0, options: Mapping[str, Any] | None = None
) -> dict[str, Any]:
    """The keyword arguments of estimator ``method`` in a search campaign.

    ``model`` when it is given; the campaign's ``seed`` for every estimator
    that takes a ``seed`` option (the DGSE networks' sampling, PMFS's
    simulations).  ``options`` come first (they win over both).
    """
    from dgse.estimators.registry import ESTIMATORS

    kw = dict(options or {})
    if model is not None:
        kw.setdefault("model", model)
    if ESTIMATORS.accepts(method, "seed"):
        kw.setdefault("seed", seed)
    return kw


def fixed_start(
    case: Case, start_m: Sequence[float] | None = None, origin: str = "case", connectivity: int = 8
) -> tuple[int, int] | None:
    """The start cell of every trial on ``case``: ``start_m`` (``(x, y)`` m), else the case's
    ``meta["start_m"]``, else None (each trial draws one).

    Raises:
        InputDataError: a start that is not two numbers, lies outside the map or in a wall, or
            from which the source cannot be reached (``origin`` names the case in the message).
    """
    from dgse.planning.paths import graph_for

    given = start_m is not None
    xy = start_m if given else case.meta.get("start_m")
    if xy is None:
        return None
    where = "{start}" if given else f"meta start_m of {origin}"
    try:
        x, y = (float(v) for v in xy)
    except (TypeError, ValueError):
        raise InputDataError(
            f"start ({where}) must be two numbers x y in m, got {xy!r}", names={"start": "start_m"}
        ) from None
    label = f"start ({x:.2f}, {y:.2f}) m ({where})"
    try:
        i, j = case.grid.cell_of(x, y)
    except InputDataError:
        raise InputDataError(
            f"{label} lies outside the map of {origin}", names={"start": "start_m"}
        ) from None
    if not case.free[i, j]:
        raise InputDataError(
            f"{label} lies in a wall of {origin} (cell ({i}, {j}))", names={"start": "start_m"}
        )
    graph = graph_for(case.occupancy, case.resolution, connectivity)
    if not math.isfinite(graph.distance((i, j), case.source_cell)):
        raise InputDataError(
            f"{label}: the source of {origin} cannot be reached from it", names={"start": "start_m"}
        )
    return (i, j)


def _check_settings(trials: int, time_limit: float, speed: float, dwell: float, min_start: float) -> None:
    """Raise :class:`InputDataError` naming the argument (``{name}``: each front end spells it)."""
    if trials < 1:
        raise InputDataError(f"{{trials}} must be at least 1, got {trials}", names={"trials": "trials"})
    for name, v in (("time_limit", time_limit), ("speed", speed), ("dwell", dwell)):
        if not (math.isfinite(v) and v > 0):
            raise InputDataError(f"{{{name}}} must be a positive number, got {v:g}", names={name: name})
    if not (math.isfinite(min_start) and min_start >= 0):
        raise InputDataError(
            f"{{min_start_distance}} must be >= 0, got {min_start:g}",
            names={"min_start_distance": "min_start_distance"},
        )


def run_trials(
    cases: Sequence[tuple[str | os.PathLike[str], Case]] | str | os.PathLike[str],
    estimator: str | Estimator,
    planner: str | Planner,
    trials: int = 20,
    seed: int = 0,
    *,
    estimator_options: Mapping[str, Any] | None = None,
    planner_options: Mapping[str, Any] | None = None,
    method: str | None = None,
    planner_name: str | None = None,
    speed: float = PROTOCOL.speed,
    dwell: float = PROTOCOL.dwell,
    time_limit: float = PROTOCOL.time_limit,
    use_frames: bool = True,
    min_start_distance: float = PROTOCOL.min_start_distance,
    include_compute_time: bool = False,
    steps: bool = False,
    record_first: bool = False,
    progress: Progress | None = None,
    on_episode: EpisodeCallback | None = None,
    on_step: TrialStepCallback | None = None,
    on_start: StartCallback | None = None,
    journal: str | os.PathLike[str] | None = None,
    restart: bool = False,
    knowledge: str = DEFAULT_LEVEL,
    start_m: Sequence[float] | None = None,
    sample_rate_hz: float | None = PROTOCOL.sample_rate_hz,
) -> dict[str, Any]:
    """Run ``trials`` search episodes on every case and return the metrics (module docstring).

    Args:
        cases: ``(path, case)`` pairs (the path's stem seeds the trials and
            names the case's row), or a case file or directory of case files
            (:func:`load_cases`).
        estimator: a registered estimator name (built with
            ``estimator_options``) or an estimator object.
        planner: a registered planner name (built with ``planner_options``)
            or a planner object (``reset()`` before every episode).
        trials: episodes per case.
        seed: the campaign's seed (:func:`trial_seed`).
        estimator_options: keyword arguments of a named estimator; with an
            estimator object, the ones it was built with (only recorded).  In
            ``settings`` the model is recorded separately.
        planner_options: the same for the planner.
        method: the estimator's name in ``settings`` (default: the name given,
            or the object's ``name``).
        planner_name: the planner's name in ``settings`` (the same default).
        speed, dwell, time_limit, use_frames, min_start_distance, include_compute_time:
            :func:`~dgse.search.episode.run_episode`'s.
        steps: include every step's record in the trials' summaries.
        record_first: record the belief maps of trial 0 of every case (for
            ``on_episode``; e.g. an animation).
        progress: see :data:`Progress` (``done`` counts resumed episodes too).
        on_episode: see :data:`EpisodeCallback` (e.g. keep the results); not
            called for resumed episodes.
        on_step: see :data:`TrialStepCallback` (signs of life within an episode).
        on_start: see :data:`StartCallback` (e.g. say what the run will do once it is sure to start).
        journal: keep every finished episode in this JSON-lines file and skip
            the ones already there (module docstring); None keeps nothing.
            With estimator or planner objects, give the options they were
            built with: they are how a journal tells runs apart.
        restart: discard an existing journal instead of resuming it.
        knowledge: what the estimator is told about each case besides its readings
            (:mod:`dgse.belief.knowledge`); recorded in ``settings``.
        start_m: the start ``(x, y)`` in m of every trial on every case (:func:`fixed_start`;
            recorded in ``settings``); None: a case file's ``meta["start_m"]``, else drawn.
        sample_rate_hz: readings per second of travel on the way to each goal
            (:func:`~dgse.search.episode.run_episode`'s; recorded in ``settings`` when set).

    Returns:
        ``{"settings", "aggregate", "per_case"}``, JSON-ready.

    Raises:
        InputDataError: bad settings, no cases, or a journal written with other
            settings or for a case file that has changed since.
        UnsupportedError: a knowledge level the estimator does not work at.
    """
    from dgse.estimators.registry import get_estimator
    from dgse.journal import Journal, case_fingerprint, check_kept_case
    from dgse.planning.planners import get_planner
    from dgse.search.episode import run_episode
    from dgse.search.metrics import aggregate, episode_metrics
    from dgse.search.robot import check_sample_rate

    _check_settings(trials, time_limit, speed, dwell, min_start_distance)
    sample_rate_hz = check_sample_rate(sample_rate_hz)
    level = check_level(knowledge)
    pairs = load_cases(cases) if isinstance(cases, str | os.PathLike) else [(Path(p), c) for p, c in cases]
    if not pairs:
        raise InputDataError("no cases to search")
    est_kw = dict(estimator_options or {})
    plan_kw = dict(planner_options or {})
    est, method = _made(estimator, get_estimator, est_kw, method)
    plan, planner_name = _made(planner, get_planner, plan_kw, planner_name)
    require_level(est, method, level)
    model = est_kw.get("model")
    settings = json_safe(
        {
            "method": method,
            "knowledge": level,
            "model": model if isinstance(model, str) else None,
            "planner": planner_name,
            "planner_options": plan_kw,
            "estimator_options": {k: v for k, v in est_kw.items() if k != "model"},
            "trials": trials,
            "seed": seed,
            "time_limit_s": time_limit,
            "frames": use_frames,
            "speed": speed,
            "dwell": dwell,
            "min_start_distance_m": min_start_distance,
            "include_compute_time": include_compute_time,
        }
    )
    if start_m is not None:
        settings["start_m"] = [float(v) for v in start_m]
    if sample_rate_hz is not None:
        settings["sample_rate_hz"] = sample_rate_hz
    starts = {path: fixed_start(case, start_m, str(path)) for path, case in pairs}
    identity = {**{k: v for k, v in settings.items() if k != "trials"}, "steps": bool(steps)}
    book = None if journal is None else Journal(journal, "search", identity, restart=restart, unit="episode")
    kept = {} if book is None else {(r.get("case"), r.get("trial")): r for r in book.records}

    per_case: list[dict[str, Any]] = []
    all_rows: list[dict[str, Any]] = []
    total, done = len(pairs) * trials, 0
    if on_start is not None:
        on_start(sum((p.stem, r) in kept for p, _ in pairs for r in range(trials)), total)
    try:
        for path, case in pairs:
            fingerprint = None if book is None else case_fingerprint(case)
            trial_rows: list[dict[str, Any]] = []
            for r in range(trials):
                old = kept.get((path.stem, r))
                if old is not None and book is not None:
                    check_kept_case(
                        old,
                        fingerprint,
                        f"{path} differs from the case whose episodes {book.path} keeps (re-solved?): "
                        "start afresh with {restart}, or give another output path",
                    )
                    row = old["row"]
                else:
                    if progress is not None:
                        progress(f"{path.stem} trial {r + 1}/{trials}", done, total)
                    step_cb = None
                    if on_step is not None:
                        step_cb = functools.partial(on_step, path, r)
                    result = run_episode(
                        case,
                        est,
                        plan,
                        start=starts[path],
                        rng=trial_seed(seed, path.stem, r),
                        speed=speed,
                        dwell=dwell,
                        time_limit=time_limit,
                        include_compute_time=include_compute_time,
                        record=record_first and r == 0,
                        use_frames=use_frames,
                        min_start_distance=min_start_distance,
                        on_step=step_cb,
                        knowledge=level,
                        sample_rate_hz=sample_rate_hz,
                    )
                    row = json_safe(
                        {"trial": r, **result.to_dict(steps=steps), "metrics": episode_metrics(result)}
                    )
                    if book is not None:
                        book.append(
                            {"case": path.stem, "trial": r, "case_fingerprint": fingerprint, "row": row}
                        )
                    if on_episode is not None:
                        on_episode(path, case, r, result)
                trial_rows.append(row)
                all_rows.append(row["metrics"])
                done += 1
            agg = aggregate([t["metrics"] for t in trial_rows])
            per_case.append({"case": case.name, "file": str(path), "metrics": agg, "trials": trial_rows})
    finally:
        if book is not None:
            book.close()
    if progress is not None:
        progress("done", done, total)
    return json_safe({"settings": settings, "aggregate": aggregate(all_rows), "per_case": per_case})
