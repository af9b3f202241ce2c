"""The ``dgse`` command line: layouts, solves, figures and the scenario job.

Commands (``dgse COMMAND --help`` for each):

* ``layout``: draw a random layout and save it as a layout file;
* ``import-floorplan``: a layout from a ROS map_server map or a floor plan image;
* ``solve``: solve a layout file (with an inlet speed and a source) or re-solve a case file;
* ``show``: the figure of a case (or a layout) file;
* ``demo``: the main job: a random scenario solved, then one active search with the shipped
  DGSE-S model (:mod:`dgse.cli.demo`);
* ``scenario``: a random multi-room scenario with four sources, solved, with figures;
* ``engines``: the physics engines and why a missing one is missing;
* ``generate``, ``export``, ``import``, ``import-gaden``, ``import-gaden-scenario``, ``data stats``: datasets
  (:mod:`dgse.cli.data`);
* ``estimate``, ``evaluate``, ``export-onnx``: estimators on cases (:mod:`dgse.cli.models`);
* ``plume``: time-varying filament readings of a case as ``frames`` (:mod:`dgse.cli.plume`);
* ``train``: train DGSE-O/P/S on a dataset store (:mod:`dgse.cli.train`);
* ``search``: active search episodes with any estimator and planner (:mod:`dgse.cli.search`);
* ``bench``, ``report``: the paper's experiments as suites, and their HTML report (:mod:`dgse.cli.bench`);
* ``ros run``, ``ros sim``, ``ros replay``: the search on a ROS 2 robot (:mod:`dgse.cli.ros`).

Every error a user can cause (:class:`~dgse.errors.DGSEError`, a file that
cannot be written, or a command line that does not parse) is printed as one
red line ``error: <message>`` and the exit status is 2; there is no
traceback.  Ctrl-C ends a command with one line saying what was kept and how
to resume, and status 130; anything unexpected prints one line with the path
of a log file holding the traceback (:func:`dgse.cli.common.write_crash_log`)
and exits with 1.
"""

from __future__ import annotations

import importlib
import math
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Annotated

import typer
from rich import box
from rich.markup import escape
from rich.table import Table
from rich.text import Text

from dgse.cli.common import (
    EXIT_BUG,
    EXIT_INTERRUPTED,
    EXIT_USER_ERROR,
    NOTHING_KEPT,
    OPENING_ARGS,
    ClickException,
    EngineOption,
    NoArgsIsHelpError,
    UsageError,
    check_output_dir,
    check_output_file,
    console,
    new_app,
    os_error_message,
    path_text,
    print_error,
    print_interrupted,
    report_bug,
    usage_error_message,
    user_errors,
)
from dgse.errors import DGSEError, InputDataError
from dgse.files import atomic_path
from dgse.world.case import Case
from dgse.world.layout import Layout, Opening

__all__ = ["app", "main"]

app = new_app(
    "dgse",
    "Indoor gas leaks: scenarios, a RANS + gas transport solver, datasets, estimators, search.",
)


_SEED_HELP = "Random seed (default: a fresh one, printed)."
#: ``--plot`` of the commands that write a layout file.
LayoutPlotOption = Annotated[
    Path | None, typer.Option("--plot", help="Also save a figure of the layout (png, pdf, ...).")
]


# -- helpers -----------------------------------------------------------------------------
def _version_callback(value: bool) -> None:
    if value:
        from importlib.metadata import PackageNotFoundError, version

        try:
            v = version("dgse")
        except PackageNotFoundError:
            v = "0.1.0 (not installed)"
        console.print(f"dgse {v}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[
        bool,
        typer.Option("--version", callback=_version_callback, is_eager=True, help="Print the version."),
    ] = False,
) -> None:
    """Indoor gas-leak scenarios: layouts, a RANS + gas transport solver, figures."""


def _new_seed() -> int:
    import secrets

    return secrets.randbelow(2**31)


def _engine(name: str):
    from dgse.physics.engines import get_engine

    return get_engine(name)


def _opening_str(o: Opening) -> str:
    return f"{o.side} {o.start_m:g}-{o.end_m:g} m"


def _openings_str(layout: Layout) -> str:
    ins = ", ".join(_opening_str(o) for o in layout.inlets)
    outs = ", ".join(_opening_str(o) for o in layout.outlets)
    s_in = "s" * (len(layout.inlets) > 1)
    s_out = "s" * (len(layout.outlets) > 1)
    return f"inlet{s_in} {ins}; outlet{s_out} {outs}"


