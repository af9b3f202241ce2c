"""Dataset generation on Dask: a tiny paper-shaped dataset, resuming after SIGKILL, errors, CLI."""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from dgse.cli.main import main as dgse_main
from dgse.data.generation import ClusterError, generate, layout_id_for, solve_layout
from dgse.data.store import SPLITS, DatasetStore, Journal, assign_splits, cases_equal
from dgse.errors import ConvergenceError, InputDataError, UnsupportedError

#: Tiny layouts: one solve takes a fraction of a second.
TINY = {"width_range": (3.0, 3.5), "height_range": (3.0, 3.5)}
#: A seed whose first tiny layouts all converge at the first attempt.
SEED = 3


def check_store(path: Path, n: int, seed: int = SEED) -> None:
    """Exactly layouts 0..n-1, each with 4 loadable cases, nothing duplicated or left over."""
    splits = assign_splits(n, seed)
    with DatasetStore(path) as s:
        assert s.layouts() == [layout_id_for(i) for i in range(n)]
        assert s.layout_indices() == set(range(n))
        assert s.failures() == []
        names = []
        for i, lid in enumerate(s.layouts()):
            assert s.split_of(lid) == splits[i]
            cases = s.layout_cases(lid)
            assert len(cases) == 4
            for k, c in enumerate(cases):
                assert c.name == f"{lid}_src{k}"
                assert c.meta["generation"]["layout_index"] == i
                assert c.meta["solver"] == "builtin"
                names.append(c.name)
            assert len({tuple(c.source) for c in cases}) == 4
        assert len(names) == len(set(names)) == 4 * n
        for sp in ("val", "test"):
            assert s.has_fixed_configurations(sp)
    assert not Journal(path).dir.exists()
    assert not list(path.parent.glob(f".{path.name}*"))


def test_tiny_dataset_is_shaped_like_the_papers(tmp_path):
    out = tmp_path / "tiny.h5"
    report = generate(4, out, workers=2, seed=SEED, progress=False, **TINY)
    assert report.complete and report.n_new == 4 and report.n_layouts == 4
    assert report.splits == {"train": 2, "val": 1, "test": 1}
    assert report.layouts_per_minute > 0
    check_store(out, 4)
    with DatasetStore(out) as s:
        info = s.generation_info
        assert info["seed"] == SEED and info["n_sources"] == 4 and info["engine"] == "builtin"
        fx = s.fixed_configurations("val")
        assert len(fx) == 4 * 30 and fx.seed == SEED
        # the task is pure: the same draws in this process as on the workers
        stored = s.case(layout_id_for(2), 0)
    res = solve_layout(SEED, 2, layout_kwargs=TINY)
    assert res.ok and res.cases is not None
    assert np.array_equal(res.cases[0].occupancy, stored.occupancy)
    assert np.array_equal(res.cases[0].source, stored.source)
    assert res.cases[0].meta["inlet_velocity"] == stored.meta["inlet_velocity"]
    # done: a second run submits nothing (no cluster), other parameters are refused
    again = generate(4, out, workers=2, seed=SEED, progress=False, **TINY)
    assert again.n_before == 4 and again.n_new == 0
    with pytest.raises(InputDataError, match="seed"):
        generate(4, out, seed=SEED + 1, progress=False, **TINY)
    with pytest.raises(InputDataError, match="n_layouts"):
        generate(5, out, seed=SEED, progress=False, **TINY)
    # one generator per store at a time
    from dgse.data.generation import _generation_lock

    with _generation_lock(out), pytest.raises(InputDataError, match="another process"):
        generate(4, out, seed=SEED, progress=False, **TINY)


def untimed(case):
    return dataclasses.replace(case, meta={k: v for k, v in case.meta.items() if k != "timings"})


