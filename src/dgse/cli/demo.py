"""``dgse demo``: the main job, end to end, with nothing but the package installed.

1. draw a random multi-room scenario of the training distribution and solve
   its flow and one gas release with the built-in solver;
2. run one active search with the method for the knowledge given (``--knowledge``;
   :data:`dgse.presets.DEFAULT_METHOD`: ``dgse-phys`` at every level) and its preset's
   planner (:func:`dgse.presets.resolve`: the information planner for dgse-phys, the
   utility planner of paper Algorithm 1 with the entropy test from the 5th reading on for
   DGSE-S given with ``--method``), the robot starting at least 2 m from the source,
   showing the step, the simulated clock, the entropy and the error as it goes;
3. print the outcome and write the case figure, the final belief, the last
   search step and the animation of the search into the output folder.
"""

from __future__ import annotations

import math
import secrets
import time
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.markup import escape
from rich.table import Table

from dgse.belief.knowledge import DEFAULT_LEVEL, check_level, require_level
from dgse.cli.common import (
    NOTHING_KEPT,
    KnowledgeOption,
    TimeLimitOption,
    check_output_dir,
    console,
    interruptible,
    path_text,
    user_errors,
)
from dgse.errors import InputDataError
from dgse.files import atomic_path
from dgse.presets import PROTOCOL

if TYPE_CHECKING:
    from dgse.search.episode import StepRecord

__all__ = ["demo_cmd", "register", "step_text"]


def _told(level: str) -> str:
    return {
        "map": "the map only",
        "openings": "the map, its inlets and outlets",
        "wind": "the map, its openings and the mean wind field (as from the user's CFD)",
    }[level]


def step_text(rec: StepRecord, time_limit: float, stop: str) -> str:
    """The search status line after step ``rec``: step, simulated clock, entropy, error.

    ``stop``: the planner's stop test in words (:meth:`~dgse.planning.planners.Planner.describe_stop`).
    """
    return (
        f"searching: step {rec.step}, {rec.time_s:.0f} of {time_limit:g} s simulated, "
        f"entropy {rec.normalized_entropy:.2f} of log N (stops when {stop}), error {rec.error_m:.2f} m"
    )


