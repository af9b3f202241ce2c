"""The ``dgse bench`` and ``dgse report`` commands: the paper's experiments and their report.

``dgse bench SUITE [SUITE ...] [--quick] --out DIR [--data STORE] [--seed S]``
runs suites (:mod:`dgse.bench`; ``all`` for every one) into ``DIR/<suite>/``;
``dgse report DIR [-o FILE]`` writes ``DIR/summary.md`` from the suites' result files
(:mod:`dgse.bench.summary`) and the self-contained HTML page (``DIR/report.html`` by default)
that shows it first.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import typer
from rich.markup import escape

from dgse.cli.common import (
    KnowledgeOption,
    ProgressOption,
    ThreadsOption,
    check_output_dir,
    check_output_file,
    console,
    interruptible,
    path_text,
    resume_command,
    user_errors,
)
from dgse.errors import InputDataError

__all__ = ["bench_cmd", "register", "report_cmd"]


@user_errors
def bench_cmd(
    ctx: typer.Context,
    suites: Annotated[
        list[str],
        typer.Argument(
            metavar="SUITE...",
            help="variants, gdm, gsl, search, samples, calibration, field, or all.",
        ),
    ],
    out: Annotated[Path, typer.Option("--out", "-o", help="Output directory.")],
    quick: Annotated[
        bool, typer.Option("--quick/--full", help="Small runs (CI); --full is the paper's size.")
    ] = False,
    data: Annotated[
        Path | None,
        typer.Option(
            "--data",
            "-d",
            exists=True,
            dir_okay=False,
            help="Dataset store whose test split gives the scenarios.",
        ),
    ] = None,
    seed: Annotated[int, typer.Option("--seed", "-s", help="Seed of scenarios and trials.")] = 0,
    threads: ThreadsOption = None,
    report: Annotated[
        bool, typer.Option("--report/--no-report", help="Also write DIR/summary.md and DIR/report.html.")
    ] = True,
    progress: ProgressOption = True,
    knowledge: KnowledgeOption = "map",
) -> None:
    """Run benchmark suites that reproduce the paper's experiments (JSON, CSV, PNG per suite).

    Every method is told the same --knowledge; methods that do not work at that level are
    left out and named in the suite's notes.
    """
    from dgse.belief.knowledge import check_level
    from dgse.bench import SUITES, run_suite

    check_level(knowledge)

    names = list(SUITES) if "all" in suites else list(dict.fromkeys(suites))
    unknown = [s for s in names if s not in SUITES]
    if unknown:
        raise InputDataError(
            f"unknown suite(s) {', '.join(unknown)}; the suites are: {', '.join(SUITES)}, all"
        )
    check_output_dir(out)
    if threads is not None:
        if threads < 1:
            raise InputDataError(f"--threads must be at least 1, got {threads}")
        import torch

        torch.set_num_threads(threads)

    def kept() -> str:  # every suite keeps its finished results in its folder and reuses them
        return f"the finished results are kept in {out}; resume with: {resume_command(ctx)}"

    with interruptible(kept):
        for name in names:
            t0 = time.perf_counter()
            console.print(
                f"[bold]{escape(name)}[/]: {escape(SUITES.entry(name).display)}{' (quick)' if quick else ''}"
            )
            manifest = run_suite(
                name, out, quick=quick, data=data, seed=seed, knowledge=knowledge, progress=progress
            )
            console.print(
                f"  done in {time.perf_counter() - t0:.1f} s: [cyan]{path_text(manifest.parent)}[/]"
            )
    if report:
        from dgse.bench.report import write_report

        console.print(f"wrote report [cyan]{path_text(write_report(out))}[/]")


@user_errors
def report_cmd(
    directory: Annotated[Path, typer.Argument(metavar="DIR", help="Output directory of dgse bench.")],
    output: Annotated[
        Path | None, typer.Option("--out", "-o", "--output", help="HTML file (default DIR/report.html).")
    ] = None,
) -> None:
    """Write DIR/summary.md and one self-contained HTML page (figures embedded) from the results in DIR."""
    from dgse.bench.report import write_report

    check_output_file(output, "report")
    console.print(f"wrote report [cyan]{path_text(write_report(directory, output))}[/]")


def register(app: typer.Typer) -> None:
    """Attach ``bench`` and ``report`` to ``app``."""
    app.command("bench")(bench_cmd)
    app.command("report")(report_cmd)
