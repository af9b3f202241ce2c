"""Dataset commands: ``generate``, ``export``, ``import``, ``import-gaden[-scenario]``, ``stats``.

:func:`register` attaches them to the ``dgse`` command: ``generate``,
``export``, ``import``, ``import-gaden`` and ``import-gaden-scenario`` at the
top level, ``stats`` under a ``data`` group (``dgse data stats``).

Every error a user can cause (:class:`~dgse.errors.DGSEError`, or a file that
cannot be written) prints one red line ``error: <message>`` and exits with
status 2.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer
from rich.markup import escape
from rich.table import Table

from dgse.cli.common import (
    EngineOption,
    ProgressOption,
    check_output_dir,
    check_output_file,
    console,
    interruptible,
    new_app,
    path_text,
    resume_command,
    resume_note,
    user_errors,
)
from dgse.errors import InputDataError
from dgse.files import atomic_path, write_json

__all__ = [
    "export_cmd",
    "generate_cmd",
    "import_cmd",
    "import_gaden_cmd",
    "import_gaden_scenario_cmd",
    "register",
    "stats_cmd",
]


# -- commands ------------------------------------------------------------------------------------
@user_errors
def generate_cmd(
    ctx: typer.Context,
    n_layouts: Annotated[int, typer.Option("--layouts", "-n", help="Number of layouts (3750 in the paper).")],
    out: Annotated[
        Path, typer.Option("--out", "-o", help="Dataset store (.h5 or .hdf5) to create or resume.")
    ],
    engine: EngineOption = "builtin",
    workers: Annotated[
        int | None,
        typer.Option("--workers", "-w", help="Local worker processes (default: number of CPUs)."),
    ] = None,
    scheduler: Annotated[
        str | None,
        typer.Option("--scheduler", help="Address of an existing Dask scheduler (tcp://host:8786)."),
    ] = None,
    seed: Annotated[int, typer.Option("--seed", "-s", help="Dataset seed.")] = 0,
    size: Annotated[
        tuple[float, float] | None,
        typer.Option(
            "--size",
            metavar="MIN MAX",
            help="Range of the domain's width and height in m (default 5 10, the paper's).",
        ),
    ] = None,
    retries: Annotated[
        int, typer.Option("--retries", help="Fresh draws to try for a layout that fails.")
    ] = 2,
    retry_failed: Annotated[
        bool, typer.Option("--retry-failed", help="Try layouts recorded as failed again.")
    ] = False,
    checkpoint_s: Annotated[
        float,
        typer.Option("--checkpoint", help="Least seconds between commits into the store file."),
    ] = 60.0,
    progress: ProgressOption = True,
    split: Annotated[
        list[str] | None,
        typer.Option(
            "--split",
            help="Make only the layouts of this split (repeatable: train, val, test); the same layouts "
            "as in the whole dataset. Run again without it to complete the store.",
        ),
    ] = None,
) -> None:
    """Generate a dataset: random layouts x 4 sources, solved on a Dask cluster.

    Resumable: run the same command again after an interruption (even kill -9)
    and it makes only the missing layouts.
    """
    from dgse.data.generation import generate, stored_layouts

    check_output_file(out, "dataset store")
    kwargs: dict[str, Any] = {}
    if size is not None:
        kwargs = {"width_range": tuple(size), "height_range": tuple(size)}

    def started(todo: int, n_workers: int) -> None:
        where = f"scheduler {scheduler}" if scheduler else f"{n_workers} local worker{'s' * (n_workers != 1)}"
        console.print(
            f"generating {todo} of {n_layouts} layouts into [cyan]{path_text(out)}[/] with "
            f"{escape(engine)} on {escape(where)} (seed {seed})"
        )

    def kept() -> str:
        return resume_note(stored_layouts(out), "layout", out, resume_command(ctx))

    with interruptible(kept):
        report = generate(
            n_layouts,
            out,
            engine=engine,
            workers=workers,
            scheduler=scheduler,
            seed=seed,
            progress=progress,
            retries=retries,
            retry_failed=retry_failed,
            checkpoint_s=checkpoint_s,
            only_splits=split or None,
            on_start=started,
            **kwargs,
        )
    splits = ", ".join(f"{k} {v}" for k, v in report.splits.items())
    rate = report.layouts_per_minute
    console.print(
        f"[bold]{report.n_layouts}[/] layouts in [cyan]{path_text(out)}[/] ({splits}); "
        f"{report.n_failures} failed; this run: {report.n_new} new, {report.n_failed_new} failed "
        f"in {report.seconds:.1f} s"
        + (f" ({rate:.1f} layouts/min)" if report.n_new + report.n_failed_new else "")
    )


@user_errors
def export_cmd(
    store: Annotated[Path, typer.Argument(metavar="STORE", help="Dataset store (.h5).")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Directory for the case files.")],
    split: Annotated[str | None, typer.Option("--split", help="Only this split (train, val, test).")] = None,
) -> None:
    """Write every case of a store as a case file <layout>_src<k>.npz (plus manifest.json)."""
    from dgse.data.store import DatasetStore

    check_output_dir(out)

    def kept() -> str:
        return f"the case files written so far are in {out}, without manifest.json; run the command again"

    with interruptible(kept), DatasetStore(store, "r") as s:
        files = s.export(out, split=split)
    console.print(f"wrote {len(files)} case files into [cyan]{path_text(out)}[/]")


@user_errors
def import_cmd(
    cases: Annotated[
        list[Path],
        typer.Argument(metavar="CASES...", help="Case files (.npz) or directories of them."),
    ],
    out: Annotated[Path, typer.Option("--out", "-o", help="Dataset store (.h5), created if missing.")],
    split: Annotated[
        str, typer.Option("--split", help="Split of the imported layouts (train, val, test).")
    ] = "train",
) -> None:
    """Add case files to a dataset store (cases sharing a layout become one layout)."""
    from dgse.data.store import DatasetStore

    check_output_file(out, "dataset store")
    with DatasetStore(out, "a") as s:
        added = s.import_cases(cases, split=split)
        n_cases = sum(s.n_sources(i) for i in added)
        total = len(s)
    console.print(
        f"imported {n_cases} cases as {len(added)} layouts ({escape(split)}) into "
        f"[cyan]{path_text(out)}[/]; the store now holds {total} layouts"
    )


def _fmt(v: float | int | None) -> str:
    if v is None or (isinstance(v, float) and v != v):
        return "-"
    return f"{v:.3g}"


@user_errors
def stats_cmd(
    store: Annotated[Path, typer.Argument(metavar="STORE", help="Dataset store (.h5).")],
    plot: Annotated[
        Path | None, typer.Option("--plot", help="Save histograms to this figure (png, pdf, ...).")
    ] = None,
    json_out: Annotated[Path | None, typer.Option("--json", help="Write the statistics as JSON.")] = None,
    verify: Annotated[
        bool,
        typer.Option(
            "--verify/--no-verify",
            help="Read every array first, so a damaged file is an error (seconds per 1000 layouts).",
        ),
    ] = True,
) -> None:
    """Statistics of a dataset: sizes, inlet speeds, release rates, concentrations, splits."""
    from dgse.data.stats import dataset_stats, plot_stats

    check_output_file(plot, "figure")
    check_output_file(json_out, "JSON file")
    st = dataset_stats(store, verify=verify)
    sp = st["splits"]
    console.print(
        f"[bold]{escape(str(store))}[/]: {st['n_layouts']} layouts, {st['n_cases']} cases; "
        + ", ".join(f"{k} {v['layouts']}" for k, v in sp.items())
        + f"; {st['failures']['count']} failures"
        + (
            " (" + ", ".join(f"{k} {v}" for k, v in st["failures"]["by_error"].items()) + ")"
            if st["failures"]["count"]
            else ""
        )
    )
    table = Table(title_justify="left")
    for col in ("quantity", "min", "p05", "median", "mean", "p95", "max"):
        table.add_column(col, justify="left" if col == "quantity" else "right")
    rows = [
        ("width [m]", "width_m"),
        ("height [m]", "height_m"),
        ("free fraction", "free_fraction"),
        ("inlet velocity [m/s]", "inlet_velocity"),
        ("max wind speed [m/s]", "max_speed"),
        ("release rate [g/s]", "release_rate_gps"),
        ("max conc. [ppm]", "max_ppm"),
        ("mean conc. [ppm]", "mean_ppm"),
    ]
    for label, key in rows:
        s = st[key]
        table.add_row(label, *(_fmt(s[k]) for k in ("min", "p05", "median", "mean", "p95", "max")))
    console.print(table)
    if json_out is not None:
        json_out.parent.mkdir(parents=True, exist_ok=True)
        write_json(json_out, st, indent=1, allow_nan=True)
        console.print(f"wrote statistics [cyan]{path_text(json_out)}[/]")
    if plot is not None:
        plot.parent.mkdir(parents=True, exist_ok=True)
        try:
            # savefig names a figure without a suffix NAME.png; the temporary name has a suffix
            target = plot if plot.suffix else plot.with_name(plot.name + ".png")
            with atomic_path(target) as tmp:
                plot_stats(st).savefig(tmp, dpi=120)
        except ValueError as e:  # unknown image format
            raise InputDataError(f"cannot save figure {plot}: {e}") from None
        console.print(f"wrote figure [cyan]{path_text(plot)}[/]")


@user_errors
def import_gaden_cmd(
    files: Annotated[
        list[Path],
        typer.Argument(metavar="FILES...", help="GADEN result files (time frames) or a directory of them."),
    ],
    obstacles: Annotated[Path, typer.Option("--obstacles", help="Obstacle image (PGM/PNG, dark = solid).")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Case file (.npz) to write.")],
    frame_dt: Annotated[
        float | None, typer.Option("--frame-dt", help="Seconds between frames (with several files).")
    ] = None,
    z_index: Annotated[
        int | None, typer.Option("--z-index", help="z slice to keep (default: the source's).")
    ] = None,
    rate: Annotated[float | None, typer.Option("--rate", help="Release rate in g/s, if known.")] = None,
    inlet_velocity: Annotated[
        float | None, typer.Option("--inlet-velocity", help="Inlet speed in m/s, if known.")
    ] = None,
) -> None:
    """Make a case file (with frames) from a GADEN scenario's result files."""
    from dgse.data.gaden import load_gaden

    check_output_file(out, "case file")
    case = load_gaden(
        files, obstacles, z_index=z_index, frame_dt=frame_dt, release_rate=rate, inlet_velocity=inlet_velocity
    )
    path = case.save(out)
    n = 0 if case.frames is None else case.frames.shape[0]
    console.print(f"wrote [cyan]{path_text(path)}[/]: {case.grid.width}x{case.grid.height} cells, {n} frames")


