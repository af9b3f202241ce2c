"""The command line as a user meets it: one rule for Ctrl-C, messages in the user's terms,
arguments checked before any output, no silent acceptance, one meaning per option name,
help that is never cut, output a person can read.

Every test makes its own tiny inputs and runs in seconds: the work a command would do is
replaced (monkeypatched) where only the command's edge is under test.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from dgse.data.store import DatasetStore
from dgse.physics.scenario import solve_cases
from tests.conftest import two_rooms
from tests.test_cli import COMMANDS, SRC, _assert_user_error, _run

REPO = Path(__file__).resolve().parents[1]
TINY_CONFIG = REPO / "configs" / "train" / "tiny-test.yaml"


@pytest.fixture(scope="module")
def case_file(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("usability")
    case = solve_cases(two_rooms(), 1.0, [((2.05, 0.55), 0.8)])[0]
    return case.save(d / "two_rooms_src0.npz")


def _interrupted(code: int, out: str, err: str, *fragments: str) -> str:
    """Exit status 130 and one ``interrupted: ...`` line on stderr, no traceback; the line."""
    assert code == 130, (out, err)
    assert "Traceback" not in out + err
    line = err.strip()
    assert line.startswith("interrupted: ") and "\n" not in line, err
    for f in fragments:
        assert f in line, (f, line)
    return line


def _raise_interrupt(*args, **kwargs):
    raise KeyboardInterrupt


# -- 1. Ctrl-C: exit 130, one line saying what was kept and how to resume ----------------------
def test_ctrl_c_in_train_is_130_and_says_how_to_resume(capsys, monkeypatch, tmp_path):
    import importlib

    from dgse.training.train import TrainResult

    train_module = importlib.import_module("dgse.training.train")  # the package exports a function `train`

    data = tmp_path / "tiny.h5"
    data.write_bytes(b"")  # only its existence is checked before training
    args = ["train", "--config", TINY_CONFIG, "--data", data, "--out", tmp_path / "run"]
    monkeypatch.setattr(train_module, "train", _raise_interrupt)
    line = _interrupted(*_run(capsys, *args), "nothing was kept")
    assert "resume" not in line  # no epoch was saved: nothing to resume

    def stopped(config, resume=False):  # the first Ctrl-C: training stops cleanly and saves
        run = Path(config.out_dir)
        return TrainResult(run, run / "last.safetensors", None, None, run / "history.csv", None,
                           1, 2, None, None, "interrupted", 1.0)  # fmt: skip

    monkeypatch.setattr(train_module, "train", stopped)
    monkeypatch.setattr(
        train_module, "read_train_state", lambda path, config=None: type("S", (), {"next_epoch": 1})()
    )
    code, out, err = _run(capsys, *args)
    line = _interrupted(code, out, err, "1 epoch kept in", "resume with: dgse train")
    assert line.endswith("--resume") and "epochs done" not in out  # no summary after an interrupt


def test_ctrl_c_in_demo_says_nothing_was_kept(capsys, monkeypatch, tmp_path):
    import dgse.physics.scenario as scenario

    monkeypatch.setattr(scenario, "random_cases", _raise_interrupt)
    args = ["demo", "--seed", "1", "--method", "kdmv", "--no-animate", "-o", tmp_path / "d"]
    _interrupted(*_run(capsys, *args), "nothing was kept")


def test_ctrl_c_in_search_evaluate_generate_names_the_command_that_resumes(
    capsys, monkeypatch, tmp_path, case_file
):
    import importlib

    import dgse.data.generation as generation
    import dgse.search.episode as episode

    evaluation = importlib.import_module("dgse.evaluation.evaluate")  # the package exports `evaluate`

    monkeypatch.setattr(episode, "run_episode", _raise_interrupt)
    out = tmp_path / "s.json"
    args = ["search", case_file, "--method", "kdmv", "--trials", "1", "-o", out, "--no-progress"]
    _interrupted(*_run(capsys, *args), "0 finished episodes kept in", "resume with: dgse search")
    assert not out.exists()

    monkeypatch.setattr(evaluation, "evaluate", _raise_interrupt)
    args = ["evaluate", case_file, "-n", "5", "--method", "kdmv", "-o", tmp_path / "e.json"]
    _interrupted(*_run(capsys, *args), "finished estimates kept in", "resume with: dgse evaluate")

    monkeypatch.setattr(generation, "generate", _raise_interrupt)
    store = tmp_path / "g.h5"
    line = _interrupted(
        *_run(capsys, "generate", "--layouts", "3", "--out", store, "--size", "3", "3.5"),
        "0 finished layouts kept in",
    )
    assert line.endswith(f"resume with: dgse generate --layouts 3 --out {store} --size 3.0 3.5")


def test_ctrl_c_in_a_command_that_does_not_resume(capsys, monkeypatch, tmp_path, case_file):
    import dgse.physics.scenario as scenario

    monkeypatch.setattr(scenario, "resolve_case", _raise_interrupt)
    _interrupted(*_run(capsys, "solve", case_file, "-o", tmp_path / "o.npz"), "nothing was kept")
    assert not (tmp_path / "o.npz").exists()


# -- 2. messages in the user's terms ---------------------------------------------------------
def test_floorplan_messages_name_the_option_and_the_opening(capsys, tmp_path):
    from PIL import Image

    from dgse.errors import InputDataError
    from dgse.world.floorplan import layout_from_floorplan, load_png_map

    img = np.full((30, 40), 255, np.uint8)
    img[:, :2] = 0  # an outer wall on the west side
    Image.fromarray(img).save(tmp_path / "plan.png")
    args = ["import-floorplan", tmp_path / "plan.png", "--inlet", "west", "0.5", "1.5"]
    args += ["--outlet", "east", "1.5", "2.5", "-o", tmp_path / "p.npz"]
    code, out, err = _run(capsys, *args)
    _assert_user_error(code, out, err, "the west inlet at 0.5-1.5 m touches no free cell", "give --carve")
    assert "carve_depth_m" not in err and "{" not in err and not (tmp_path / "p.npz").exists()
    assert out == ""  # the floor plan is not announced before its openings are checked
    # the library's own message names its argument
    with pytest.raises(InputDataError, match="give carve_depth_m"):
        layout_from_floorplan(
            load_png_map(tmp_path / "plan.png"), None, [("west", 0.5, 1.5)], [("east", 1, 2)]
        )
    assert _run(capsys, *args, "--carve", "0.3")[0] == 0


def test_a_temporary_file_is_named_as_the_users_file(capsys, tmp_path, monkeypatch):
    import dgse.files

    blocker = tmp_path / ".x.npz.tmp-0000.npz"
    blocker.mkdir()  # in the way of the layout file's temporary name
    monkeypatch.setattr(dgse.files, "temporary_name", lambda path: blocker)
    code, out, err = _run(capsys, "layout", "--seed", "1", "-o", tmp_path / "x.npz")
    _assert_user_error(code, out, err, f"cannot write {tmp_path / 'x.npz'}")
    assert ".tmp-" not in err


def test_restart_is_the_option_not_the_python_argument(capsys, tmp_path, case_file):
    out = tmp_path / "e.json"
    args = ["evaluate", case_file, "-n", "5", "--method", "kdmv", "--trials", "1", "-o", out, "--no-progress"]
    assert _run(capsys, *args)[0] == 0
    code, o, err = _run(capsys, *args, "--seed", "1")
    _assert_user_error(code, o, err, "seed was 0, now 1", "start afresh with --restart")
    assert "restart=True" not in err


def test_train_blames_the_option_typed_not_the_yaml_file(capsys, tmp_path):
    data = tmp_path / "d.h5"
    data.write_bytes(b"")
    base = ["train", "--config", TINY_CONFIG, "--data", data, "--out", tmp_path / "r"]
    code, out, err = _run(capsys, *base, "--set", "epocs=1")
    _assert_user_error(code, out, err, "--set epocs=1", "unknown training config key(s) epocs")
    assert str(TINY_CONFIG) not in err
    code, out, err = _run(capsys, *base, "--batch-size", "0")
    _assert_user_error(code, out, err, "--batch-size 0", "batch_size must be an integer >= 1")
    assert str(TINY_CONFIG) not in err
    bad = tmp_path / "bad.yaml"
    bad.write_text("epocs: 1\n")
    _assert_user_error(*_run(capsys, "train", "--config", bad, "--data", data), str(bad), "epocs")


# -- 3. arguments checked before any output or work ------------------------------------------
def test_evaluate_and_search_check_their_arguments_before_saying_anything(capsys, tmp_path, case_file):
    out = tmp_path / "e.json"
    code, o, err = _run(capsys, "evaluate", case_file, "-n", "5", "--trials", "0", "-o", out)
    _assert_user_error(code, o, err, "--trials must be a positive integer")
    assert o == "" and not out.exists() and not (tmp_path / "e.journal.jsonl").exists()
    code, o, err = _run(capsys, "search", case_file, "--method", "kdmv", "--trials", "0", "-o", out)
    _assert_user_error(code, o, err, "--trials must be at least 1")
    assert o == "" and not out.exists()
    code, o, err = _run(capsys, "search", case_file, "--method", "adjoint", "-o", out)
    _assert_user_error(code, o, err, "give --knowledge openings")
    assert o == ""


def test_generate_checks_workers_before_announcing(capsys, tmp_path):
    store = tmp_path / "g.h5"
    code, out, err = _run(capsys, "generate", "--layouts", "2", "--out", store, "--workers", "-3")
    _assert_user_error(code, out, err, "--workers must be at least 1, got -3")
    assert out == "" and not list(tmp_path.iterdir())


def test_a_train_config_error_comes_before_pytorch_is_loaded(tmp_path):
    data = tmp_path / "d.h5"
    data.write_bytes(b"")
    probe = (
        "import sys; from dgse.cli.main import main; code = main(sys.argv[1:]); "
        "print(code, 'torch' in sys.modules, 'lightning' in sys.modules)"
    )
    args = ["train", "--config", str(TINY_CONFIG), "--data", str(data), "--set", "epocs=1"]
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join(filter(None, [str(SRC), os.environ.get("PYTHONPATH")])),
    }
    r = subprocess.run(
        [sys.executable, "-c", probe, *args], capture_output=True, text=True, env=env, timeout=120
    )
    assert r.stdout.split() == ["2", "False", "False"], (r.stdout, r.stderr)
    assert r.stderr.startswith("error: --set epocs=1") and len(r.stderr.strip().splitlines()) == 1


# -- 4. nothing accepted silently ------------------------------------------------------------
@pytest.mark.parametrize("command", ["estimate", "evaluate"])
def test_dtype_takes_only_the_listed_precisions(capsys, tmp_path, case_file, command):
    out = tmp_path / "x.npz"
    code, o, err = _run(capsys, command, case_file, "-n", "5", "-o", out, "--dtype", "float16")
    _assert_user_error(code, o, err, "--dtype", "'float16'", "float32", "bf16", "auto")
    assert not out.exists()


@pytest.mark.parametrize("command", ["generate", "import"])
def test_a_store_must_be_an_h5_file(capsys, tmp_path, case_file, command):
    out = tmp_path / "x.txt"
    args = ["generate", "--layouts", "2"] if command == "generate" else ["import", case_file]
    code, o, err = _run(capsys, *args, "--out", out)
    _assert_user_error(code, o, err, "x.txt", "HDF5", ".h5 or .hdf5")
    assert o == "" and not list(tmp_path.iterdir())


@pytest.fixture(scope="module")
def store(tmp_path_factory, case_file) -> Path:
    from dgse.world.case import Case

    case = Case.load(case_file)
    path = tmp_path_factory.mktemp("store") / "s.h5"
    with DatasetStore(path, "w") as s:
        for k in range(6):
            s.add_layout([case], "train", f"layout-{k}")
    return path


def _damaged(store: Path, tmp_path: Path, offset: int, size: int) -> Path:
    bad = tmp_path / f"bad-{offset}.h5"
    data = bytearray(store.read_bytes())
    data[offset : offset + size] = np.random.default_rng(offset).bytes(size)
    bad.write_bytes(bytes(data))
    return bad


def test_stats_of_a_damaged_store_is_an_error(capsys, tmp_path, store):
    from dgse.data.stats import dataset_stats

    assert _run(capsys, "data", "stats", store)[0] == 0
    with h5py.File(store, "r") as f:
        chunk = f["layouts/layout-3/concentration"].id.get_chunk_info(0)
    bad = _damaged(store, tmp_path, chunk.byte_offset, chunk.size)
    assert dataset_stats(bad)["n_layouts"] == 6  # the summaries alone look healthy
    code, out, err = _run(capsys, "data", "stats", bad)
    _assert_user_error(code, out, err, str(bad), "corrupt", "layout-3")
    assert out == ""
    # 20 kB of random bytes anywhere in the file's data
    size = store.stat().st_size
    for offset in (size // 4, size // 2, 3 * size // 4):
        _assert_user_error(
            *_run(capsys, "data", "stats", _damaged(store, tmp_path, offset, 20_000)), "corrupt"
        )


# -- 5. one meaning per name; help is never cut ----------------------------------------------
def test_o_is_the_output_file_in_every_command():
    from typer.main import get_command

    from dgse.cli.main import app, register_commands

    register_commands(["--help"])
    group = get_command(app)
    seen = {}
    for name, command in group.commands.items():  # type: ignore[attr-defined]
        for p in command.params:
            if "-o" in getattr(p, "opts", []):
                seen[name] = p.opts
    assert {"search", "evaluate", "report", "layout", "solve", "generate", "train"} <= set(seen)
    for name, opts in seen.items():
        assert "--out" in opts, (name, opts)


def test_every_command_has_the_one_rule_for_errors_and_ctrl_c():
    from dgse.cli.main import app, register_commands

    register_commands(["--help"])
    callbacks = {info.name: info.callback for info in app.registered_commands}
    for group in app.registered_groups:
        callbacks |= {f"{group.name} {i.name}": i.callback for i in group.typer_instance.registered_commands}
    assert "data stats" in callbacks and "engines" in callbacks
    unwrapped = [name for name, cb in callbacks.items() if not getattr(cb, "user_errors", False)]
    assert not unwrapped, unwrapped


def test_train_takes_the_network_not_a_model_file(capsys, tmp_path):
    code, out, err = _run(capsys, "train", "--model", "weights.safetensors", "--data", tmp_path / "d.h5")
    _assert_user_error(code, out, err, "dgse train has no --model", "--network", "--init")
    code, out, _ = _run(capsys, "train", "--help")
    assert "--network" in out and "--model" not in out


def test_evaluate_marks_observations_required(capsys, case_file):
    code, out, err = _run(capsys, "evaluate", case_file)
    _assert_user_error(code, out, err, "Missing option '--observations'", "(see dgse evaluate --help)")
    _, help_text, _ = _run(capsys, "evaluate", "--help")
    assert re.search(r"--observations N \[N \.\.\.\][^\n]*\n?[^\n]*\[required\]", help_text)


def test_usage_errors_are_one_line(capsys):
    _assert_user_error(*_run(capsys, "search", "--trials", "many"), "Invalid value for '--trials'", "'many'")
    _assert_user_error(*_run(capsys, "serch"), "No such command 'serch'")


def test_help_renders_fully_at_80_columns():
    """Every command's help (and the command list) at 80 columns: wrapped, nothing cut."""
    env = {**os.environ, "COLUMNS": "80",
           "PYTHONPATH": os.pathsep.join(filter(None, [str(SRC), os.environ.get("PYTHONPATH")]))}  # fmt: skip
    script = (
        "import sys, io, contextlib\nfrom dgse.cli.main import main\n"
        "for cmd in [[]] + [[c] for c in sys.argv[1:]] + [['data', 'stats']]:\n"
        "    f = io.StringIO()\n"
        "    with contextlib.redirect_stdout(f):\n"
        "        main([*cmd, '--help'])\n"
        "    print('=====', ' '.join(cmd)); print(f.getvalue())\n"
    )
    commands = [*COMMANDS, "bench", "report"]
    r = subprocess.run(
        [sys.executable, "-c", script, *commands], capture_output=True, text=True, env=env, timeout=120
    )
    assert r.returncode == 0, r.stderr
    pages = r.stdout.split("===== ")
    assert len(pages) == len(commands) + 3
    for page in pages[1:]:
        assert "…" not in page and "Usage:" in page, page
        assert not re.search(r"\bdgse\.[a-z]", page), page  # a default is a value, not a module path
        assert max(len(line) for line in page.splitlines()) <= 80, page
    flat = " ".join(pages[1].split())
    for summary in ("Train a DGSE network (paper Sec. III, App. A) on a dataset store, resumably.",):
        assert summary in flat  # a command's summary is not cut at its first full stop
    assert "--min-start-distance" in pages[1 + 1 + COMMANDS.index("search")]


