"""The ``dgse search`` command: active gas source search trials with a simulated robot.

``dgse search CASES_DIR_OR_CASE --method dgse-s --trials 20 --seed 0 [-o out.json]``
runs ``--trials`` episodes (:func:`dgse.search.episode.run_episode`) per case
with the estimator ``--method`` (any registered name, built by
:func:`~dgse.estimators.registry.get_estimator`) and the planner ``--planner``
(:func:`~dgse.planning.planners.get_planner`), prints a table of the paper's
metrics per case and over all trials, and writes them as JSON (the loop is
:func:`dgse.search.campaign.run_trials`; the JSON is what it returns):

* ``per_case``: one entry per case: ``case``, ``file``, ``metrics`` (the
  :func:`~dgse.search.metrics.aggregate` of its trials) and ``trials`` (each
  episode's summary and metrics);
* ``aggregate``: the aggregate over all trials of all cases (``success_rate``,
  ``error_m_mean``, ``search_time_s_mean``, ``distance_m_mean``,
  ``step_seconds_mean``, ``per_mean``, ... with ``_std`` and ``_median``);
* ``settings``: the command's settings.

Seeds: trial ``r`` of the case file ``<stem>.npz`` uses
``SeedSequence([seed, crc32(stem), r])``, so the start cells (and sensor
noise) do not depend on the method, the planner or the other cases.

``--sample-rate HZ``: the robot also reads every ``1/HZ`` seconds while it drives to a
goal; those readings are estimated with the goal's, and the planner decides at the goals
(:mod:`dgse.search.episode`; recorded as ``sample_rate_hz`` in ``settings``).

``--animate DIR`` also writes ``DIR/<stem>.gif`` for trial 0 of every case:
the trajectory, measurements and the predicted wind, concentration and
source posterior over the steps (:mod:`dgse.viz.search`).

For DGSE methods (``dgse-*``) the estimator gets ``model=`` (``--model``,
default ``"default"``: the shipped weights) and ``seed=`` (``--seed``);
other methods get ``model=`` only when ``--model`` is given.
``-p/--param KEY=VALUE`` passes further estimator arguments (values parsed as
JSON when possible, e.g. ``-p K=5``; the same option as in ``dgse estimate``
and ``dgse evaluate``; ``-O/--option`` is a hidden alias kept for old
command lines), ``-P/--planner-option KEY=VALUE`` planner options.

Signs of life and keeping what was done: the progress bar shows the running
episode's step, simulated clock (of the time limit), normalized entropy and
current error; without a terminal (a log file, a pipe) one line per finished
episode is printed instead.  Every finished episode is kept at once in the
journal beside the JSON file (``out.json`` -> ``out.journal.jsonl``,
:func:`dgse.journal.journal_path`); without ``-o/--out`` (``--json`` is the
same option) the JSON file is ``dgse-out/search-<method>-<planner>.json``
(printed).  Ctrl-C (or SIGTERM) stops the run with one line: how many
episodes are kept, where, and the command that resumes the run (exit status
130).  Running the same command again skips the kept episodes and gives the
same JSON as an uninterrupted run (up to the measured computation times); a
run with other settings into the same file is refused (the error names the
difference): give another ``--out`` or ``--restart`` to discard the journal.

Every setting is checked (by :func:`~dgse.search.campaign.run_trials`) before
anything is printed; the summary table's abbreviations are spelled out under
it (:data:`LEGEND`).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer
from rich import box
from rich.markup import escape
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from dgse.belief.knowledge import DEFAULT_LEVEL, check_level
from dgse.cli.common import (
    DwellOption,
    FramesOption,
    KnowledgeOption,
    MethodOption,
    MinStartDistanceOption,
    ParamOption,
    SampleRateOption,
    SpeedOption,
    ThreadsOption,
    TimeLimitOption,
    check_output_dir,
    check_output_file,
    console,
    default_output,
    interruptible,
    journal_output,
    kept_note,
    parse_params,
    path_text,
    restart_option,
    resume_command,
    resume_note,
    user_errors,
)
from dgse.errors import InputDataError
from dgse.files import json_safe, write_json
from dgse.journal import count_records, journal_path
from dgse.presets import PROTOCOL

if TYPE_CHECKING:
    from dgse.search.episode import EpisodeResult, StepRecord
    from dgse.world.case import Case

__all__ = [
    "register",
    "search_cmd",
]


def _step_text(stem: str, trial: int, trials: int, rec: StepRecord, time_limit: float) -> str:
    return (
        f"{stem} trial {trial + 1}/{trials}: step {rec.step}, {rec.time_s:.0f}/{time_limit:g} s, "
        f"H {rec.normalized_entropy:.2f}, error {rec.error_m:.2f} m"
    )


def _table(rows: list[tuple[str, dict[str, Any]]], title: str) -> Table:
    from dgse.search.metrics import format_mean_std

    t = Table(title=title, title_justify="left", box=box.SIMPLE_HEAD)
    t.add_column("case", no_wrap=True)
    for col in ("trials", "SR [%]", "error [m]", "ST [s]", "TD [m]", "step [ms]", "PER"):
        t.add_column(escape(col), justify="right", overflow="fold")  # a narrow terminal folds, never cuts
    for i, (name, agg) in enumerate(rows):
        sr = agg.get("success_rate")
        step_ms = {k: v * 1e3 for k, v in agg.items() if k.startswith("step_seconds") and v is not None}
        t.add_row(
            escape(name),
            str(agg["n_trials"]),
            "-" if sr is None else f"{100 * sr:.0f}",
            format_mean_std(agg, "error_m", ".2f"),
            format_mean_std(agg, "search_time_s", ".1f"),
            format_mean_std(agg, "distance_m", ".2f"),
            format_mean_std(step_ms, "step_seconds", ".3g"),
            "-" if agg.get("per_mean") is None else f"{agg['per_mean']:.2f}",
            style="bold" if i == len(rows) - 1 and len(rows) > 1 else None,
            end_section=i == len(rows) - 2,
        )
    return t


def _write_json(path: Path, data: dict[str, Any]) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    return write_json(path, json_safe(data), indent=1, allow_nan=False)


# -- command -----------------------------------------------------------------------------
#: What the columns of the summary table stand for, printed under it.
LEGEND = (
    "SR success rate (error <= 2 m when the method stops), ST search time, TD travelled distance, "
    "PER path efficiency ratio = distance travelled / shortest path from the start to the source; "
    "mean (std)"
)


def _episode_line(stem: str, trial: int, trials: int, result: EpisodeResult) -> str:
    """One line per finished episode, for a log without a terminal."""
    from dgse.search.metrics import is_success

    outcome = "found" if is_success(result) else "not found"
    return (
        f"{stem} trial {trial + 1}/{trials}: {outcome} ({result.reason}), error {result.error_m:.2f} m, "
        f"{result.search_time_s:.0f} s, {result.distance_m:.1f} m, {len(result.steps)} measurements"
        + (f" ({result.n_readings} readings)" if result.n_readings != len(result.steps) else "")
    )


@user_errors
def search_cmd(
    ctx: typer.Context,
    cases_path: Annotated[
        Path,
        typer.Argument(metavar="CASES_DIR_OR_CASE", help="A case file or a directory of case files."),
    ],
    method: MethodOption = None,
    model: Annotated[
        str | None,
        typer.Option("--model", help="Network checkpoint, or 'default' (DGSE methods' default)."),
    ] = None,
    planner: Annotated[
        str | None,
        typer.Option("--planner", help="Planner (registered name; default: the method's, with its options)."),
    ] = None,
    trials: Annotated[int, typer.Option("--trials", "-r", help="Episodes per case.")] = 20,
    seed: Annotated[int, typer.Option("--seed", "-s", help="Seed of the start cells and noise.")] = 0,
    eta: Annotated[
        float | None,
        typer.Option("--eta", help="Entropy termination threshold of the utility planner (-P stop.eta=...)."),
    ] = None,
    time_limit: TimeLimitOption = PROTOCOL.time_limit,
    frames: FramesOption = True,
    speed: SpeedOption = PROTOCOL.speed,
    dwell: DwellOption = PROTOCOL.dwell,
    sample_rate_hz: SampleRateOption = PROTOCOL.sample_rate_hz,
    min_start_distance: MinStartDistanceOption = PROTOCOL.min_start_distance,
    start: Annotated[
        tuple[float, float] | None,
        typer.Option(
            "--start",
            metavar="X Y",
            help="Start every trial here, m (default: a case file's start_m, else drawn).",
        ),
    ] = None,
    compute_time: Annotated[
        bool,
        typer.Option(
            "--compute-time/--no-compute-time", help="Add the measured computation time to the clock."
        ),
    ] = False,
    out: Annotated[
        Path | None, journal_output("The metrics", "dgse-out/search-<method>-<planner>.json", "episodes")
    ] = None,
    restart: Annotated[bool, restart_option("episodes")] = False,
    animate: Annotated[
        Path | None,
        typer.Option("--animate", help="Write a GIF of trial 0 of every case into this directory."),
    ] = None,
    steps: Annotated[
        bool, typer.Option("--steps/--no-steps", help="Include every step of every trial in the JSON.")
    ] = False,
    param: ParamOption = None,
    option: Annotated[
        list[str] | None,
        typer.Option("--option", "-O", metavar="KEY=VALUE", hidden=True, help="Old name of --param."),
    ] = None,
    planner_option: Annotated[
        list[str] | None,
        typer.Option("--planner-option", "-P", metavar="KEY=VALUE", help="Planner option (repeatable)."),
    ] = None,
    threads: ThreadsOption = None,
    progress: Annotated[
        bool,
        typer.Option(
            "--progress/--no-progress",
            help="Show a progress bar (without a terminal: one line per finished episode).",
        ),
    ] = True,
    knowledge: KnowledgeOption = DEFAULT_LEVEL,
) -> None:
    """Run active source search trials and report success rate, error, search time, travelled
    distance, step time and path efficiency.

    Every finished episode is kept at once (in the journal beside the JSON
    file); after Ctrl-C or a kill, the same command resumes where it stopped.
    """
    from dgse.planning.planners import PLANNERS
    from dgse.presets import resolve
    from dgse.search.campaign import estimator_options, run_trials

    level = check_level(knowledge)
    if threads is not None and threads < 1:
        raise InputDataError(f"--threads must be at least 1, got {threads}")
    user_est = parse_params([*(option or []), *(param or [])], "--param")
    user_plan = parse_params(planner_option, "--planner-option")
    run = resolve(method, level, search=True, planner=planner, planner_options=user_plan)
    if eta is not None:  # the utility planner's stop.eta, another planner's own eta
        user_plan["stop.eta" if PLANNERS.accepts(run.planner, "stop.eta") else "eta"] = eta
        run = resolve(method, level, search=True, planner=planner, planner_options=user_plan)
    method, planner = run.method, run.planner
    chosen_model = {} if model is None else {"model": model}
    est_kwargs = estimator_options(
        run.estimator, seed=seed, options={**run.estimator_options, **chosen_model, **user_est}
    )
    plan_kwargs = run.planner_options
    names = (method, planner) if level == DEFAULT_LEVEL else (method, planner, level)
    out = out if out is not None else default_output("search", *names)
    journal = journal_path(out)
    check_output_file(out, "JSON file")
    check_output_file(journal, "journal")
    check_output_dir(animate, "animation folder")
    if threads is not None:
        import torch

        torch.set_num_threads(threads)

    gifs: list[Path] = []
    fresh = 0
    log_lines = progress and not console.is_terminal  # a log gets a line per episode, not a bar
    bar = Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        console=console,
        disable=not progress or log_lines,
        transient=True,
    )
    task = bar.add_task("episodes", total=None, start=False)
    state = {"done": 0, "total": 0}

    def started(kept: int, total: int) -> None:
        n_cases = total // trials
        console.print(
            f"searching {n_cases} case{'s' * (n_cases != 1)} x {trials} trials with "
            f"[bold]{escape(method)}[/] + [bold]{escape(planner)}[/] (knowledge {level}, seed {seed}, "
            f"time limit {time_limit:g} s)"
        )
        console.print(kept_note(journal, "episode", kept))
        state["total"] = total
        bar.update(task, total=total, completed=kept)
        bar.start_task(task)
        bar.start()

    def tick(description: str, done: int, total: int) -> None:
        state["done"] = done
        bar.update(task, description=escape(description), completed=done)

    def step(path: Path, trial: int, rec: StepRecord) -> None:
        within = min(rec.time_s / time_limit, 0.99)  # the bar creeps along the episode's clock
        text = _step_text(path.stem, trial, trials, rec, time_limit)
        bar.update(task, description=escape(text), completed=state["done"] + within)

    def finished(path: Path, case: Case, trial: int, result: EpisodeResult) -> None:
        nonlocal fresh
        fresh += 1
        if log_lines:
            console.print(escape(_episode_line(path.stem, trial, trials, result)), soft_wrap=True)
        if animate is not None and trial == 0:
            from dgse.viz.search import animate_episode

            gifs.append(animate_episode(result, case, animate / f"{path.stem}.gif"))

    def kept() -> str:
        return resume_note(count_records(journal), "episode", journal, resume_command(ctx))

    t_start = time.perf_counter()
    with interruptible(kept):
        try:
            data = run_trials(
                cases_path,
                run.estimator,
                planner,
                trials,
                seed,
                estimator_options=est_kwargs,
                planner_options=plan_kwargs,
                method=method,
                speed=speed,
                dwell=dwell,
                time_limit=time_limit,
                use_frames=frames,
                min_start_distance=min_start_distance,
                include_compute_time=compute_time,
                steps=steps,
                record_first=animate is not None,
                progress=tick,
                on_episode=finished,
                on_step=step if progress and not log_lines else None,
                on_start=started,
                journal=journal,
                restart=restart,
                knowledge=level,
                start_m=start,
                sample_rate_hz=sample_rate_hz,
            )
        finally:
            bar.stop()
    data["resolved"] = {**run.to_json(), "estimator_options": json_safe(est_kwargs)}
    table_rows = [(Path(c["file"]).stem, c["metrics"]) for c in data["per_case"]]
    table_rows.append(("all", data["aggregate"]))
    console.print(_table(table_rows, f"active search: {escape(method)} + {escape(planner)}"))
    console.print(f"[dim]{escape(LEGEND)}[/]")
    resumed = state["total"] - fresh
    console.print(
        f"{data['aggregate']['n_trials']} episodes in {time.perf_counter() - t_start:.1f} s"
        + (f" ({resumed} kept from an earlier run)" if resumed else "")
    )
    console.print(f"wrote metrics [cyan]{path_text(_write_json(out, data))}[/]")
    for g in gifs:
        console.print(f"wrote animation [cyan]{path_text(g)}[/]")


def register(app: typer.Typer) -> None:
    """Attach ``search`` to ``app`` (``dgse search``)."""
    app.command("search")(search_cmd)