def _layout_summary(layout: Layout) -> str:
    g = layout.grid
    return (
        f"{g.width_m:g} x {g.height_m:g} m ({g.width} x {g.height} cells of {g.resolution:g} m), "
        f"{100 * layout.free.mean():.0f} % free; {_openings_str(layout)}"
    )


def _save_figure(fig, path: Path, dpi: int) -> Path:
    """Save a figure; the format follows the suffix (png, pdf, svg, ...)."""
    _check_figure_out(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi)
    return path


def _check_figure_out(path: Path | None) -> None:
    """Check before any work that a figure can be written at ``path`` (format and folder)."""
    if path is None:
        return
    from matplotlib.figure import Figure

    fmt = path.suffix.lstrip(".").lower()
    supported = Figure().canvas.get_supported_filetypes()
    if fmt not in supported:
        raise InputDataError(
            f"cannot write a figure as {path.name!r}: use one of "
            + ", ".join(f".{k}" for k in sorted(supported))
        )
    check_output_file(path, "figure")


def _check_positive(value: float, what: str) -> float:
    if not (math.isfinite(value) and value > 0):
        raise InputDataError(f"{what} must be a positive number, got {value:g}")
    return float(value)


def _check_source(layout: Layout, x: float, y: float) -> None:
    """Raise :class:`InputDataError` unless ``(x, y)`` m lies in a free cell of ``layout``."""
    i, j = layout.grid.cell_of(x, y)
    if layout.occupancy[i, j]:
        raise InputDataError(f"source ({x:g}, {y:g}) m lies in a wall of layout {layout.name!r}")


def _fmt_s(seconds: object) -> str:
    return f"{float(seconds):.2f} s" if isinstance(seconds, int | float) else "-"


def _ratio_text(ratio: object) -> Text:
    if not isinstance(ratio, int | float):
        return Text("-")
    style = "green" if abs(ratio - 1.0) <= 0.01 else "yellow" if abs(ratio - 1.0) <= 0.05 else "red"
    return Text(f"{ratio:.4f}", style=style)


def _case_summary(case: Case, path: Path, seconds: float) -> Table:
    """A two-column table of one solved case: scenario, solver facts, mass balance, timings."""
    m = case.meta
    t = Table.grid(padding=(0, 2))
    t.add_column(style="bold")
    t.add_column()
    g = case.grid
    t.add_row("case", f"{escape(case.name)} -> {path_text(path)}")
    t.add_row("engine", escape(str(m.get("solver", "?"))))
    t.add_row("grid", f"{g.width} x {g.height} cells, {g.width_m:g} x {g.height_m:g} m")
    t.add_row("inlet velocity", f"{case.inlet_velocity:.3g} m/s")
    t.add_row(
        "source",
        f"({float(case.source[0]):.2f}, {float(case.source[1]):.2f}) m, {case.release_rate:.3g} g/s",
    )
    iters = (m.get("iterations") or {}).get("flow")
    conv = m.get("flow_converged")
    conv_txt = "[green]converged[/]" if conv else "[red]not converged[/]" if conv is False else "?"
    t.add_row("flow", f"{iters if iters is not None else '?'} iterations, {conv_txt}")
    ratio = (m.get("mass_balance") or {}).get("outlet_flux_ratio")
    t.add_row("mass balance", Text("outlet flux / release rate = ").append(_ratio_text(ratio)))
    t.add_row("max concentration", f"{float(case.concentration.max()):,.1f} ppm")
    tm = m.get("timings") or {}
    t.add_row(
        "timings",
        f"flow {_fmt_s(tm.get('flow'))}, gas {_fmt_s(tm.get('gas'))}, wall clock {seconds:.2f} s",
    )
    return t


