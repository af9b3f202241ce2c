"""The ``dgse`` command line: help, layout -> solve -> show, scenario, errors without tracebacks.

Real solver runs are few (three, on a 3 x 3 m layout): one layout solve shared
by a module-scoped fixture, one re-solve of its case file, one scenario.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import numpy as np
import pytest
import typer
from PIL import Image

from dgse.cli.main import main
from dgse.physics import engines as engines_mod
from dgse.world.case import Case
from dgse.world.layout import Layout, Opening
from dgse.world.layout_io import load_layout, save_layout

SRC = Path(__file__).resolve().parents[1] / "src"
COMMANDS = [
    "layout",
    "import-floorplan",
    "solve",
    "show",
    "scenario",
    "demo",
    "engines",
    "generate",
    "export",
    "import",
    "import-gaden",
    "import-gaden-scenario",
    "search",
    "estimate",
    "evaluate",
    "export-onnx",
    "train",
    "plume",
    "ros",
]
SOURCE = ("0.55", "0.55")  # free cell of the tiny layout
WALL = ("1.45", "0.55")  # inside its wall


def _tiny_layout() -> Layout:
    """3 x 3 m, a wall from the south up to y = 1.8 m, inlet west high, outlet east low."""
    occ = np.zeros((30, 30), np.uint8)
    occ[:18, 14:16] = 1
    return Layout(occ, (Opening("west", 1.8, 2.6),), (Opening("east", 0.3, 1.1),), name="tiny")


def _run(capsys, *args: str) -> tuple[int, str, str]:
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def _assert_user_error(code: int, out: str, err: str, *fragments: str) -> None:
    """Exit status 2, one ``error: ...`` line on stderr naming the problem, no traceback."""
    assert code == 2, (out, err)
    assert "Traceback" not in out + err
    line = err.strip()
    assert line.startswith("error: ") and "\n" not in line, err
    for f in fragments:
        assert f in line, (f, line)


def _subprocess(*args: str) -> subprocess.CompletedProcess:
    path = os.pathsep.join(filter(None, [str(SRC), os.environ.get("PYTHONPATH")]))
    env = {**os.environ, "PYTHONPATH": path}
    return subprocess.run(
        [sys.executable, "-m", "dgse.cli.main", *args],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )


@pytest.fixture(scope="module")
def solved(tmp_path_factory) -> dict[str, Path]:
    """A tiny layout file and its case file, solved once through ``dgse solve``."""
    d = tmp_path_factory.mktemp("cli")
    layout = save_layout(_tiny_layout(), d / "tiny.npz")
    case = d / "tiny_case.npz"
    code = main(
        [
            "solve",
            str(layout),
            "-o",
            str(case),
            "--inlet-velocity",
            "1.0",
            "--source",
            *SOURCE,
            "--rate",
            "0.5",
        ]
    )
    assert code == 0
    return {"dir": d, "layout": layout, "case": case}


# -- help -------------------------------------------------------------------------------
def test_help_as_a_subprocess():
    r = _subprocess("--help")
    assert r.returncode == 0, r.stderr
    for cmd in COMMANDS:
        assert cmd in r.stdout


def test_a_command_imports_only_its_own_module():
    """``dgse engines`` (a command of ``dgse.cli.main``) imports none of the other command modules,
    ``dgse search --help`` only ``dgse.cli.search``; ``dgse --help`` all of them (fresh processes)."""
    from dgse.cli.main import COMMAND_MODULES

    probe = (
        "import sys; from dgse.cli.main import main; main(sys.argv[1:]); "
        f"print(sorted(m for m in sys.modules if m in {set(COMMAND_MODULES)!r}), file=sys.stderr)"
    )
    for argv, expected in ((["engines"], []), (["search", "--help"], ["dgse.cli.search"])):
        r = subprocess.run([sys.executable, "-c", probe, *argv], capture_output=True, text=True, timeout=120)
        assert r.returncode == 0, r.stderr
        assert r.stderr.strip().splitlines()[-1] == repr(expected)
    r = subprocess.run([sys.executable, "-c", probe, "--help"], capture_output=True, text=True, timeout=120)
    assert r.stderr.strip().splitlines()[-1] == repr(sorted(COMMAND_MODULES))


def test_command_modules_name_every_command_they_add():
    """The map of :data:`COMMAND_MODULES` is what the modules register (a command missing from it
    would still run, but import every command module first)."""
    import importlib

    import typer

    from dgse.cli.main import COMMAND_MODULES

    for module, names in COMMAND_MODULES.items():
        scratch = typer.Typer()
        importlib.import_module(module).register(scratch)
        added = {c.name for c in scratch.registered_commands} | {g.name for g in scratch.registered_groups}
        assert added == set(names), module


@pytest.mark.parametrize("cmd", COMMANDS)
def test_help_of_every_command(capsys, cmd):
    code, out, _ = _run(capsys, cmd, "--help")
    assert code == 0 and "Usage" in out


def test_demo_searches_a_random_scenario(capsys, tmp_path):
    from dgse.models.checkpoint import save_model
    from tests.models.helpers import tiny_model

    weights = save_model(tiny_model("dgse-s"), tmp_path / "tiny.safetensors")
    out = tmp_path / "demo"
    net = ["--method", "dgse-s", "--model"]
    args = ["demo", "--seed", "3", *net, str(weights), "--time-limit", "40", "--no-animate"]
    code, text, err = _run(capsys, *args, "-o", str(out))
    assert code == 0, err
    assert "localization error" in text and "search time" in text
    assert (out / "search_final.png").exists() and len(list(out.glob("*.npz"))) == 1
    code, _, err = _run(capsys, "demo", *net, str(tmp_path / "missing.safetensors"))
    assert code == 2 and "missing.safetensors" in err


def test_no_command_shows_usage(capsys):
    code, out, err = _run(capsys)
    assert code in (0, 2) and "Usage" in out + err


# -- layout -> solve -> show ------------------------------------------------------------
def test_layout_command_writes_a_layout_and_figure(capsys, tmp_path):
    code, out, _ = _run(
        capsys, "layout", "--seed", "3", "-o", tmp_path / "l.npz", "--plot", tmp_path / "l.png"
    )
    assert code == 0, out
    lay = load_layout(tmp_path / "l.npz")
    assert lay.name == "random-3" and "random-3" in out and "seed 3" in out
    assert (tmp_path / "l.png").read_bytes()[:4] == b"\x89PNG"
    code, _, _ = _run(capsys, "layout", "--seed", "3", "--ood", "-o", tmp_path / "o.npz")
    assert code == 0 and load_layout(tmp_path / "o.npz").name == "ood-3"


def test_layout_building_writes_an_office_floor(capsys, tmp_path):
    code, out, err = _run(capsys, "layout", "--seed", "3", "--building", "-o", tmp_path / "b.npz")
    assert code == 0, err
    lay = load_layout(tmp_path / "b.npz")
    assert lay.name == "office-3" and "office-3" in out and "seed 3" in out
    assert all(200 <= n <= 400 for n in lay.occupancy.shape)
    assert 2 <= len(lay.inlets) <= 4 and 2 <= len(lay.outlets) <= 4
    code, out, err = _run(capsys, "layout", "--building", "--ood", "-o", tmp_path / "x.npz")
    _assert_user_error(code, out, err, "--ood and --building exclude each other")
    assert not (tmp_path / "x.npz").exists()


def test_import_floorplan_of_a_generated_office_floor(capsys, tmp_path):
    """A building-scale ROS map (benchmarks/floorplans/) imports through the CLI cell for cell."""
    from dgse.world.building import random_office_floor

    floor = random_office_floor(3)
    i, o = floor.inlets[0], floor.outlets[0]
    yaml_path = Path(__file__).resolve().parents[1] / "benchmarks" / "floorplans" / "office-3.yaml"
    args = ["--inlet", i.side, f"{i.start_m:g}", f"{i.end_m:g}"]
    args += ["--outlet", o.side, f"{o.start_m:g}", f"{o.end_m:g}", "-o", tmp_path / "f.npz"]
    code, _, err = _run(capsys, "import-floorplan", yaml_path, *args)
    assert code == 0, err
    lay = load_layout(tmp_path / "f.npz")
    assert np.array_equal(lay.occupancy, floor.occupancy) and lay.name == "office-3"
    assert (lay.inlets, lay.outlets) == ((i,), (o,))


def test_import_floorplan_of_a_drawn_plan_is_what_import_plan_gives(capsys, tmp_path):
    """A drawn plan's PNG through ``dgse import-floorplan`` with its options: the layout the
    floor plan benchmark solves (``dgse.world.plans.import_plan``)."""
    from dgse.world.plans import draw_house, import_plan

    plan = draw_house(2, pixel_size=0.025)
    png = plan.save_png(tmp_path / "house.png")
    code, _, err = _run(capsys, "import-floorplan", png, *plan.import_args(), "-o", tmp_path / "h.npz")
    assert code == 0, err
    lay, ref = load_layout(tmp_path / "h.npz"), import_plan(png, plan)
    assert np.array_equal(lay.occupancy, ref.occupancy) and lay.walls == ref.walls
    assert (lay.inlets, lay.outlets) == (plan.inlets, plan.outlets)


def test_solve_layout_writes_a_valid_case(solved, capsys):
    case = Case.load(solved["case"])
    assert case.inlet_velocity == pytest.approx(1.0) and case.release_rate == pytest.approx(0.5)
    assert tuple(case.source) == pytest.approx((0.55, 0.55))
    np.testing.assert_array_equal(case.occupancy, _tiny_layout().occupancy)
    assert case.concentration.max() > 0 and case.meta["flow_converged"] is True
    assert case.meta["mass_balance"]["outlet_flux_ratio"] == pytest.approx(1.0, abs=0.02)


def test_resolve_case_file_and_show(solved, capsys):
    out_case = solved["dir"] / "again.npz"
    code, out, err = _run(capsys, "solve", solved["case"], "-o", out_case)
    assert code == 0, err
    for word in ("iterations", "converged", "mass balance", "timings", "flow"):
        assert word in out
    a, b = Case.load(solved["case"]), Case.load(out_case)
    assert b.name == a.name
    np.testing.assert_allclose(b.concentration, a.concentration, rtol=1e-3, atol=1e-3)
    fig = solved["dir"] / "fig.png"
    code, out, _ = _run(capsys, "show", out_case, "-o", fig)
    assert code == 0 and fig.read_bytes()[:4] == b"\x89PNG" and "wrote figure" in out
    code, _, _ = _run(capsys, "show", solved["layout"], "-o", solved["dir"] / "lay.svg")
    assert code == 0 and (solved["dir"] / "lay.svg").stat().st_size > 0


def test_scenario_writes_cases_figures_and_a_summary(capsys, tmp_path):
    out_dir = tmp_path / "out"
    code, out, err = _run(
        capsys, "scenario", "--seed", "2", "--size", "3", "3.5", "--sources", "2", "-o", out_dir
    )
    assert code == 0, err
    names = sorted(p.name for p in out_dir.iterdir())
    assert names == [
        "random-2_src0.npz",
        "random-2_src0.png",
        "random-2_src1.npz",
        "random-2_src1.png",
    ]
    for n in range(2):
        c = Case.load(out_dir / f"random-2_src{n}.npz")
        assert c.meta["mass_balance"]["outlet_flux_ratio"] == pytest.approx(1.0, abs=0.02)
    assert "outflux / q" in out and "random-2_src1" in out and "iterations" in out


class _FakeFoam:
    name = "fakefoam"

    @classmethod
    def unavailable(cls) -> str:
        return "fakeFoam not on PATH"


def test_engines_lists_builtin_and_reasons(capsys, monkeypatch):
    monkeypatch.setattr(engines_mod.ENGINES, "_entries", dict(engines_mod.ENGINES._entries))
    engines_mod.ENGINES.register("fakefoam", _FakeFoam)
    code, out, _ = _run(capsys, "engines")
    assert code == 0
    assert "builtin" in out and "available" in out
    assert "fakefoam" in out and "unavailable" in out and "fakeFoam not on PATH" in out


def test_import_floorplan(capsys, tmp_path):
    img = np.full((30, 40), 255, np.uint8)  # 4 x 3 m at 0.1 m per pixel
    img[:, 19:21] = 0
    img[10:20, 19:21] = 255  # a doorway
    Image.fromarray(img).save(tmp_path / "plan.png")
    code, out, err = _run(
        capsys,
        "import-floorplan",
        tmp_path / "plan.png",
        "--inlet",
        "west",
        "0.5",
        "1.5",
        "--outlet",
        "east",
        "1.5",
        "2.5",
        "-o",
        tmp_path / "plan.npz",
        "--plot",
        tmp_path / "plan_fig.png",
    )
    assert code == 0, err
    lay = load_layout(tmp_path / "plan.npz")
    assert lay.occupancy.shape == (30, 40) and lay.name == "plan"
    assert lay.inlets == (Opening("west", 0.5, 1.5),)
    assert (tmp_path / "plan_fig.png").exists()
    code, out, err = _run(
        capsys,
        "import-floorplan",
        tmp_path / "plan.png",
        "--inlet",
        "up",
        "0.5",
        "1.5",
        "--outlet",
        "east",
        "1.5",
        "2.5",
        "-o",
        tmp_path / "x.npz",
    )
    _assert_user_error(code, out, err, "unknown boundary side 'up'")


def test_import_floorplan_keeps_every_inlet_and_outlet(capsys, tmp_path):
    """Repeated --inlet/--outlet options each become an opening, in the order given."""
    img = np.full((30, 40), 255, np.uint8)  # 4 x 3 m at 0.1 m per pixel, no inner wall
    Image.fromarray(img).save(tmp_path / "plan.png")
    args = ["--inlet", "west", "0.5", "1.5", "--inlet", "south", "0.3", "1.2"]
    args += ["--outlet", "east", "1.5", "2.5", "--outlet", "north", "2.5", "3.5"]
    args += ["--outlet", "east", "0.2", "0.9", "-o", tmp_path / "plan.npz"]
    code, out, err = _run(capsys, "import-floorplan", tmp_path / "plan.png", *args)
    assert code == 0, err
    lay = load_layout(tmp_path / "plan.npz")
    assert lay.inlets == (Opening("west", 0.5, 1.5), Opening("south", 0.3, 1.2))
    assert lay.outlets == (Opening("east", 1.5, 2.5), Opening("north", 2.5, 3.5), Opening("east", 0.2, 0.9))
    assert "inlets west 0.5-1.5 m, south 0.3-1.2 m;" in " ".join(out.split())


# -- errors: exit 2, one line, no traceback (no solver run) ------------------------------
def test_solve_not_an_npz(capsys, tmp_path):
    bad = tmp_path / "bad.npz"
    bad.write_text("not a zip")
    _assert_user_error(*_run(capsys, "solve", bad, "-o", tmp_path / "o.npz"), str(bad), "not an .npz file")
    _assert_user_error(
        *_run(capsys, "solve", tmp_path / "missing.npz", "-o", tmp_path / "o.npz"), "no such file"
    )


def test_solve_missing_keys(capsys, solved, tmp_path):
    only_occ = tmp_path / "occ.npz"
    np.savez(only_occ, occupancy=np.zeros((5, 5), np.uint8))
    _assert_user_error(*_run(capsys, "solve", only_occ, "-o", tmp_path / "o.npz"), "missing key(s) meta")
    with np.load(solved["case"]) as data:
        arrays = {k: data[k] for k in data.files if k != "concentration"}
    no_conc = tmp_path / "no_conc.npz"
    np.savez(no_conc, **arrays)
    _assert_user_error(
        *_run(capsys, "solve", no_conc, "-o", tmp_path / "o.npz"), "missing key(s) concentration"
    )


def test_solve_source_in_a_wall_or_outside(capsys, solved, tmp_path):
    args = ["solve", solved["layout"], "-o", tmp_path / "o.npz", "-v", "1", "-q", "1"]
    _assert_user_error(*_run(capsys, *args, "--source", *WALL), "lies in a wall", "(1.45, 0.55)")
    _assert_user_error(*_run(capsys, *args, "--source", "5", "1"), "outside")
    assert not (tmp_path / "o.npz").exists()


def test_solve_case_file_with_a_source_in_a_wall(capsys, solved, tmp_path):
    with np.load(solved["case"]) as data:
        arrays = {k: data[k] for k in data.files}
    arrays["source"] = np.array([float(WALL[0]), float(WALL[1])], np.float32)
    bad = tmp_path / "wall_case.npz"
    np.savez(bad, **arrays)
    _assert_user_error(*_run(capsys, "solve", bad, "-o", tmp_path / "o.npz"), "lies in a solid cell")


def test_solve_bad_arguments(capsys, solved, tmp_path):
    out = tmp_path / "o.npz"
    _assert_user_error(
        *_run(capsys, "solve", solved["layout"], "-o", out),
        "layout file",
        "--inlet-velocity",
        "--seed",
    )
    _assert_user_error(
        *_run(capsys, "solve", solved["layout"], "-o", out, "-v", "-1", "--source", *SOURCE, "-q", "1"),
        "--inlet-velocity",
        "positive",
    )
    _assert_user_error(
        *_run(capsys, "solve", solved["case"], "-o", out, "--rate", "2"),
        "--rate",
        "layout files only",
    )


def test_unknown_engine(capsys, solved, tmp_path):
    _assert_user_error(
        *_run(capsys, "solve", solved["case"], "-o", tmp_path / "o.npz", "--engine", "nope"),
        "unknown engine 'nope'",
        "builtin",
    )
    _assert_user_error(*_run(capsys, "scenario", "--engine", "nope", "-o", tmp_path), "unknown engine 'nope'")


def test_show_bad_format_and_meta(capsys, solved, tmp_path):
    _assert_user_error(
        *_run(capsys, "show", solved["case"], "-o", tmp_path / "f.xyz"),
        "cannot write a figure",
        ".png",
    )
    with np.load(solved["case"]) as data:
        arrays = {k: data[k] for k in data.files}
    arrays["meta"] = np.array(json.dumps([1, 2]))
    bad = tmp_path / "bad_meta.npz"
    np.savez(bad, **arrays)
    _assert_user_error(*_run(capsys, "show", bad, "-o", tmp_path / "f.png"), "meta is not a JSON object")


def test_errors_in_a_real_process(solved, tmp_path):
    r = _subprocess(
        "solve",
        str(solved["layout"]),
        "-o",
        str(tmp_path / "o.npz"),
        "-v",
        "1",
        "-q",
        "1",
        "--source",
        *WALL,
    )
    assert r.returncode == 2
    assert r.stderr.strip().startswith("error: ") and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize(("argv", "status"), [(["engines"], 0), (["solve", "missing.npz", "-o", "x.npz"], 2)])
def test_console_script_exits_with_mains_status_and_sets_the_collector(monkeypatch, argv, status):
    """``run`` (the installed ``dgse``) exits with ``main``'s status; it raised the collector's
    first threshold before the command and froze the live objects after it."""
    import gc

    from dgse.cli import process
    from dgse.cli.main import run

    monkeypatch.setattr(sys, "argv", ["dgse", *argv])
    before = gc.get_threshold()
    assert before[0] != process.GEN0_THRESHOLD
    try:
        with pytest.raises(SystemExit) as exit_:
            run()
        assert exit_.value.code == status
        assert gc.get_threshold() == (process.GEN0_THRESHOLD, *before[1:])
        assert gc.get_freeze_count() > 0
    finally:
        gc.unfreeze()
        gc.set_threshold(*before)


@dataclass(frozen=True)
class _Pair:
    """A bundle of two options (for the option_bundle test)."""

    a: Annotated[int, typer.Option("--a", help="first")] = 1
    b: Annotated[str | None, typer.Option("--b", help="second")] = None


_SEEN: list[tuple[int, _Pair, int]] = []


def _bundled_cmd(
    first: Annotated[int, typer.Option("--first")] = 0,
    pair: _Pair = _Pair(),
    last: Annotated[int, typer.Option("--last")] = 0,
) -> None:
    _SEEN.append((first, pair, last))


def test_option_bundle_declares_shared_options_once():
    """The bundle's options stand where its parameter stood and reach the command as one object."""
    from typer.testing import CliRunner

    from dgse.cli.common import option_bundle

    cmd = option_bundle("pair", _Pair)(_bundled_cmd)
    app = typer.Typer()
    app.command("cmd")(cmd)
    app.command("other")(lambda: None)
    runner = CliRunner()
    _SEEN.clear()
    assert runner.invoke(app, ["cmd", "--a", "3", "--last", "2"]).exit_code == 0
    assert runner.invoke(app, ["cmd", "--b", "x", "--first", "5"]).exit_code == 0
    assert _SEEN == [(0, _Pair(3, None), 2), (5, _Pair(1, "x"), 0)]
    help_text = runner.invoke(app, ["cmd", "--help"]).output
    order = [help_text.index(flag) for flag in ("--first", "--a", "--b", "--last")]
    assert order == sorted(order) and "--pair" not in help_text
    cmd(first=1, last=4)  # called from Python: the bundle's defaults
    assert _SEEN[-1] == (1, _Pair(), 4)
    with pytest.raises(TypeError, match="no parameter 'nope'"):
        option_bundle("nope", _Pair)(_bundled_cmd)
