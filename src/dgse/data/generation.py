"""Dataset generation on Dask: layouts x 4 sources, as in the paper (Sec. IV).

Each layout is one task, :func:`solve_layout` ``(seed, layout_index, engine)``.
It is pure: its random generator comes from
``numpy.random.SeedSequence((seed, layout_index))`` only, so a layout is the
same whichever worker makes it, in whichever order, in whichever run.  It
draws, in this order, a random training layout (:func:`random_layout`), an
inlet speed (:func:`random_inlet_velocity`) and ``n_sources`` sources
(:func:`random_sources`), then solves the flow once and the gas once per
source.  A :class:`~dgse.errors.DGSEError` (a
:class:`~dgse.errors.ConvergenceError`, a layout that cannot be drawn, ...)
makes it try fresh draws from ``SeedSequence((seed, layout_index, attempt))``,
``retries`` times (default 2), and then return a failure record instead, so a
dataset normally holds exactly the requested number of layouts while the
reason of every failed attempt is kept.

:func:`generate` runs the tasks on a Dask ``LocalCluster`` of ``workers``
single-threaded processes, or on an existing cluster given by its scheduler
address.  The client process is the single writer: each result is staged in
the store's journal as soon as it arrives (``as_completed``) and the journal
is committed into the store file by copy-and-rename every ``checkpoint_s``
seconds (longer when a commit is slow: at most 1/20 of the time goes to
commits) and at the end (:mod:`dgse.data.store` explains why).  The split of
layout ``i`` is ``assign_splits(n_layouts, seed)[i]``: 80/13.3/6.7 % train/val/test,
3000/500/250 of the paper's 3750.  When every layout is done, the fixed
validation and test sensor configurations (30 per environment) are drawn
into the store.

**Resuming.**  ``generate`` reads which layout indices are stored, staged or
recorded as failed and submits only the others.  Kill it at any moment
(SIGKILL included) and run it again with the same arguments: it finishes
without losing, duplicating or corrupting a case.  Running it again with
other generation parameters (seed, number of layouts, sources, engine, layout
options, split fractions) on the same store is refused.
"""

from __future__ import annotations

import contextlib
import functools
import inspect
import json
import logging
import math
import os
import signal
import threading
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dgse.data.store import (
    DEFAULT_CONFIGS_PER_ENV,
    SPLITS,
    DatasetStore,
    Journal,
    _check_fractions,
    assign_splits,
    check_store_path,
    commit_pending,
    create_store,
)
from dgse.errors import DGSEError, InputDataError
from dgse.world.case import Case

__all__ = [
    "ClusterError",
    "GenerationReport",
    "LayoutResult",
    "generate",
    "layout_id_for",
    "layout_seed",
    "solve_layout",
    "stored_layouts",
]

#: Generation parameters that must match to resume into an existing store.
_COMPAT_KEYS = ("seed", "n_layouts", "n_sources", "engine", "layout_kwargs", "split_fractions")


class ClusterError(DGSEError):
    """The Dask cluster cannot be reached or started, or has no workers."""


def layout_id_for(layout_index: int) -> str:
    """The store id of generated layout ``layout_index``: ``layout-000042``."""
    return f"layout-{int(layout_index):06d}"


def layout_seed(seed: int, layout_index: int, attempt: int = 0) -> np.random.SeedSequence:
    """The seed sequence of a layout: ``(seed, layout_index)``, plus ``attempt`` when > 0."""
    entropy = [int(seed), int(layout_index)] + ([int(attempt)] if attempt else [])
    return np.random.SeedSequence(entropy)


@dataclass(frozen=True)
class LayoutResult:
    """What :func:`solve_layout` returns: the cases, or a failure record."""

    layout_index: int
    layout_id: str
    cases: list[Case] | None
    failure: dict[str, Any] | None
    seconds: float
    cpu_seconds: float = 0.0

    @property
    def ok(self) -> bool:
        return self.cases is not None


