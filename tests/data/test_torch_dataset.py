"""Training and evaluation datasets: shapes, seeding, augmentation, fixed configurations."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from torch.utils.data import DataLoader

from dgse.data.store import DatasetStore
from dgse.data.torch_dataset import FixedSet, TrainingSet, load_cases
from dgse.errors import InputDataError
from dgse.physics.scenario import solve_cases
from tests.conftest import two_rooms


@pytest.fixture(scope="module")
def store_path(tmp_path_factory):
    layout = two_rooms()
    cases = solve_cases(layout, 1.3, [((0.55, 0.55), 0.5), ((2.45, 1.45), 2.0)])
    path = tmp_path_factory.mktemp("ds") / "tiny.h5"
    with DatasetStore(path, "w") as s:
        s.add_layout(cases, "train")
        s.add_layout(cases, "val")
        s.fixed_configurations("val", n_per_env=3, seed=1)
    return path


def _tset(store_path, **kw):
    return TrainingSet([c for _, _, c in load_cases(store_path, "train")], configs_per_env=4, **kw)


def test_training_items_have_the_contract_shapes(store_path):
    ds = _tset(store_path)
    assert len(ds) == 2 * 4 and ds.canvas == (100, 100)
    item = ds[5]
    assert item["inputs"].shape == (5, 100, 100) and item["inputs"].dtype == torch.float32
    assert item["wind"].shape == (2, 100, 100) and item["log_conc"].shape == (100, 100)
    valid = item["valid"]
    assert valid.dtype == torch.bool and int(valid.sum()) == 20 * 30
    assert valid.flatten()[item["source_index"]]  # the source is on the map
    gas = item["inputs"][0]
    assert int((gas >= 0).sum()) == int(item["n_obs"])  # one gas reading per sensor
    assert 5 <= int(item["n_obs"]) <= 300 and int(item["n_obs"]) % 5 == 0


def test_draws_depend_on_seed_epoch_and_index_only(store_path):
    a, b = _tset(store_path, seed=3), _tset(store_path, seed=3)
    assert torch.equal(a[6]["inputs"], b[6]["inputs"])
    a.set_epoch(1)
    assert not torch.equal(a[6]["inputs"], b[6]["inputs"])  # fresh configurations each epoch
    b.set_epoch(1)
    loaded = next(iter(DataLoader(b, batch_size=len(b), num_workers=2)))
    single = torch.stack([a[i]["inputs"] for i in range(len(a))])
    assert torch.equal(loaded["inputs"], single)  # workers do not change the draws


def test_augmentation_moves_targets_with_inputs(store_path):
    cases = [c for _, _, c in load_cases(store_path, "train")]
    ds = TrainingSet(cases, configs_per_env=12, augment=True)
    rotated = 0
    for i in range(len(ds)):
        item = ds[i]
        H, W = (int(item["valid"].any(1).sum()), int(item["valid"].any(0).sum()))
        rotated += (H, W) == (30, 20)
        # observed wind sits where the target wind is (noise aside, same sign pattern)
        obs = item["inputs"][0] >= 0
        wind_obs = item["inputs"][1:3][:, obs]
        wind_true = item["wind"][:, obs]
        cos = (wind_obs * wind_true).sum(0) / (wind_obs.norm(dim=0) * wind_true.norm(dim=0) + 1e-9)
        assert float(cos.median()) > 0.8
    assert 0 < rotated < len(ds)  # quarter turns swap the map's sides, not always


def test_fixed_set_is_deterministic(store_path):
    a, b = FixedSet(store_path, "val"), FixedSet(store_path, "val")
    assert len(a) == 2 * 3
    for i in range(len(a)):
        assert torch.equal(a[i]["inputs"], b[i]["inputs"])
    assert len({int(a[i]["n_obs"]) for i in range(len(a))}) > 1


def test_empty_split_is_an_error(store_path):
    with pytest.raises(InputDataError, match="no cases in split 'test'"):
        load_cases(store_path, "test")
    with pytest.raises(InputDataError, match="at least one case"):
        TrainingSet([])


def test_batches_collate(store_path):
    batch = next(iter(DataLoader(_tset(store_path), batch_size=4)))
    assert batch["inputs"].shape == (4, 5, 100, 100) and batch["source_index"].shape == (4,)
    assert np.isfinite(batch["log_conc"].numpy()).all()