def test_one_split_first_then_the_rest(tmp_path):
    n = 6
    splits = assign_splits(n, SEED)
    wanted = [i for i in range(n) if splits[i] in ("val", "test")]
    out = tmp_path / "part.h5"
    report = generate(n, out, workers=1, seed=SEED, progress=False, only_splits=["val", "test"], **TINY)
    assert not report.complete and report.n_new == len(wanted) and report.n_before == 0
    with DatasetStore(out) as s:
        assert s.layout_indices() == set(wanted)
        assert {s.split_of(lid) for lid in s.layouts()} == {"val", "test"}
        assert s.has_fixed_configurations("test")
        part = {lid: s.case(lid, 0) for lid in s.layouts()}
        test_configs = s.fixed_configurations("test")
    # running again without the filter completes the store; what was made stays as it was
    report = generate(n, out, workers=1, seed=SEED, progress=False, **TINY)
    assert report.complete and report.n_before == len(wanted) and report.n_new == n - len(wanted)
    check_store(out, n)
    with DatasetStore(out) as s:
        for lid, case in part.items():
            assert cases_equal(s.case(lid, 0), case)
        again = s.fixed_configurations("test")
        assert np.array_equal(again.cells, test_configs.cells)
    # the same layouts as a store made in one go
    whole = tmp_path / "whole.h5"
    generate(n, whole, workers=1, seed=SEED, progress=False, **TINY)
    with DatasetStore(whole) as s:
        for lid, case in part.items():  # equal but for the solver's wall times in meta
            assert cases_equal(untimed(s.case(lid, 0)), untimed(case))
    with pytest.raises(InputDataError, match=r"unknown split.*dev: the splits are train, val, test"):
        generate(n, tmp_path / "bad.h5", seed=SEED, progress=False, only_splits=["dev"], **TINY)
    with pytest.raises(InputDataError, match="none given"):
        generate(n, tmp_path / "bad.h5", seed=SEED, progress=False, only_splits=[], **TINY)