def solve_layout(
    seed: int,
    layout_index: int,
    engine: str = "builtin",
    *,
    n_sources: int = 4,
    layout_kwargs: Mapping[str, Any] | None = None,
    retries: int = 2,
) -> LayoutResult:
    """Make and solve layout ``layout_index`` of the dataset of ``seed`` (a pure task).

    Args:
        seed: the dataset seed (non-negative).
        layout_index: the layout's index in the dataset.
        engine: physics engine name.
        n_sources: sources per layout (4 in the paper).
        layout_kwargs: options of :func:`~dgse.world.generate.random_layout`
            (e.g. ``width_range=(3, 3.5)``).
        retries: further attempts with fresh draws after a failed one (the
            reasons of failed attempts are kept in ``meta["generation"]``).

    Returns:
        A :class:`LayoutResult` with ``n_sources`` cases named
        ``layout-<index>_src<k>`` (``meta["generation"]`` records seed, index and
        attempt), or with a failure record ``{layout_index, layout_id, seed,
        entropy, error, reason, attempts}``.  Only :class:`DGSEError` is turned
        into a failure; anything else (a bug) propagates.
    """
    from dgse.physics.scenario import solve_cases
    from dgse.world.generate import random_inlet_velocity, random_layout, random_sources

    t0, c0 = time.perf_counter(), time.process_time()
    lid = layout_id_for(layout_index)
    kwargs = dict(layout_kwargs or {})
    attempts: list[dict[str, Any]] = []
    for attempt in range(int(retries) + 1):
        ss = layout_seed(seed, layout_index, attempt)
        rng = np.random.default_rng(ss)
        try:
            layout = random_layout(rng, name=lid, **kwargs)
            v_in = random_inlet_velocity(rng)
            sources = random_sources(layout, rng, n=n_sources)
            cases = solve_cases(layout, v_in, sources, engine, name=lid)
        except DGSEError as e:
            attempts.append(
                {"attempt": attempt, "entropy": list(ss.entropy), "error": type(e).__name__, "reason": str(e)}
            )
            continue
        gen: dict[str, Any] = {
            "seed": int(seed),
            "layout_index": int(layout_index),
            "attempt": attempt,
            "entropy": list(ss.entropy),
        }
        if attempts:
            gen["failed_attempts"] = attempts
        cases = [c.with_meta(generation=gen) for c in cases]
        return LayoutResult(
            layout_index, lid, cases, None, time.perf_counter() - t0, time.process_time() - c0
        )
    last = attempts[-1]
    failure = {
        "layout_index": int(layout_index),
        "layout_id": lid,
        "seed": int(seed),
        "entropy": last["entropy"],
        "error": last["error"],
        "reason": last["reason"],
        "attempts": attempts,
    }
    return LayoutResult(layout_index, lid, None, failure, time.perf_counter() - t0, time.process_time() - c0)


@dataclass
class GenerationReport:
    """The outcome of :func:`generate`.

    Attributes:
        path: the store.
        n_requested: layouts asked for.
        n_before: layout indices already done (stored, staged or failed) at the start.
        n_new: layouts made and stored by this run.
        n_failed_new: layouts that failed in this run.
        n_layouts: layouts in the store at the end.
        n_failures: failure records in the store at the end.
        splits: layouts per split at the end.
        seconds: wall time of the run.
        first_result_s: seconds from the start of the run to its first result
            (cluster start-up and the first layout), None when nothing ran.
        solve_seconds: summed task wall times of this run's layouts.
        cpu_seconds: summed task CPU times (of the worker processes).
        complete: every requested index is stored or recorded as failed.
    """

    path: Path
    n_requested: int
    n_before: int
    n_new: int = 0
    n_failed_new: int = 0
    n_layouts: int = 0
    n_failures: int = 0
    splits: dict[str, int] = field(default_factory=dict)
    seconds: float = 0.0
    first_result_s: float | None = None
    solve_seconds: float = 0.0
    cpu_seconds: float = 0.0
    complete: bool = False

    @property
    def layouts_per_minute(self) -> float:
        """Layouts made by this run per minute of wall time."""
        done = self.n_new + self.n_failed_new
        return 60.0 * done / self.seconds if self.seconds > 0 else math.nan


