"""The ``dgse plume`` command: time-varying, intermittent concentration frames for a case.

``dgse plume CASE.npz -o OUT.npz [--duration S] [--frame-dt S] [--seed S] [--warmup S]``
runs the filament dispersion model (:mod:`dgse.physics.filament`, GADEN's
model in 2-D) on the case's wind from its source and writes the case again
with ``frames`` ``(T, H, W)`` ppm, ``meta.frame_dt`` and ``meta.filament``
(settings, seed, counts, timings).  A simulated robot then reads its gas
measurement at time ``t`` from frame ``floor(t / frame_dt) mod T``.

``--noise turbulent`` (the default) derives the random walk from the RANS eddy
viscosity, which costs one flow solve with the built-in solver (seconds);
``--noise constant`` is GADEN's constant velocity noise (``--noise-std``).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import typer

from dgse.cli.common import check_output_file, console, path_text, user_errors
from dgse.errors import InputDataError
from dgse.physics.constants import RECOMMENDED_MAX_FILAMENTS

__all__ = ["plume_cmd", "register"]


@user_errors
def plume_cmd(
    case_file: Annotated[Path, typer.Argument(metavar="CASE", help="Case file (.npz).")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Case file with frames to write (.npz).")],
    duration: Annotated[float, typer.Option("--duration", help="Recorded seconds.")] = 120.0,
    frame_dt: Annotated[float, typer.Option("--frame-dt", help="Seconds between frames.")] = 0.5,
    seed: Annotated[
        int | None, typer.Option("--seed", "-s", help="Random seed (default: fresh, printed).")
    ] = None,
    warmup: Annotated[
        float, typer.Option("--warmup", help="Simulated seconds before the first frame.")
    ] = 60.0,
    noise: Annotated[
        str, typer.Option("--noise", help="turbulent (from the RANS eddy viscosity) or constant (GADEN).")
    ] = "turbulent",
    noise_std: Annotated[
        float, typer.Option("--noise-std", help="Velocity noise in m/s per axis (--noise constant).")
    ] = 0.1,
    filaments: Annotated[
        float, typer.Option("--filaments-per-second", help="Filaments released per second.")
    ] = 100.0,
    dt: Annotated[float, typer.Option("--dt", help="Longest time step in s.")] = 0.1,
    prefill: Annotated[
        bool, typer.Option("--prefill/--no-prefill", help="Start from the case's steady concentration.")
    ] = True,
    max_filaments: Annotated[
        int,
        typer.Option(
            "--max-filaments",
            help="Cap of the filaments standing for the steady field at the start (heavier ones carry "
            "the rest; bounds the cost in poorly ventilated rooms); 0: no cap.",
        ),
    ] = RECOMMENDED_MAX_FILAMENTS,
) -> None:
    """Simulate filament dispersion on a case and write it with concentration frames."""
    import secrets

    from dgse.physics.filament import FilamentSettings, make_filament_case
    from dgse.world.case import Case

    if out.resolve() == case_file.resolve():
        raise InputDataError(f"--out {out} would overwrite the input case; choose another file")
    check_output_file(out, "case file")
    settings = FilamentSettings(
        filaments_per_second=filaments,
        dt=dt,
        noise=noise,
        noise_std=noise_std,
        prefill=prefill,
        max_filaments=max_filaments or None,
        warmup=warmup,
        frame_dt=frame_dt,
        duration=duration,
    )
    case = Case.load(case_file)
    seed = secrets.randbelow(2**31) if seed is None else seed
    console.print(
        f"[bold]{path_text(case.name)}[/]: {case.grid.width} x {case.grid.height} cells, "
        f"q {case.release_rate:.3g} g/s; {settings.n_frames} frames every {frame_dt:g} s "
        f"after {warmup:g} s, noise {noise} (seed {seed})"
    )
    t0 = time.perf_counter()
    with console.status("simulating filaments ..."):
        result = make_filament_case(case, settings, seed)
    path = result.save(out)
    info = result.meta["filament"]
    wall = info.get("wall_clock_s", {})
    frames = result.frames
    assert frames is not None
    console.print(
        f"{info['n_released']} filaments released, {info['mean_alive']:.0f} in the air on average, "
        f"{info['exit_rate_per_s']:.1f}/s leaving (release {filaments:g}/s); "
        f"peak {float(frames.max()):,.0f} ppm"
    )
    console.print(
        f"flow {wall.get('nut_flow', 0.0):.1f} s, particles {wall.get('particles', 0.0):.1f} s, "
        f"frames {wall.get('splat', 0.0):.1f} s; total {time.perf_counter() - t0:.1f} s"
    )
    console.print(f"wrote [cyan]{path_text(path)}[/] ({frames.shape[0]} frames)")


def register(app: typer.Typer) -> None:
    """Attach ``plume`` to ``app`` (``dgse plume``)."""
    app.command("plume")(plume_cmd)