def test_resume_after_sigkill(tmp_path):
    n = 6
    out = tmp_path / "killed.h5"
    code = (
        "from dgse.data.generation import generate\n"
        f"generate({n}, {str(out)!r}, workers=1, seed={SEED}, progress=False, checkpoint_s=0, "
        f"width_range={TINY['width_range']}, height_range={TINY['height_range']})\n"
    )
    proc = subprocess.Popen(
        [sys.executable, "-c", code],
        start_new_session=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    before: dict = {}
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and proc.poll() is None:
            if out.exists():
                with DatasetStore(out) as s:
                    if len(s) >= 1:
                        before = {lid: s.layout_cases(lid) for lid in s.layouts()}
                        break
            time.sleep(0.02)
        assert before, "the generator stored no layout within 60 s"
        os.kill(proc.pid, signal.SIGKILL)
        assert proc.wait(timeout=10) == -signal.SIGKILL
    finally:
        if proc.poll() is None:
            proc.kill()
        try:  # the killed run's orphaned workers (our own process group)
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    assert 1 <= len(before) < n, "the kill should land in the middle of the run"
    report = generate(n, out, workers=1, seed=SEED, progress=False, **TINY)
    assert report.n_before >= len(before) and report.n_before + report.n_new == n
    check_store(out, n)
    with DatasetStore(out) as s:  # what was stored before the kill is unchanged
        for lid, cases in before.items():
            for k, c in enumerate(cases):
                assert cases_equal(s.case(lid, k), c)


def test_failures_are_recorded_and_not_resubmitted(tmp_path, monkeypatch):
    """A layout that never converges is recorded (seed, reason) once, on an in-process cluster."""
    from distributed import Client, LocalCluster

    import dgse.physics.scenario as scenario

    real = scenario.solve_cases

    def flaky(layout, v_in, sources, engine="builtin", name=None):
        if name == layout_id_for(1):
            raise ConvergenceError("flow did not converge (test)")
        return real(layout, v_in, sources, engine, name)

    monkeypatch.setattr(scenario, "solve_cases", flaky)
    out = tmp_path / "fail.h5"
    with (
        LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cl,
        Client(cl) as client,
    ):
        r = generate(3, out, scheduler=client, seed=SEED, progress=False, retries=1, **TINY)
        assert r.n_new == 2 and r.n_failed_new == 1 and r.complete
        again = generate(3, out, scheduler=client, seed=SEED, progress=False, retries=1, **TINY)
        assert again.n_before == 3 and again.n_new == again.n_failed_new == 0
    with DatasetStore(out) as s:
        assert s.layouts() == [layout_id_for(0), layout_id_for(2)]
        (rec,) = s.failures()
    assert rec["layout_index"] == 1 and rec["seed"] == SEED and rec["entropy"] == [SEED, 1, 1]
    assert rec["error"] == "ConvergenceError" and "test" in rec["reason"]
    assert [a["attempt"] for a in rec["attempts"]] == [0, 1]


def test_unknown_engine_fails_before_any_work(tmp_path):
    out = tmp_path / "x.h5"
    t0 = time.perf_counter()
    with pytest.raises(UnsupportedError, match="unknown engine 'nope'"):
        generate(2, out, engine="nope", progress=False)
    assert time.perf_counter() - t0 < 2 and not out.exists()
    with pytest.raises(InputDataError, match="unknown layout option"):
        generate(2, out, progress=False, widht_range=(3, 4))
    assert not out.exists()


def test_unreachable_scheduler_is_a_clear_error(tmp_path):
    out = tmp_path / "x.h5"
    t0 = time.perf_counter()
    with pytest.raises(ClusterError, match=r"cannot reach the Dask scheduler at 'tcp://127\.0\.0\.1:1'"):
        generate(2, out, scheduler="tcp://127.0.0.1:1", connect_timeout=1.0, progress=False, **TINY)
    assert time.perf_counter() - t0 < 5 and not out.exists()
    assert not list(tmp_path.iterdir())  # no store, no lock file
    with pytest.raises(ClusterError, match="cannot reach"):
        generate(2, out, scheduler="not an address:::", progress=False, **TINY)


def test_cli_commands(tmp_path, capsys):
    # generate: user errors are one red line and exit status 2
    assert dgse_main(["generate", "-n", "2", "-o", str(tmp_path / "x.h5"), "-e", "nope"]) == 2
    assert "unknown engine" in capsys.readouterr().err
    assert dgse_main(["data", "stats", str(tmp_path / "missing.h5")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no such dataset store" in err
    # export/import/stats on a store of synthetic cases
    from tests.data.test_store import synthetic_layout_cases

    store = tmp_path / "s.h5"
    with DatasetStore(store, "w") as s:
        s.add_layout(synthetic_layout_cases(0), "train")
        s.add_layout(synthetic_layout_cases(1, n_sources=2), "test")
    assert dgse_main(["export", str(store), "--out", str(tmp_path / "cases")]) == 0
    assert len(list((tmp_path / "cases").glob("*.npz"))) == 6
    back = tmp_path / "back.h5"
    assert dgse_main(["import", str(tmp_path / "cases"), "--out", str(back), "--split", "val"]) == 0
    assert "imported 6 cases as 2 layouts" in capsys.readouterr().out
    assert dgse_main(["import", str(tmp_path / "cases"), "--out", str(back), "--split", "dev"]) == 2
    fig, js = tmp_path / "stats.png", tmp_path / "stats.json"
    assert dgse_main(["data", "stats", str(back), "--plot", str(fig), "--json", str(js)]) == 0
    st = json.loads(js.read_text())
    assert st["n_layouts"] == 2 and st["n_cases"] == 6
    assert st["splits"]["val"] == {"layouts": 2, "cases": 6}
    assert set(st["splits"]) == set(SPLITS) and fig.stat().st_size > 10_000


def test_register_attaches_commands():
    import typer
    from typer.testing import CliRunner

    from dgse.cli.data import register

    app = typer.Typer()

    @app.command("other")
    def other() -> None:
        """Another command."""

    register(app)
    runner = CliRunner()
    out = runner.invoke(app, ["--help"]).output
    for name in ("generate", "export", "import", "data"):
        assert name in out
    assert "stats" in runner.invoke(app, ["data", "--help"]).output


def test_ctrl_c_stops_generation_and_keeps_what_was_done(tmp_path):
    """Ctrl-C (SIGINT to the whole process group, as a terminal sends it) stops ``dgse generate``
    soon (not lost in Dask's callbacks): exit 130, one line (no worker's traceback), layouts kept."""
    n = 8
    out = tmp_path / "interrupted.h5"
    lo, hi = TINY["width_range"]
    cmd = [sys.executable, "-m", "dgse.cli.main", "generate", "--layouts", str(n), "--out", str(out),
           "--workers", "1", "--seed", str(SEED), "--checkpoint", "0", "--no-progress",
           "--size", str(lo), str(hi)]  # fmt: skip
    proc = subprocess.Popen(
        cmd, start_new_session=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        deadline = time.monotonic() + 60
        stored = 0
        while time.monotonic() < deadline and proc.poll() is None and not stored:
            if out.exists():
                with DatasetStore(out) as s:
                    stored = len(s)
            time.sleep(0.05)
        assert stored, "the generator stored no layout within 60 s"
        os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    assert proc.returncode == 130, err
    line = err.strip()
    assert "\n" not in line and line.startswith("interrupted: ") and "Traceback" not in err, err
    assert "finished layout" in line and "resume with: dgse generate --layouts 8" in line
    with DatasetStore(out) as s:
        kept = len(s)
    assert 1 <= kept < n
    report = generate(n, out, workers=1, seed=SEED, progress=False, **TINY)
    assert report.n_before == kept and report.n_before + report.n_new == n