def _default_workers() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def _check_layout_kwargs(layout_kwargs: Mapping[str, Any]) -> dict[str, Any]:
    """Validate options of ``random_layout`` (names, JSON-ability, a trial draw)."""
    from dgse.world.generate import random_layout

    params = inspect.signature(random_layout).parameters
    allowed = sorted(k for k in params if k not in ("rng_or_seed", "name"))
    unknown = sorted(set(layout_kwargs) - set(allowed))
    if unknown:
        raise InputDataError(f"unknown layout option(s) {', '.join(unknown)}; known: {', '.join(allowed)}")
    try:
        normal = json.loads(json.dumps(dict(layout_kwargs)))
    except (TypeError, ValueError) as e:
        raise InputDataError(f"layout options must be plain numbers/lists: {e}") from None
    random_layout(np.random.default_rng(0), name="check", **layout_kwargs)  # raises InputDataError
    return normal


@contextlib.contextmanager
def _sigint_ignored() -> Iterator[None]:
    """SIGINT ignored while the block starts the local cluster, so its worker processes are born
    ignoring it (an ignored signal stays ignored across ``exec``).

    Ctrl-C in a terminal reaches every process of the foreground group; a worker that took it
    would die printing its traceback.  Ignoring it, only this process stops, and it closes the
    workers itself.  A Ctrl-C while the workers start is lost (it takes a few seconds; press
    it again).
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


@contextlib.contextmanager
def _dask_client(scheduler: Any, workers: int, connect_timeout: float) -> Iterator[Any]:
    """A ``distributed.Client``: on a new LocalCluster, or on ``scheduler`` (address or Client)."""
    try:
        from distributed import Client, LocalCluster
    except ImportError as e:  # pragma: no cover - a dependency
        raise ClusterError(f"dataset generation needs dask[distributed] ({e})") from None
    if scheduler is not None and not isinstance(scheduler, str):
        yield scheduler  # an existing Client: used, not closed
        return
    cluster = None
    try:
        if scheduler is None:
            try:
                with _sigint_ignored():
                    cluster = LocalCluster(
                        n_workers=workers,
                        threads_per_worker=1,
                        processes=True,
                        dashboard_address=None,
                        scheduler_kwargs={"dashboard": False},
                        silence_logs=logging.ERROR,
                    )
                    client = Client(cluster)
            except (RuntimeError, OSError) as e:
                raise ClusterError(
                    f"cannot start a local Dask cluster of {workers} workers: {e} (scripts "
                    "that call generate() need an `if __name__ == '__main__':` guard)"
                ) from None
        else:
            try:
                client = Client(scheduler, timeout=connect_timeout)
            except (OSError, TimeoutError, ValueError) as e:
                raise ClusterError(
                    f"cannot reach the Dask scheduler at {scheduler!r} within {connect_timeout:g} s: {e}"
                ) from None
            try:
                client.wait_for_workers(1, timeout=connect_timeout)
            except (TimeoutError, OSError) as e:
                client.close()
                raise ClusterError(
                    f"the Dask scheduler at {scheduler!r} has no workers (waited {connect_timeout:g} s): {e}"
                ) from None
        try:
            yield client
        finally:
            with _quiet_distributed(), contextlib.suppress(Exception):
                client.close()
    finally:
        if cluster is not None:
            with _quiet_distributed(), contextlib.suppress(Exception):
                cluster.close()


@contextlib.contextmanager
def _quiet_distributed() -> Iterator[None]:
    """distributed's loggers silent (a cluster closed on Ctrl-C reports its cancelled tasks)."""
    logger = logging.getLogger("distributed")
    level = logger.level
    logger.setLevel(logging.CRITICAL + 1)
    try:
        yield
    finally:
        logger.setLevel(level)