# -- commands ----------------------------------------------------------------------------
@app.command("layout")
@user_errors
def layout_cmd(
    seed: Annotated[int | None, typer.Option("--seed", "-s", help=_SEED_HELP)] = None,
    ood: Annotated[
        bool,
        typer.Option("--ood", help="Out-of-domain layout: up to 15 x 10 m, several openings, obstacles."),
    ] = False,
    building: Annotated[
        bool,
        typer.Option(
            "--building",
            help="Office floor: 20-40 m per side, 1-2 corridors, rooms with doors, 2-4 inlets and outlets.",
        ),
    ] = False,
    out: Annotated[
        Path | None,
        typer.Option("--out", "-o", help="Layout file to write (default: ./<name>.npz)."),
    ] = None,
    plot: LayoutPlotOption = None,
) -> None:
    """Make a random multi-room layout and save it as a layout file (.npz)."""
    from dgse.world.building import random_office_floor
    from dgse.world.generate import random_layout, random_ood_layout
    from dgse.world.layout_io import save_layout

    if ood and building:
        raise InputDataError("--ood and --building exclude each other: give one of them")
    _check_figure_out(plot)
    check_output_file(out, "layout file")
    seed = _new_seed() if seed is None else seed
    generator = random_office_floor if building else random_ood_layout if ood else random_layout
    layout = generator(seed)
    path = save_layout(layout, out if out is not None else Path(f"{layout.name}.npz"))
    summary = escape(_layout_summary(layout))
    console.print(f"[bold]{escape(layout.name)}[/] (seed {seed}): {summary}")
    console.print(f"wrote layout [cyan]{path_text(path)}[/]")
    if plot is not None:
        from dgse.viz.case import plot_layout

        console.print(f"wrote figure [cyan]{path_text(_save_figure(plot_layout(layout), plot, 150))}[/]")


@app.command("import-floorplan")
@user_errors
def import_floorplan_cmd(
    floorplan: Annotated[
        Path,
        typer.Argument(metavar="MAP", help="ROS map_server YAML (with its PGM/PNG) or a floor plan image."),
    ],
    inlet: Annotated[
        list[tuple],
        typer.Option(
            "--inlet",
            click_type=OPENING_ARGS,
            metavar="SIDE START END",
            help="Inlet on side west/east/south/north from START to END m along it "
            "(x for south/north, y for west/east; m from the map's lower-left corner); "
            "repeat for several inlets.",
        ),
    ],
    outlet: Annotated[
        list[tuple],
        typer.Option(
            "--outlet",
            click_type=OPENING_ARGS,
            metavar="SIDE START END",
            help="Outlet, as --inlet; repeat for several.",
        ),
    ],
    out: Annotated[Path, typer.Option("--out", "-o", help="Layout file to write.")],
    resolution: Annotated[
        float, typer.Option("--resolution", "-r", help="Cell size of the layout in m.")
    ] = 0.1,
    pixel_size: Annotated[
        float | None,
        typer.Option("--pixel-size", help="Image pixel side in m (plain images; default: one cell)."),
    ] = None,
    width_m: Annotated[
        float | None,
        typer.Option("--width-m", help="Image width in m (plain images; instead of --pixel-size)."),
    ] = None,
    carve_depth_m: Annotated[
        float,
        typer.Option("--carve", help="Cut the openings through an outer wall up to this depth in m."),
    ] = 0.0,
    name: Annotated[
        str | None, typer.Option("--name", help="Layout name (default: the map's file name).")
    ] = None,
    plot: LayoutPlotOption = None,
) -> None:
    """Make a layout from a floor plan (ROS map_server YAML, or PNG/PGM: dark is solid)."""
    from dgse.world.floorplan import layout_from_floorplan, load_png_map, load_ros_map
    from dgse.world.layout_io import save_layout

    _check_positive(resolution, "--resolution")
    check_output_file(out, "layout file")
    _check_figure_out(plot)
    if floorplan.suffix.lower() in (".yaml", ".yml"):
        if pixel_size is not None or width_m is not None:
            raise InputDataError(
                "--pixel-size/--width-m apply to plain images; a ROS map's YAML gives its resolution"
            )
        fp = load_ros_map(floorplan, resolution)
        where = f", origin ({fp.origin[0]:g}, {fp.origin[1]:g}) m in the map frame"
    else:
        fp = load_png_map(floorplan, resolution, pixel_size=pixel_size, width_m=width_m)
        where = ""
    layout = layout_from_floorplan(
        fp, None, inlet, outlet, name=name or floorplan.stem, carve_depth_m=carve_depth_m
    )
    g = fp.grid
    console.print(
        f"floor plan [cyan]{path_text(floorplan)}[/]: {g.width_m:g} x {g.height_m:g} m "
        f"({g.width} x {g.height} cells){escape(where)}"
    )
    path = save_layout(layout, out)
    console.print(f"[bold]{escape(layout.name)}[/]: {escape(_layout_summary(layout))}")
    console.print(f"wrote layout [cyan]{path_text(path)}[/]")
    if plot is not None:
        from dgse.viz.case import plot_layout

        console.print(f"wrote figure [cyan]{path_text(_save_figure(plot_layout(layout), plot, 150))}[/]")