# -- 6. output a person reads ----------------------------------------------------------------
def test_estimate_prints_positions_in_metres(capsys, tmp_path, case_file):
    code, out, err = _run(
        capsys, "estimate", case_file, "-n", "8", "--method", "kdmv", "-o", tmp_path / "e.npz"
    )
    assert code == 0, err
    flat = " ".join(out.split())
    assert re.search(r"most likely at \(\d+\.\d\d, \d+\.\d\d\) m", flat) and "cell (" not in flat


def test_search_spells_out_its_columns_and_logs_a_line_per_episode(capsys, tmp_path, case_file):
    args = ["search", case_file, "--method", "kdmv", "--trials", "2", "--time-limit", "30"]
    code, out, err = _run(capsys, *args, "-o", tmp_path / "s.json")  # capsys: no terminal
    assert code == 0, err
    flat = " ".join(out.split())
    assert "SR success rate" in flat and "ST search time" in flat and "TD travelled distance" in flat
    assert "PER path efficiency ratio = distance travelled / shortest path" in flat
    lines = [ln for ln in out.splitlines() if re.match(r"two_rooms_src0 trial [12]/2: ", ln)]
    assert len(lines) == 2 and all("error" in ln and " m, " in ln for ln in lines), out
    json.loads((tmp_path / "s.json").read_text())