@contextlib.contextmanager
def _generation_lock(out: Path) -> Iterator[None]:
    """Hold ``<store>.lock`` (flock) for the run: one generator per store at a time.

    The lock file stays beside the store; the kernel releases the lock when the
    process ends, however it ends.
    """
    import fcntl

    lock_path = out.with_name(out.name + ".lock")
    lock_path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(lock_path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise InputDataError(f"{out} is being generated by another process (lock {lock_path})") from None
        try:
            yield
        finally:
            if not out.exists():  # nothing was made (e.g. no cluster): leave no lock file
                lock_path.unlink(missing_ok=True)
    finally:
        os.close(fd)


def _read_state(out: Path, info: dict[str, Any], retry_failed: bool) -> tuple[set[int], int]:
    """Indices already done (stored, staged, failed unless retried) and the failure count.

    Commits the journal left by an interrupted run first; refuses a store made
    with other generation parameters.
    """
    with DatasetStore(out, "r") as s:
        old = s.generation_info
        if not old:
            raise InputDataError(
                f"{out} was not made by `generate` (no generation parameters); use a new --out"
            )
        diff = [k for k in _COMPAT_KEYS if old.get(k) != info.get(k)]
        if diff:
            was = ", ".join(f"{k}={old.get(k)!r}" for k in diff)
            now = ", ".join(f"{k}={info.get(k)!r}" for k in diff)
            raise InputDataError(
                f"{out} was generated with {was}; this run asks for {now}. Resume with the "
                "same parameters, or write to a new store"
            )
    commit_pending(out)
    with DatasetStore(out, "r") as s:
        done = s.layout_indices()
        failed = s.failed_indices()
    return (done if retry_failed else done | failed), len(failed)


def _finalize(out: Path, seed: int, configs_per_env: int) -> None:
    """Commit the journal, then draw the fixed val/test configurations if missing."""
    commit_pending(out)
    with DatasetStore(out, "r") as s:
        missing = [sp for sp in ("val", "test") if not s.has_fixed_configurations(sp)]
    if missing:

        def draw(store: DatasetStore) -> None:
            for sp in missing:
                store.fixed_configurations(sp, n_per_env=configs_per_env, seed=seed)

        commit_pending(out, finalize=draw)


def generate(
    n_layouts: int,
    out: str | Path,
    engine: str = "builtin",
    workers: int | None = None,
    scheduler: Any = None,
    seed: int = 0,
    progress: bool = True,
    *,
    n_sources: int = 4,
    retries: int = 2,
    retry_failed: bool = False,
    split_fractions: Mapping[str, float] | None = None,
    configs_per_env: int = DEFAULT_CONFIGS_PER_ENV,
    checkpoint_s: float = 60.0,
    connect_timeout: float = 5.0,
    only_splits: Sequence[str] | None = None,
    on_start: Callable[[int, int], None] | None = None,
    **layout_kwargs: Any,
) -> GenerationReport:
    """Generate (or finish generating) a dataset store of ``n_layouts`` layouts.

    Args:
        n_layouts: layouts in the dataset (3750 in the paper), indices ``0..n-1``.
        out: the store file (created if missing; resumed if it exists).
        engine: physics engine; checked before any work.
        workers: processes of the local cluster (1 thread each); default: the
            number of usable CPUs.  Ignored with ``scheduler``.
        scheduler: address of an existing Dask scheduler (``tcp://host:8786``) or
            a ``distributed.Client``; the workers must be able to import ``dgse``.
        seed: dataset seed (non-negative): layouts, splits and fixed sensor
            configurations all derive from it.
        progress: show a progress bar (rich).
        n_sources: sources per layout (4 in the paper).
        retries: fresh draws (``SeedSequence((seed, index, attempt))``) to try
            after a failed layout before recording it as failed.
        retry_failed: submit the layouts recorded as failed again.
        split_fractions: train/val/test shares (default 0.8/0.1333/0.0667).
        configs_per_env: fixed sensor configurations per val/test environment.
        checkpoint_s: least seconds between commits of the journal into the store.
        connect_timeout: seconds to wait for the scheduler and its first worker.
        only_splits: make only the layouts these splits get (e.g. ``["test"]``: a
            dataset's test scenarios without its training set).  The layouts are the
            same as in the whole dataset; running again without it completes the store.
        on_start: called as ``on_start(todo, workers)`` once every argument is checked and
            the store is read, before the cluster starts: the layouts this run makes and
            the local workers (ignored with ``scheduler``).
        **layout_kwargs: options of :func:`~dgse.world.generate.random_layout`, e.g.
            ``width_range=(3, 3.5), height_range=(3, 3.5)`` for tiny layouts.

    Returns:
        A :class:`GenerationReport`.

    Raises:
        UnsupportedError: unknown or unavailable engine (before any work).
        InputDataError: bad arguments, or a store made with other parameters.
        ClusterError: unreachable scheduler, a cluster that cannot start.
    """
    from dgse.physics.engines import get_engine

    t_start = time.perf_counter()
    if isinstance(n_layouts, bool) or not isinstance(n_layouts, int) or n_layouts < 1:
        raise _argument_error("n_layouts", f"must be a positive integer, got {n_layouts!r}")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise _argument_error("seed", f"must be a non-negative integer, got {seed!r}")
    if n_sources < 1:
        raise _argument_error("n_sources", f"must be at least 1, got {n_sources}")
    if retries < 0:
        raise _argument_error("retries", f"must be >= 0, got {retries}")
    workers = _default_workers() if workers is None else int(workers)
    if workers < 1:
        raise _argument_error("workers", f"must be at least 1, got {workers}")
    if not checkpoint_s >= 0:
        raise _argument_error("checkpoint_s", f"must be >= 0, got {checkpoint_s!r}")
    if not connect_timeout > 0:
        raise _argument_error("connect_timeout", f"must be positive, got {connect_timeout!r}")
    get_engine(engine)  # UnsupportedError, clear, before any work
    kwargs = _check_layout_kwargs(layout_kwargs)
    fractions = _check_fractions(split_fractions)
    wanted_splits = _check_only_splits(only_splits)
    out = Path(out)
    info = {
        "seed": seed,
        "n_layouts": n_layouts,
        "n_sources": int(n_sources),
        "engine": engine,
        "layout_kwargs": kwargs,
        "split_fractions": fractions,
        "configs_per_env": int(configs_per_env),
    }
    if not out.exists():
        check_store_path(out)
    elif out.is_dir():
        raise InputDataError(f"{out} is a directory; give the dataset store's file name")
    with _generation_lock(out):
        done, _ = _read_state(out, info, retry_failed) if out.exists() else (set(), 0)
        splits = assign_splits(n_layouts, seed, fractions)
        todo = [i for i in range(n_layouts) if i not in done and splits[i] in wanted_splits]
        report = GenerationReport(out, n_layouts, n_before=len(done))
        if on_start is not None:
            on_start(len(todo), workers)
        if todo:
            with _dask_client(scheduler, workers, connect_timeout) as client:
                if not out.exists():
                    create_store(out, {**info, "created_by": "dgse.data.generation.generate"})
                _run(
                    client,
                    out,
                    todo,
                    splits,
                    info,
                    retries,
                    checkpoint_s,
                    progress,
                    report,
                    t_start,
                )
        _finalize(out, seed, configs_per_env)
    with DatasetStore(out, "r") as s:
        report.n_layouts = len(s)
        report.n_failures = len(s.failures())
        report.splits = {sp: len(ids) for sp, ids in s.splits.items()}
        stored = s.layout_indices() | s.failed_indices()
    report.complete = all(i in stored for i in range(n_layouts))
    report.seconds = time.perf_counter() - t_start
    return report


def _argument_error(name: str, problem: str) -> InputDataError:
    """``<name> <problem>``, the argument spelled as each front end spells it."""
    return InputDataError(f"{{{name}}} {problem}", names={name: name})


def stored_layouts(out: str | Path) -> int:
    """The layouts a store holds, made or recorded as failed (0 when there is no store yet)."""
    out = Path(out)
    if not out.is_file():
        return 0
    with DatasetStore(out, "r") as s:
        return len(s.layout_indices() | s.failed_indices())


def _check_only_splits(only_splits: Sequence[str] | None) -> set[str]:
    if only_splits is None:
        return set(SPLITS)
    if isinstance(only_splits, str):
        only_splits = [only_splits]
    wanted = set(only_splits)
    unknown = sorted(wanted - set(SPLITS))
    if not wanted or unknown:
        raise InputDataError(
            f"unknown split(s) {', '.join(unknown) or '(none given)'}: the splits are {', '.join(SPLITS)}"
        )
    return wanted


def _run(
    client: Any,
    out: Path,
    todo: list[int],
    splits: list[str],
    info: dict[str, Any],
    retries: int,
    checkpoint_s: float,
    progress: bool,
    report: GenerationReport,
    t_start: float,
) -> None:
    """Submit the tasks, stage results as they complete, commit now and then."""
    from distributed import as_completed
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        SpinnerColumn,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )
    from rich.text import Text

    journal = Journal(out)
    # the options go through a partial: Client.submit has keywords of its own (retries, ...)
    task = functools.partial(
        solve_layout,
        n_sources=info["n_sources"],
        layout_kwargs=info["layout_kwargs"],
        retries=retries,
    )
    futures = {}
    for i in todo:
        futures[client.submit(task, info["seed"], i, info["engine"], pure=False)] = i
    last_commit = time.monotonic()
    commit_cost = 0.0
    n_total = report.n_before + len(todo)  # fewer than n_layouts with only_splits
    columns = (
        SpinnerColumn(),
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[failed]}"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
    )
    console = Console(stderr=True)
    with (
        # without a terminal the bar would only print its last state
        Progress(*columns, console=console, disable=not (progress and console.is_terminal)) as bar,
        _stop_requests() as stop,
    ):
        bar_task = bar.add_task("layouts", total=n_total, completed=n_total - len(todo), failed="")
        try:
            for fut in _completed(as_completed(list(futures)), stop):
                i = futures.pop(fut)
                if report.first_result_s is None:
                    report.first_result_s = time.perf_counter() - t_start
                try:
                    res: LayoutResult = fut.result()
                except Exception as e:  # a worker died, or a bug: record, go on
                    res = LayoutResult(
                        i,
                        layout_id_for(i),
                        None,
                        {
                            "layout_index": i,
                            "layout_id": layout_id_for(i),
                            "seed": info["seed"],
                            "entropy": list(layout_seed(info["seed"], i).entropy),
                            "error": type(e).__name__,
                            "reason": f"unexpected error in the task: {e}",
                            "unexpected": True,
                        },
                        0.0,
                    )
                fut.release()
                if res.cases is not None:
                    journal.add_layout(res.cases, splits[i], res.layout_id, i)
                    report.n_new += 1
                else:
                    assert res.failure is not None
                    journal.add_failure(res.failure)
                    report.n_failed_new += 1
                    bar.console.print(
                        Text(
                            f"{res.layout_id}: {res.failure['error']}: {res.failure['reason']}",
                            style="yellow",
                        )
                    )
                report.solve_seconds += res.seconds
                report.cpu_seconds += res.cpu_seconds
                failed = f"[red]{report.n_failed_new} failed[/]" if report.n_failed_new else ""
                bar.update(bar_task, advance=1, failed=failed)
                now = time.monotonic()
                if now - last_commit >= max(checkpoint_s, 20.0 * commit_cost):
                    commit_pending(out)
                    commit_cost = time.monotonic() - now
                    last_commit = time.monotonic()
        except KeyboardInterrupt:
            bar.live.transient = True  # the caller says what was kept; the bar goes
            raise
        finally:
            for fut in futures:
                fut.cancel()
            commit_pending(out)
        if stop.is_set():
            bar.live.transient = True
            raise KeyboardInterrupt  # after the finished layouts were committed