@app.command("solve")
@user_errors
def solve_cmd(
    input_file: Annotated[
        Path, typer.Argument(metavar="CASE_OR_LAYOUT", help="A case file or a layout file (.npz).")
    ],
    out: Annotated[Path, typer.Option("--out", "-o", help="Case file to write.")],
    engine: EngineOption = "builtin",
    inlet_velocity: Annotated[
        float | None,
        typer.Option("--inlet-velocity", "-v", help="Inlet speed in m/s (layout files)."),
    ] = None,
    source: Annotated[
        tuple[float, float] | None,
        typer.Option("--source", metavar="X Y", help="Source position in m (layout files)."),
    ] = None,
    rate: Annotated[
        float | None, typer.Option("--rate", "-q", help="Release rate in g/s (layout files).")
    ] = None,
    seed: Annotated[
        int | None,
        typer.Option(
            "--seed",
            "-s",
            help="Draw what is not given (inlet speed, source, rate) from the training "
            "distribution with this seed (layout files).",
        ),
    ] = None,
    plot: Annotated[Path | None, typer.Option("--plot", help="Also save the case figure.")] = None,
) -> None:
    """Solve flow and gas: re-solve a case file, or solve a layout file for one source.

    A case file's scenario (layout, inlet speed, source, rate) is solved again
    as it is.  A layout file needs --inlet-velocity, --source X Y and --rate Q,
    or --seed S to draw the missing ones.
    """
    from dgse.physics.scenario import resolve_case, solve_cases
    from dgse.world.layout_io import load_layout, npz_kind

    check_output_file(out, "case file")
    _check_figure_out(plot)
    eng = _engine(engine)
    kind = npz_kind(input_file)
    given = {
        "--inlet-velocity": inlet_velocity,
        "--source": source,
        "--rate": rate,
        "--seed": seed,
    }
    t0 = time.perf_counter()
    if kind == "case":
        extra = [k for k, v in given.items() if v is not None]
        if extra:
            raise InputDataError(
                f"{', '.join(extra)} apply to layout files only; {input_file} is a case file "
                "and its scenario is re-solved as it is"
            )
        case = Case.load(input_file)
        with console.status(f"re-solving {escape(case.name)} with {escape(engine)} ..."):
            result = resolve_case(case, eng)
    else:
        layout = load_layout(input_file)
        if seed is None:
            missing = [k for k, v in given.items() if v is None and k != "--seed"]
            if missing:
                raise InputDataError(
                    f"{input_file} is a layout file: give {', '.join(missing)} (or --seed S to draw them)"
                )
        else:
            from dgse.world.generate import as_generator, random_inlet_velocity, random_sources

            rng = as_generator(seed)  # always draw both, so a seed means one scenario
            v_drawn = random_inlet_velocity(rng)
            [(xy_drawn, q_drawn)] = random_sources(layout, rng, n=1)
            inlet_velocity = v_drawn if inlet_velocity is None else inlet_velocity
            source = xy_drawn if source is None else source
            rate = q_drawn if rate is None else rate
        assert inlet_velocity is not None and source is not None and rate is not None
        _check_positive(inlet_velocity, "--inlet-velocity")
        _check_positive(rate, "--rate")
        _check_source(layout, *source)
        with console.status(f"solving {escape(layout.name)} with {escape(engine)} ..."):
            result = solve_cases(layout, inlet_velocity, [(source, rate)], eng)[0]
    path = result.save(out)
    console.print(_case_summary(result, path, time.perf_counter() - t0))
    if plot is not None:
        from dgse.viz.case import plot_case

        console.print(f"wrote figure [cyan]{path_text(_save_figure(plot_case(result), plot, 150))}[/]")


