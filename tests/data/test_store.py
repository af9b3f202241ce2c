"""The dataset store: lossless round trips, splits, fixed configurations, errors, journal."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

from dgse.data.store import (
    SENSOR_COUNTS,
    SPLITS,
    DatasetStore,
    Journal,
    assign_splits,
    cases_equal,
    commit_pending,
    create_store,
    split_counts,
)
from dgse.errors import InputDataError
from dgse.world.case import Case


def synthetic_layout_cases(
    seed: int, n_sources: int = 4, shape: tuple[int, int] = (23, 31), frames: bool = False
) -> list[Case]:
    """Cases of one made-up layout: random bits in every field (no solver needed)."""
    rng = np.random.default_rng(seed)
    H, W = shape
    occ = np.zeros((H, W), np.uint8)
    occ[:, W // 2] = 1
    occ[H // 3 : H // 3 + 5, W // 2] = 0
    occ[0, 0] = 1
    free = occ == 0
    wind = (rng.standard_normal((2, H, W)) * 3).astype(np.float32)
    wind[:, ~free] = 0
    wind[0, 1, 1] = np.float32(1e-42)  # a denormal survives too
    layout_name = f"synthetic-{seed}"
    cases = []
    cells = np.argwhere(free)
    for k in range(n_sources):
        conc = (rng.random((H, W)) * 10.0 ** rng.uniform(0, 5)).astype(np.float32)
        conc[~free] = 0
        i, j = cells[rng.integers(len(cells))]
        meta = {
            "name": f"{layout_name}_src{k}",
            "layout": layout_name,
            "source_index": k,
            "width_m": W * 0.1,
            "height_m": H * 0.1,
            "inlet": {"side": "west", "start_m": 0.5, "end_m": 1.2},
            "outlet": {"side": "east", "start_m": 0.5, "end_m": 1.2},
            "inlet_velocity": float(rng.uniform(0.5, 5)),
            "release_rate_gps": float(rng.uniform(0.01, 5)),
            "nested": {"list": [1, 2.5, None, "ü"], "flag": True},
        }
        fr = None
        if frames and k == 1:
            fr = (rng.random((3, H, W)) * 100).astype(np.float32)
            fr[:, ~free] = 0
            meta["frame_dt"] = 0.5
        src = ((j + 0.5) * 0.1, (i + 0.5) * 0.1)
        cases.append(Case(occ, wind, conc, src, 0.1, meta, fr))
    return cases


@pytest.fixture
def store_path(tmp_path):
    return tmp_path / "store.h5"


def test_round_trip_is_lossless(store_path):
    added = {}
    with DatasetStore(store_path, "w") as s:
        for n, split in enumerate(("train", "val", "test")):
            cases = synthetic_layout_cases(n, frames=(n == 0))
            lid = s.add_layout(cases, split)
            added[lid] = cases
    assert sorted(added) == ["synthetic-0", "synthetic-1", "synthetic-2"]
    with DatasetStore(store_path) as s:
        assert s.layouts() == sorted(added)
        assert len(s) == 3 and s.n_cases() == 12
        for lid, cases in added.items():
            assert s.n_sources(lid) == 4
            for k, c in enumerate(cases):
                got = s.case(lid, k)
                assert cases_equal(got, c)
                assert got.meta == c.meta
                assert got.wind.dtype == np.float32 and got.occupancy.dtype == np.uint8
                assert got.resolution == c.resolution
        got = s.case("synthetic-0", 1)
        assert got.frames is not None and got.frames.shape == (3, 23, 31)
        assert s.case("synthetic-0", 0).frames is None
        n = sum(1 for _ in s.iter_cases())
        assert n == 12
        assert [k for lid, k, _ in s.iter_cases("val")] == [0, 1, 2, 3]
        info = s.layout_info("synthetic-1")
        assert info["split"] == "val" and info["layout_index"] == -1
        summ = info["summary"]
        assert summ["shape"] == [23, 31] and len(summ["sources"]) == 4
        c = added["synthetic-1"][2]
        assert summ["sources"][2]["max_ppm"] == pytest.approx(float(c.concentration.max()))


def test_add_layout_rejects_bad_input(store_path):
    cases = synthetic_layout_cases(0)
    other = synthetic_layout_cases(1)
    with DatasetStore(store_path, "w") as s:
        with pytest.raises(InputDataError, match="does not share"):
            s.add_layout([cases[0], other[1]], "train")
        with pytest.raises(InputDataError, match="unknown split"):
            s.add_layout(cases, "validation")
        with pytest.raises(InputDataError, match="bad layout id"):
            s.add_layout(cases, "train", "a/b")
        s.add_layout(cases, "train", "L1")
        with pytest.raises(InputDataError, match="already in the store"):
            s.add_layout(cases, "train", "L1")
        with pytest.raises(InputDataError, match="out of range"):
            s.case("L1", 4)
        with pytest.raises(InputDataError, match="no layout"):
            s.case("nope", 0)
        assert "_staging" not in s._f or len(s._f["_staging"]) == 0
    with DatasetStore(store_path) as s, pytest.raises(InputDataError, match="read-only"):
        s.add_layout(other, "train")


def test_split_counts_and_determinism():
    assert split_counts(3750) == {"train": 3000, "val": 500, "test": 250}
    assert split_counts(4) == {"train": 2, "val": 1, "test": 1}
    assert split_counts(3) == {"train": 1, "val": 1, "test": 1}
    a = assign_splits(3750, seed=7)
    assert a == assign_splits(3750, seed=7)
    assert a != assign_splits(3750, seed=8)
    assert {s: a.count(s) for s in SPLITS} == {"train": 3000, "val": 500, "test": 250}
    with pytest.raises(InputDataError, match="sum to 1"):
        split_counts(10, {"train": 0.5, "val": 0.1, "test": 0.1})


def test_splits_are_layout_level_and_disjoint(store_path):
    with DatasetStore(store_path, "w") as s:
        for n in range(6):
            s.add_layout(synthetic_layout_cases(n, n_sources=2), "train")
        splits = s.reassign_splits(seed=3)
        again = s.reassign_splits(seed=3)
    assert splits == again
    ids = [i for v in splits.values() for i in v]
    assert len(ids) == len(set(ids)) == 6
    assert {s: len(v) for s, v in splits.items()} == split_counts(6)
    with DatasetStore(store_path) as s:
        for split, lids in splits.items():
            for lid in lids:
                assert s.split_of(lid) == split
        # every case of a layout is in its layout's split
        seen = {(lid, s.split_of(lid)) for sp in SPLITS for lid, _, _ in s.iter_cases(sp)}
        assert len({lid for lid, _ in seen}) == len(seen)


def test_fixed_configurations_are_stored_and_stable(store_path):
    with DatasetStore(store_path, "w") as s:
        s.add_layout(synthetic_layout_cases(0), "val")
        s.add_layout(synthetic_layout_cases(1, n_sources=2), "val")
        s.add_layout(synthetic_layout_cases(2), "test")
        fx = s.fixed_configurations("val", seed=5)
        assert fx.n_per_env == 30 and len(fx.envs) == 6 and len(fx) == 180
        assert s.has_fixed_configurations("val") and not s.has_fixed_configurations("test")
    with DatasetStore(store_path) as s:
        again = s.fixed_configurations("val")  # the stored ones, seed and all
        assert again.seed == 5
        for a, b in zip(fx, again, strict=True):
            assert a[:3] == b[:3]
            assert np.array_equal(a[3].cells, b[3].cells) and a[3].noise_seed == b[3].noise_seed
        with pytest.raises(InputDataError, match="seed 5"):
            s.fixed_configurations("val", seed=6)
        occ = s.case("synthetic-0", 0).occupancy
    for _, _, _, cfg in fx:
        assert cfg.n_sensors in SENSOR_COUNTS
        assert cfg.cells.dtype == np.int64
        assert len({tuple(c) for c in cfg.cells}) == cfg.n_sensors  # distinct
    for cfg in fx.for_env("synthetic-0", 3):
        assert (occ[cfg.cells[:, 0], cfg.cells[:, 1]] == 0).all()  # free cells only
    counts = {cfg.n_sensors for *_, cfg in fx}
    assert len(counts) > 10  # drawn from {5, ..., 300}
    # a layout added later extends the configurations; existing ones do not change
    with DatasetStore(store_path, "a") as s:
        s.add_layout(synthetic_layout_cases(3, n_sources=1), "val")
        ext = s.fixed_configurations("val")
        assert len(ext.envs) == 7
        for env in fx.envs:
            for k in (0, 29):
                assert np.array_equal(ext.get(*env, k).cells, fx.get(*env, k).cells)
        redrawn = s.fixed_configurations("val", seed=5, overwrite=True)
        assert np.array_equal(redrawn.cells, ext.cells)  # draws depend on (seed, env) only


def test_fixed_configurations_of_an_empty_split(store_path):
    """A small dataset can leave a split empty (2 layouts: no validation layout)."""
    with DatasetStore(store_path, "w") as s:
        s.add_layout(synthetic_layout_cases(0), "train")
        fx = s.fixed_configurations("val", seed=1)
        assert len(fx) == 0 and fx.cells.shape == (0, 2)
    with DatasetStore(store_path) as s:
        assert s.has_fixed_configurations("val") and len(s.fixed_configurations("val")) == 0


@pytest.mark.parametrize("kind", ["garbage", "truncated", "foreign", "directory", "missing"])
def test_bad_store_files_raise_clear_errors(tmp_path, kind):
    path = tmp_path / "bad.h5"
    if kind == "garbage":
        path.write_bytes(b"this is not an HDF5 file at all" * 100)
    elif kind == "truncated":
        good = tmp_path / "good.h5"
        with DatasetStore(good, "w") as s:
            s.add_layout(synthetic_layout_cases(0), "train")
        data = good.read_bytes()
        path.write_bytes(data[: len(data) // 3])
    elif kind == "foreign":
        with h5py.File(path, "w") as f:
            f["x"] = np.arange(3)
    elif kind == "directory":
        path.mkdir()
    with pytest.raises(InputDataError) as info:
        with DatasetStore(path) as s:
            for lid in s.layouts():
                s.layout_cases(lid)
    assert str(path) in str(info.value)
    assert {"foreign": "not a DGSE dataset store", "missing": "no such", "directory": "directory"}.get(
        kind, "HDF5"
    ) in str(info.value)


def test_export_import_round_trip(tmp_path, store_path):
    with DatasetStore(store_path, "w") as s:
        s.add_layout(synthetic_layout_cases(0, frames=True), "train")
        s.add_layout(synthetic_layout_cases(1, n_sources=3), "test")
        files = s.export(tmp_path / "cases")
    assert len(files) == 7
    manifest = json.loads((tmp_path / "cases" / "manifest.json").read_text())
    assert manifest["layouts"]["synthetic-1"]["split"] == "test"
    # a case file is the spec's interchange file
    assert cases_equal(
        Case.load(tmp_path / "cases" / "synthetic-1_src2.npz"), synthetic_layout_cases(1, n_sources=3)[2]
    )
    back = tmp_path / "back.h5"
    with DatasetStore(back, "a") as b:
        added = b.import_cases([tmp_path / "cases"], split="val")
        assert sorted(added) == ["synthetic-0", "synthetic-1"]
        assert b.import_cases(sorted((tmp_path / "cases").glob("*.npz"))) == []  # idempotent
    with DatasetStore(store_path) as s, DatasetStore(back) as b:
        assert b.layouts() == s.layouts()
        for lid in s.layouts():
            assert b.split_of(lid) == "val"
            for x, y in zip(s.layout_cases(lid), b.layout_cases(lid), strict=True):
                assert cases_equal(x, y)
    with DatasetStore(back, "a") as b, pytest.raises(InputDataError, match="no such"):
        b.import_cases([tmp_path / "nope.npz"])


def test_journal_commit_is_idempotent_and_cleans_up(tmp_path, store_path):
    create_store(store_path, {"seed": 0})
    j = Journal(store_path)
    cases = synthetic_layout_cases(0)
    entry = j.add_layout(cases, "train", "layout-000000", 0)
    j.add_failure({"layout_index": 1, "layout_id": "layout-000001", "reason": "stalled"})
    # debris of interrupted writes is dropped
    (j.dir / ".layout-000002.h5.tmp").write_bytes(b"half")
    (j.dir / "layout-000003.h5").write_bytes(b"corrupt")
    saved = entry.read_bytes()
    assert commit_pending(store_path) == 2
    assert not j.dir.exists()
    # a crash between the rename and the journal cleanup leaves the entry: no duplicate
    j.dir.mkdir()
    entry.write_bytes(saved)
    assert commit_pending(store_path) == 1
    with DatasetStore(store_path) as s:
        assert s.layouts() == ["layout-000000"]
        assert s.layout_indices() == {0}
        assert s.failed_indices() == {1}
        assert s.failures()[0]["reason"] == "stalled"
        assert s.generation_info == {"seed": 0}
        for k, c in enumerate(cases):
            assert cases_equal(s.case("layout-000000", k), c)
    assert not list(tmp_path.glob(".*tmp"))