@user_errors
def demo_cmd(
    seed: Annotated[int | None, typer.Option("--seed", "-s", help="Scenario seed (default: fresh).")] = None,
    out: Annotated[Path, typer.Option("--out", "-o", help="Folder for the figures.")] = Path("dgse-out"),
    model: Annotated[
        str, typer.Option("--model", help="DGSE-S weights: default (shipped) or a .safetensors path.")
    ] = "default",
    time_limit: TimeLimitOption = PROTOCOL.time_limit,
    eta: Annotated[
        float | None,
        typer.Option(
            "--eta",
            help="Entropy termination H <= eta log N.  Default: 0.78 for the shipped DGSE-S, tuned on "
            "the validation split (benchmarks/training.py eta; its posteriors are broader than the paper's), "
            "else the paper's 0.65.",
        ),
    ] = None,
    animate: Annotated[bool, typer.Option("--animate/--no-animate", help="Write the GIF.")] = True,
    threads: Annotated[int, typer.Option("--threads", help="PyTorch CPU threads.")] = 1,
    knowledge: KnowledgeOption = DEFAULT_LEVEL,
    method: Annotated[
        str | None,
        typer.Option("--method", "-m", help="Estimator (default: the demo's method for --knowledge)."),
    ] = None,
) -> None:
    """Solve a random scenario and find its gas source with the method for the knowledge given."""
    level = check_level(knowledge)
    check_output_dir(out)
    if not (math.isfinite(time_limit) and time_limit > 0):
        raise InputDataError(f"--time-limit must be a positive number of seconds, got {time_limit:g}")
    if eta is not None and not (math.isfinite(eta) and 0 < eta <= 1):
        raise InputDataError(f"--eta must be in (0, 1], got {eta:g}")
    if threads < 1:
        raise InputDataError(f"--threads must be at least 1, got {threads}")
    import torch

    from dgse.estimators.registry import ESTIMATORS, get_estimator
    from dgse.physics.scenario import random_cases
    from dgse.planning.planners import PLANNERS, get_planner
    from dgse.presets import resolve
    from dgse.search.episode import run_episode
    from dgse.search.metrics import episode_metrics
    from dgse.viz.case import plot_case
    from dgse.viz.search import animate_episode, plot_search_step

    torch.set_num_threads(max(1, threads))
    seed = secrets.randbelow(2**31) if seed is None else seed
    t0 = time.perf_counter()
    run = resolve(method, level, search=True)
    if eta is not None:  # the utility planner's stop.eta, another planner's own eta
        key = "stop.eta" if PLANNERS.accepts(run.planner, "stop.eta") else "eta"
        run = resolve(method, level, search=True, planner_options={key: eta})
    method = run.method  # without --method: the level's default method
    kwargs = dict(run.estimator_options)
    if ESTIMATORS.accepts(run.estimator, "model"):
        kwargs["model"] = model
    elif model != "default":
        raise InputDataError(f"--model applies to the DGSE networks, not to {method}")
    estimator = get_estimator(run.estimator, **kwargs)
    require_level(estimator, method, level)
    planner = get_planner(run.planner, **run.planner_options)
    stop_at = planner.describe_stop()
    written: list[Path] = []

    def kept() -> str:
        if not written:
            return NOTHING_KEPT
        names = ", ".join(p.name for p in written)
        return f"{names} written into {out}; the demo does not resume: run the command again"

    with interruptible(kept):
        with console.status("solving a random multi-room scenario (built-in RANS + gas transport)"):
            case = random_cases(seed, n_sources=1)[0]
        t_solve = time.perf_counter() - t0
        g = case.grid
        console.print(
            f"scenario seed {seed}: {g.width_m:g} x {g.height_m:g} m, inlet {case.inlet_velocity:.2f} m/s, "
            f"source at ({case.source[0]:.2f}, {case.source[1]:.2f}) m releasing {case.release_rate:.2f} g/s "
            f"[dim](solved in {t_solve:.1f} s)[/]"
        )
        console.print(f"method {escape(method)}, knowledge {level}: {escape(_told(level))}")
        with console.status(f"searching: sense, estimate ({escape(method)}), plan, move") as status:
            result = run_episode(
                case,
                estimator,
                planner,
                rng=seed,
                time_limit=time_limit,
                min_start_distance=PROTOCOL.min_start_distance,
                on_step=lambda rec: status.update(step_text(rec, time_limit, stop_at)),
                knowledge=level,
            )
        m = episode_metrics(result)
        table = Table(title="active search", title_justify="left", show_header=False)
        table.add_row("outcome", "[green]success[/]" if m["success"] else "[red]failure[/]")
        table.add_row("ended by", result.reason)
        table.add_row("estimate", f"({result.estimate_xy[0]:.2f}, {result.estimate_xy[1]:.2f}) m")
        table.add_row("localization error", f"{result.error_m:.2f} m")
        table.add_row("search time", f"{result.search_time_s:.0f} s ({len(result.steps)} measurements)")
        table.add_row(
            "travelled",
            f"{result.distance_m:.1f} m (path efficiency ratio {m['per']:.2f}: travelled / shortest path)",
        )
        table.add_row("one step", f"{1e3 * m['step_seconds']:.0f} ms of computation")
        console.print(table)
        out.mkdir(parents=True, exist_ok=True)
        written.append(case.save(out / f"{case.name}.npz"))
        fig = plot_case(case)
        with atomic_path(out / f"{case.name}.png") as tmp:
            fig.savefig(tmp, dpi=110)
        written.append(out / f"{case.name}.png")
        with atomic_path(out / "search_final.png") as tmp:
            plot_search_step(result, case, -1).savefig(tmp, dpi=110)
        written.append(out / "search_final.png")
        if animate:
            with console.status("writing the animation"):
                written.append(animate_episode(result, case, out / "search.gif", max_frames=30, dpi=70))
        console.print(
            f"wrote {', '.join(path_text(p.name) for p in written)} into [cyan]{path_text(out)}[/] "
            f"[dim](total {time.perf_counter() - t0:.0f} s)[/]"
        )


def register(app: typer.Typer) -> None:
    """Add ``dgse demo`` to ``app``."""
    app.command("demo")(demo_cmd)