@app.command("show")
@user_errors
def show_cmd(
    input_file: Annotated[Path, typer.Argument(metavar="CASE", help="A case file (or a layout file).")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Figure to write (png, pdf, svg, ...).")],
    arrows: Annotated[bool, typer.Option("--arrows/--no-arrows", help="Wind direction arrows.")] = True,
    dpi: Annotated[int, typer.Option("--dpi", help="Resolution of raster figures.")] = 150,
) -> None:
    """Draw a case: layout with inlet/outlet, wind speed and direction, concentration."""
    from dgse.viz.case import plot_case, plot_layout
    from dgse.world.layout_io import load_layout, npz_kind

    if dpi <= 0:
        raise InputDataError(f"--dpi must be positive, got {dpi}")
    _check_figure_out(out)
    if npz_kind(input_file) == "case":
        fig = plot_case(Case.load(input_file), arrows=arrows)
    else:
        fig = plot_layout(load_layout(input_file))
    console.print(f"wrote figure [cyan]{path_text(_save_figure(fig, out, dpi))}[/]")


_SCENARIO_HELP = (
    "Make a random multi-room scenario, solve it for several sources, write case files "
    "and figures.\n\n"
    "A random layout of the training distribution (spec section 3), a random inlet "
    "speed and --sources sources (default 4); one flow solve, one gas solve per source. "
    "Writes <name>_src<n>.npz and <name>_src<n>.png per source into --out and prints "
    "a summary with each source's mass balance."
)


@user_errors
def scenario_cmd(
    seed: Annotated[int | None, typer.Option("--seed", "-s", help=_SEED_HELP)] = None,
    out: Annotated[
        Path, typer.Option("--out", "-o", help="Directory for the case files and figures.")
    ] = Path("dgse-out"),
    engine: EngineOption = "builtin",
    sources: Annotated[int, typer.Option("--sources", "-n", help="Number of sources.")] = 4,
    size: Annotated[
        tuple[float, float],
        typer.Option(
            "--size",
            metavar="MIN MAX",
            help="Range of the domain's width and height in m (smaller solves faster).",
        ),
    ] = (5.0, 10.0),
    figures: Annotated[bool, typer.Option("--figures/--no-figures", help="Write a figure per case.")] = True,
) -> None:
    from dgse.physics.scenario import random_scenario, solve_cases

    if sources < 1:
        raise InputDataError(f"--sources must be at least 1, got {sources}")
    check_output_dir(out)
    eng = _engine(engine)
    seed = _new_seed() if seed is None else seed
    t0 = time.perf_counter()
    layout, v_in, srcs = random_scenario(
        seed, sources, width_range=size, height_range=size, name=f"random-{seed}"
    )
    console.print(
        f"[bold]{escape(layout.name)}[/] (seed {seed}): {escape(_layout_summary(layout))}; "
        f"inlet velocity {v_in:.2f} m/s"
    )
    with console.status(f"solving flow and {len(srcs)} sources with {escape(engine)} ..."):
        cases = solve_cases(layout, v_in, srcs, eng)
    t_solve = time.perf_counter() - t0
    out.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    if figures:
        from dgse.viz.case import plot_case
    with console.status("writing case files and figures ..."):
        for case in cases:
            written.append(case.save(out / f"{case.name}.npz"))
            if figures:
                written.append(_save_figure(plot_case(case), out / f"{case.name}.png", 150))

    m0 = cases[0].meta
    tm = m0.get("timings") or {}
    solver = escape(str(m0.get("solver")))
    table = Table(
        title=f"{escape(layout.name)}: inlet {v_in:.2f} m/s, engine {solver}",
        title_justify="left",
        box=box.SIMPLE_HEAD,
    )
    table.add_column("case", no_wrap=True)
    table.add_column(escape("x [m]"), justify="right")
    table.add_column(escape("y [m]"), justify="right")
    table.add_column(escape("q [g/s]"), justify="right")
    table.add_column(escape("max [ppm]"), justify="right")
    table.add_column("outflux / q", justify="right")
    table.add_column(escape("gas [s]"), justify="right")
    per_source = tm.get("gas_per_source")
    for case in cases:
        ratio = (case.meta.get("mass_balance") or {}).get("outlet_flux_ratio")
        table.add_row(
            escape(case.name),
            f"{float(case.source[0]):.2f}",
            f"{float(case.source[1]):.2f}",
            f"{case.release_rate:.3g}",
            f"{float(case.concentration.max()):,.0f}",
            _ratio_text(ratio),
            f"{per_source:.2f}" if isinstance(per_source, int | float) else "-",
        )
    console.print(table)
    iters = (m0.get("iterations") or {}).get("flow")
    conv = m0.get("flow_converged")
    conv_txt = "[green]converged[/]" if conv else "[red]not converged[/]" if conv is False else "?"
    console.print(
        f"flow: {iters if iters is not None else '?'} iterations, {conv_txt}, "
        f"{_fmt_s(tm.get('flow'))}; gas {_fmt_s(tm.get('gas'))}; "
        f"total {time.perf_counter() - t0:.2f} s (solve {t_solve:.2f} s)"
    )
    console.print(f"wrote {len(written)} files into [cyan]{path_text(out)}[/]")


app.command("scenario", help=_SCENARIO_HELP)(scenario_cmd)


@app.command("engines")
@user_errors
def engines_cmd() -> None:
    """List the physics engines and why unavailable ones are missing."""
    from dgse.physics.engines import ENGINES, unavailable_engines

    missing = unavailable_engines()
    table = Table(title="physics engines", title_justify="left", box=box.SIMPLE_HEAD)
    table.add_column("engine", style="bold")
    table.add_column("status")
    table.add_column("notes")
    for name in ENGINES.names():
        if name not in missing:
            table.add_row(name, "[green]available[/]", escape(ENGINES.entry(name).description))
            continue
        table.add_row(name, "[red]unavailable[/]", escape(missing[name]))
    console.print(table)


# -- the other modules' commands, imported for the command that runs -------------------------
#: The modules that add commands to ``app`` (their ``register``), in the order ``dgse --help``
#: lists them, with the commands each adds (``data`` is a group: ``dgse data stats``).
COMMAND_MODULES: dict[str, tuple[str, ...]] = {
    "dgse.cli.demo": ("demo",),
    "dgse.cli.data": ("generate", "export", "import", "import-gaden", "import-gaden-scenario", "data"),
    "dgse.cli.models": ("estimate", "evaluate", "export-onnx"),
    "dgse.cli.plume": ("plume",),
    "dgse.cli.search": ("search",),
    "dgse.cli.train": ("train",),
    "dgse.cli.bench": ("bench", "report"),
    "dgse.cli.ros": ("ros",),
}
#: The commands this module defines itself.
OWN_COMMANDS = frozenset(c.name for c in app.registered_commands)
_registered: set[str] = set()


def register_commands(argv: Sequence[str]) -> None:
    """Add to ``app`` the commands that ``argv`` may run: none for a command of this module
    (``dgse solve`` imports no estimator, search or plotting module), the module of another
    known command, and every module otherwise (help, completion, a mistyped command)."""
    command = argv[0] if argv else ""
    if command in OWN_COMMANDS:
        return
    wanted = [m for m, names in COMMAND_MODULES.items() if command in names] or list(COMMAND_MODULES)
    for module in wanted:
        if module not in _registered:
            importlib.import_module(module).register(app)
            _registered.add(module)


# -- entry point -------------------------------------------------------------------------
def main(args: Sequence[str] | None = None) -> int:
    """Run the CLI with ``args`` (default ``sys.argv[1:]``); returns the exit status.

    User-caused errors (a command line that does not parse included) print
    ``error: <message>`` in red and return 2; Ctrl-C returns 130 (the command
    says what it kept); an unexpected error prints one line naming its crash
    log and returns 1.
    """
    argv = list(args) if args is not None else sys.argv[1:]
    try:
        register_commands(argv)
        status = app(args=argv, prog_name="dgse", standalone_mode=False)
    except SystemExit as e:
        code = e.code
        return code if isinstance(code, int) else (0 if code is None else 1)
    except UsageError as e:
        if NoArgsIsHelpError is not None and isinstance(e, NoArgsIsHelpError):
            e.show()  # `dgse`, `dgse data`: the help
            return e.exit_code
        print_error(usage_error_message(e))
        return EXIT_USER_ERROR
    except ClickException as e:
        print_error(e.format_message())
        return e.exit_code
    except (KeyboardInterrupt, typer.Abort):
        print_interrupted(NOTHING_KEPT)
        return EXIT_INTERRUPTED
    except DGSEError as e:
        print_error(str(e))
        return EXIT_USER_ERROR
    except OSError as e:  # a file that cannot be written (permission, disk full, ...)
        print_error(os_error_message(e))
        return EXIT_USER_ERROR
    except Exception as e:  # a bug: one line here, the traceback in a log file
        report_bug(e, argv)
        return EXIT_BUG
    return status if isinstance(status, int) else 0


def run() -> None:
    """The ``dgse`` console script: :func:`main` in a process set up to run once and exit
    (:mod:`dgse.cli.process`: fewer collector passes)."""
    from dgse.cli import process

    process.start()
    status = main()
    process.finish()
    sys.exit(status)


if __name__ == "__main__":
    run()