@user_errors
def import_gaden_scenario_cmd(
    directory: Annotated[Path, typer.Argument(metavar="DIR", help="A GADEN scenario folder.")],
    out: Annotated[
        Path, typer.Option("--out", "-o", help="Layout file (.npz) to write (a case file with --solve).")
    ],
    map_path: Annotated[
        Path | None, typer.Option("--map", help="The ROS map YAML (default: the folder's).")
    ] = None,
    simulation: Annotated[
        Path | None,
        typer.Option("--simulation", help="The file with the source (default: the folder's one source)."),
    ] = None,
    scene: Annotated[
        Path | None,
        typer.Option("--scene", help="The robot scene with the start (default: the folder's one start)."),
    ] = None,
    settings: Annotated[
        Path | None,
        typer.Option("--settings", help="The preprocessing settings listing the outlet models."),
    ] = None,
    inlet: Annotated[
        list[str] | None,
        typer.Option("--inlet", metavar="FILE", help="An outlet model that is an inlet (repeatable)."),
    ] = None,
    outlet: Annotated[
        list[str] | None,
        typer.Option("--outlet", metavar="FILE", help="An outlet model that is an outlet (repeatable)."),
    ] = None,
    wind: Annotated[
        list[Path] | None,
        typer.Option("--wind", metavar="FILE", help="A wind_at_cell_centers CSV (repeatable)."),
    ] = None,
    use_wind: Annotated[bool, typer.Option("--wind-files/--no-wind", help="Read the CFD wind.")] = True,
    source: Annotated[
        tuple[float, float] | None,
        typer.Option("--source", metavar="X Y", help="Source, m (map frame; give --height too)."),
    ] = None,
    start: Annotated[
        tuple[float, float] | None, typer.Option("--start", metavar="X Y", help="Robot start, m (map frame).")
    ] = None,
    height: Annotated[
        float | None,
        typer.Option("--height", help="Map-frame height of the wind slice, m (default: the source's)."),
    ] = None,
    resolution: Annotated[float, typer.Option("--resolution", help="Cell size, m.")] = 0.1,
    solve: Annotated[bool, typer.Option("--solve", help="Solve the layout and write a case file.")] = False,
    inlet_velocity: Annotated[
        float | None,
        typer.Option("--inlet-velocity", help="Inlet speed for --solve, m/s (default: the wind's)."),
    ] = None,
    rate: Annotated[float | None, typer.Option("--rate", help="Release rate for --solve, g/s.")] = None,
) -> None:
    """Make a layout (or, with --solve, a case) file from a GADEN scenario folder: its map, outlet
    models, source, robot start and CFD wind."""
    from dgse.data.gaden_scenario import import_gaden_scenario

    check_output_file(out, "case file" if solve else "layout file")
    path, sc = import_gaden_scenario(
        directory,
        out,
        solve=solve,
        inlet_velocity=inlet_velocity,
        release_rate=rate,
        map_path=map_path,
        simulation=simulation,
        scene=scene,
        settings_path=settings,
        inlets=inlet or (),
        outlets=outlet or (),
        wind_files=wind or (),
        use_wind=use_wind,
        source=source,
        start=start,
        height=height,
        resolution=resolution,
    )
    g = sc.layout.grid

    def fmt(o) -> str:
        return f"{o.side} {o.start_m:g}-{o.end_m:g} m"

    lines = [
        f"{escape(sc.layout.name)}: {g.width_m:g} x {g.height_m:g} m, {g.width} x {g.height} cells "
        f"(map origin {sc.origin[0]:g}, {sc.origin[1]:g} m)",
        f"inlets: {escape(', '.join(fmt(o) for o in sc.layout.inlets))}; "
        f"outlets: {escape(', '.join(fmt(o) for o in sc.layout.outlets))}",
        f"source ({sc.source[0]:.2f}, {sc.source[1]:.2f}) m"
        + ("" if sc.start is None else f", start ({sc.start[0]:.2f}, {sc.start[1]:.2f}) m")
        + " (grid frame)"
        + ("" if sc.wind is None else f"; wind at z = {sc.height:g} m, inflow {sc.inlet_speed or 0:.3g} m/s"),
    ]
    for line in lines:
        console.print(line)
    console.print(f"wrote {'case' if solve else 'layout'} [cyan]{path_text(path)}[/]")


def register(app: typer.Typer) -> typer.Typer:
    """Attach the commands to ``app``: generate/export/import at top level, ``data stats``.

    Returns the ``data`` sub-app (add more dataset commands to it).
    """
    app.command("generate")(generate_cmd)
    app.command("export")(export_cmd)
    app.command("import")(import_cmd)
    app.command("import-gaden")(import_gaden_cmd)
    app.command("import-gaden-scenario")(import_gaden_scenario_cmd)
    sub = new_app("data", "Dataset tools.")
    sub.command("stats")(stats_cmd)
    app.add_typer(sub, name="data")
    return sub