def _completed(pending: Any, stop: threading.Event, poll_s: float = 0.2) -> Iterator[Any]:
    """The futures of a ``distributed.as_completed`` as they finish, until ``stop`` is set (polled)."""
    while not pending.is_empty():
        if stop.is_set():
            return
        batch = pending.next_batch(block=False)
        if not batch:
            time.sleep(poll_s)
            continue
        for fut in batch:
            yield fut
            if stop.is_set():
                return


@contextlib.contextmanager
def _stop_requests() -> Iterator[threading.Event]:
    """Ctrl-C (SIGINT) and SIGTERM set the yielded event instead of raising wherever Python runs.

    Dask runs callbacks (weakref finalizers, its event loop) in the main
    thread too; a ``KeyboardInterrupt`` raised inside one of them is printed as
    "Exception ignored" and lost, so generation would go on.  The loop checks
    the event after every finished layout, commits what it has and then
    raises ``KeyboardInterrupt``.  A second Ctrl-C raises at once.
    """
    stop = threading.Event()
    if threading.current_thread() is not threading.main_thread():
        yield stop
        return

    def request(signum: int, frame: Any) -> None:
        if stop.is_set():
            raise KeyboardInterrupt
        stop.set()

    previous = {s: signal.signal(s, request) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield stop
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
