"""Atomic writes (dgse.files): the target is the old file or the new one, never a torn one."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from dgse.files import (
    atomic_open,
    atomic_path,
    is_temporary,
    lock_path,
    temporary_name,
    update_json,
    write_bytes,
    write_json,
    write_text,
)

SRC = Path(__file__).resolve().parents[1] / "src"


def _names(d: Path) -> list[str]:
    return sorted(p.name for p in d.iterdir())


class _Interrupted(BaseException):
    """Stands for Ctrl-C: not an ``Exception``, so only a ``BaseException`` handler cleans up."""


@pytest.mark.parametrize("error", [RuntimeError, KeyboardInterrupt, _Interrupted])
def test_a_failed_block_keeps_the_old_file_and_leaves_no_temporary(tmp_path, error):
    target = tmp_path / "result.json"
    target.write_text("old")
    with pytest.raises(error), atomic_path(target) as tmp:
        tmp.write_text("new but torn")
        raise error
    assert target.read_text() == "old"
    assert _names(tmp_path) == ["result.json"]


def test_a_failed_first_write_leaves_nothing(tmp_path):
    target = tmp_path / "new.csv"
    with pytest.raises(RuntimeError), atomic_path(target) as tmp:
        tmp.write_text("a,b\n")
        raise RuntimeError
    assert _names(tmp_path) == []


def test_a_finished_block_replaces_the_file_only_at_the_end(tmp_path):
    target = tmp_path / "result.txt"
    target.write_text("old")
    with atomic_path(target) as tmp:
        tmp.write_text("new")
        assert target.read_text() == "old"  # readers see the old file until the block ends
    assert target.read_text() == "new"
    assert _names(tmp_path) == ["result.txt"]


def test_the_temporary_file_is_hidden_beside_the_target_with_its_suffix(tmp_path):
    target = tmp_path / "sub" / "case.npz"
    target.parent.mkdir()
    with atomic_path(target) as tmp:
        assert tmp.parent == target.parent
        assert tmp.suffix == ".npz" and tmp.name.startswith(".case.npz.tmp-")
        assert tmp.is_file() and is_temporary(tmp)
        np.savez(tmp, x=np.arange(3))  # would append ".npz" to a name without that suffix
        assert _names(target.parent) == [tmp.name]
    with np.load(target) as data:
        assert data["x"].tolist() == [0, 1, 2]
    assert _names(target.parent) == ["case.npz"]


def test_savefig_through_the_temporary_name_keeps_the_format(tmp_path):
    from matplotlib.figure import Figure

    for name, magic in (("f.png", b"\x89PNG"), ("f.pdf", b"%PDF")):
        with atomic_path(tmp_path / name) as tmp:
            Figure().savefig(tmp)
        assert (tmp_path / name).read_bytes()[:4] == magic
    assert _names(tmp_path) == ["f.pdf", "f.png"]


def test_temporary_names_are_fresh_and_recognised(tmp_path):
    a, b = temporary_name(tmp_path / "x.json"), temporary_name(tmp_path / "x.json")
    assert a != b and is_temporary(a) and is_temporary(b)
    assert is_temporary(temporary_name(tmp_path / "no_suffix"))
    assert not is_temporary(tmp_path / "x.json")
    assert not is_temporary(tmp_path / ".x.json")
    assert not is_temporary(tmp_path / "x.json.tmp")
    long = temporary_name(tmp_path / ("n" * 250 + ".json"))
    assert len(long.name.encode()) <= 255 and long.suffix == ".json"


def test_the_helpers_write_exactly_the_text(tmp_path):
    obj = {"b": [1, 2.5], "a": "é", "n": None}
    p = write_json(tmp_path / "a.json", obj, indent=1)
    assert p.read_bytes() == json.dumps(obj, indent=1).encode()
    write_json(p, obj, end="\n", sort_keys=True)
    assert p.read_bytes() == (json.dumps(obj, sort_keys=True) + "\n").encode()
    assert write_text(tmp_path / "t.md", "a\nb").read_bytes() == b"a\nb"
    assert write_bytes(tmp_path / "b.bin", b"\x00\x01").read_bytes() == b"\x00\x01"
    with atomic_open(tmp_path / "c.csv", "w", newline="") as fh:
        fh.write("a,b\r\n")
    assert (tmp_path / "c.csv").read_bytes() == b"a,b\r\n"
    assert _names(tmp_path) == ["a.json", "b.bin", "c.csv", "t.md"]


def test_an_object_that_is_not_json_keeps_the_old_file(tmp_path):
    p = write_json(tmp_path / "a.json", {"ok": 1})
    with pytest.raises(TypeError):
        write_json(p, {"bad": object()})
    with pytest.raises(ValueError):
        write_json(p, {"nan": float("nan")}, allow_nan=False)
    assert json.loads(p.read_text()) == {"ok": 1}
    assert _names(tmp_path) == ["a.json"]


def test_atomic_open_refuses_appending(tmp_path):
    with pytest.raises(ValueError, match="whole file"), atomic_open(tmp_path / "j.jsonl", "a"):
        pass
    assert _names(tmp_path) == []


def test_a_symlink_is_written_through(tmp_path):
    real = tmp_path / "real.json"
    real.write_text("old")
    link = tmp_path / "link.json"
    link.symlink_to(real.name)
    write_text(link, "new")
    assert link.is_symlink() and real.read_text() == "new"


def test_the_permissions_follow_the_umask_as_open_does(tmp_path):
    old = os.umask(0o022)
    try:
        write_text(tmp_path / "a.txt", "x")
    finally:
        os.umask(old)
    assert (tmp_path / "a.txt").stat().st_mode & 0o777 == 0o644


def test_update_json_creates_then_updates(tmp_path):
    p = tmp_path / "t.json"
    assert update_json(p, lambda d: {**d, "a": 1}, default={}, indent=1) == {"a": 1}
    assert update_json(p, lambda d: {**d, "b": 2}, default={}, indent=1) == {"a": 1, "b": 2}
    assert p.read_text() == json.dumps({"a": 1, "b": 2}, indent=1)
    assert _names(tmp_path) == [lock_path(p).name, "t.json"]
    with pytest.raises(RuntimeError):
        update_json(p, lambda d: (_ for _ in ()).throw(RuntimeError("no")))
    assert json.loads(p.read_text()) == {"a": 1, "b": 2}


def test_update_json_waits_for_a_writer_that_holds_the_lock(tmp_path):
    """A second update while the first is between its read and its write sees the first's result."""
    p = tmp_path / "t.json"
    inside, seen = threading.Event(), []

    def slow(d: dict) -> dict:
        inside.set()
        threading.Event().wait(0.3)  # the second writer tries meanwhile
        return {**d, "first": 1}

    def second(d: dict) -> dict:
        seen.append(dict(d))
        return {**d, "second": 2}

    t = threading.Thread(target=update_json, args=(p, slow), kwargs={"default": {}})
    t.start()
    assert inside.wait(5)
    update_json(p, second, default={})
    t.join()
    assert seen == [{"first": 1}]  # without the lock it would have read {} and lost "first"
    assert json.loads(p.read_text()) == {"first": 1, "second": 2}


def test_update_json_from_two_processes_loses_no_update(tmp_path):
    p = tmp_path / "counter.json"
    n = 40
    code = (
        "import sys\n"
        "from dgse.files import update_json\n"
        "for _ in range(int(sys.argv[2])):\n"
        "    update_json(sys.argv[1], lambda d: {'n': d['n'] + 1, 'by': d['by'] + [sys.argv[3]]},"
        " default={'n': 0, 'by': []})\n"
    )
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(SRC), os.environ.get("PYTHONPATH", "")])}
    procs = [subprocess.Popen([sys.executable, "-c", code, str(p), str(n), w], env=env) for w in "ab"]
    assert [q.wait(timeout=120) for q in procs] == [0, 0]
    got = json.loads(p.read_text())
    assert got["n"] == 2 * n and sorted(got["by"]) == ["a"] * n + ["b"] * n
    assert not any(is_temporary(q) for q in tmp_path.iterdir())


# -- results written through the helper --------------------------------------------------------
def test_an_interrupted_bench_table_keeps_the_old_csv(tmp_path):
    from dgse.bench.core import BenchContext

    class Boom:
        def __str__(self) -> str:
            raise KeyboardInterrupt

    ctx = BenchContext("suite", tmp_path)
    sec = ctx.section("s")
    path = sec.table("t", [{"a": 1, "b": "x"}, {"a": 2, "b": "y"}], "caption")
    old = path.read_bytes()
    assert old == b"a,b\r\n1,x\r\n2,y\r\n"
    with pytest.raises(KeyboardInterrupt):
        sec.table("t", [{"a": 3, "b": "z"}, {"a": Boom(), "b": "w"}], "caption")
    assert path.read_bytes() == old
    assert not any(is_temporary(q) for q in ctx.out.iterdir())


def test_bench_timings_from_parallel_writers_are_all_kept(tmp_path):
    from dgse.bench.core import TIMINGS, BenchContext

    ctxs = [BenchContext("suite", tmp_path) for _ in range(4)]

    def record(k: int) -> None:
        for i in range(15):
            ctxs[k]._record_seconds(f"r{k}-{i}", 0.5)

    threads = [threading.Thread(target=record, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    timings = json.loads((ctxs[0].out / TIMINGS).read_text())
    assert len(timings) == 60 and set(timings.values()) == {0.5}
    assert ctxs[0].compute_seconds() == 30.0


def test_a_stale_temporary_file_is_not_read_as_a_result(tmp_path):
    from dgse.bench.core import BenchContext

    ctx = BenchContext("suite", tmp_path)
    ctx.save_json("r", {"seconds_total": 2.0})
    (ctx.out / temporary_name(ctx.out / "r.json").name).write_text(json.dumps({"seconds_total": 5.0}))
    assert ctx.compute_seconds() == 2.0


def test_an_interrupted_cli_figure_keeps_the_old_one(tmp_path, monkeypatch):
    from matplotlib.figure import Figure

    from dgse.cli.common import EXIT_INTERRUPTED
    from dgse.cli.main import main

    png = tmp_path / "l.png"
    assert main(["layout", "--seed", "3", "-o", str(tmp_path / "l.npz"), "--plot", str(png)]) == 0
    with Image.open(png) as im:
        im.verify()  # a complete PNG
    old = png.read_bytes()
    real = Figure.savefig

    def torn(self, fname, *args, **kwargs):
        Path(fname).write_bytes(b"\x89PNG half")
        raise KeyboardInterrupt

    monkeypatch.setattr(Figure, "savefig", torn)
    code = main(["layout", "--seed", "4", "-o", str(tmp_path / "l.npz"), "--plot", str(png)])
    assert code == EXIT_INTERRUPTED
    assert png.read_bytes() == old
    monkeypatch.setattr(Figure, "savefig", real)
    assert _names(tmp_path) == ["l.npz", "l.png"]


def test_an_interrupted_case_file_keeps_the_old_case(tmp_path, monkeypatch):
    from dgse.world.case import Case

    occ = np.zeros((4, 5), np.uint8)
    case = Case(
        occupancy=occ,
        wind=np.zeros((2, 4, 5), np.float32),
        concentration=np.ones((4, 5), np.float32),
        source=np.array([0.25, 0.25], np.float32),
        resolution=0.1,
        meta={"name": "c"},
    )
    path = case.save(tmp_path / "c.npz")
    old = path.read_bytes()

    def torn(fh, **arrays):
        fh.write(b"PK\x03\x04 half")
        raise KeyboardInterrupt

    monkeypatch.setattr(np, "savez_compressed", torn)
    with pytest.raises(KeyboardInterrupt):
        case.with_meta(name="d").save(path)
    assert path.read_bytes() == old
    assert _names(tmp_path) == ["c.npz"]
