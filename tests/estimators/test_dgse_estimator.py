"""DGSEEstimator: rasterize -> network -> Belief on the map; factories and checkpoints."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from dgse.belief.estimator import Estimator, StreamingEstimator
from dgse.errors import InputDataError, UnsupportedError
from dgse.estimators.dgse import DGSEEstimator, default_model_path
from dgse.estimators.registry import get_estimator
from dgse.models.checkpoint import CheckpointError, save_model
from dgse.models.inference import native_bf16
from dgse.sensing.sensors import Observations
from tests.models.helpers import tiny_model


def _map() -> tuple[np.ndarray, Observations]:
    occ = np.zeros((20, 30), np.uint8)
    occ[:, 15] = 1
    occ[8:12, 15] = 0
    cells = np.array([[1, 1], [5, 20], [19, 29], [10, 15]])
    obs = Observations(
        cells, np.array([0.0, 10.0, 3.0, 50.0]), np.array([[1, 0], [0, 1], [0.5, 0.5], [0, 0]])
    )
    return occ, obs


@pytest.mark.parametrize("variant", ["dgse-o", "dgse-p", "dgse-s"])
def test_estimate_belief_on_map(variant):
    occ, obs = _map()
    est = DGSEEstimator(tiny_model(variant), K=2, T=2, seed=0, canvas_minimum=32)
    assert isinstance(est, Estimator) and est.name == variant
    b = est.estimate(occ, 0.1, obs)
    assert b.source_probs.shape == (20, 30)
    assert b.source_probs.sum() == pytest.approx(1.0, abs=1e-9)
    assert (b.source_probs[occ == 1] == 0).all() and (b.source_probs[occ == 0] > 0).all()
    assert b.info["method"] == variant and b.info["seconds"] > 0 and b.info["canvas"] == (32, 32)
    assert 0 <= b.source_estimate()[0] <= 3.0 and 0 <= b.source_estimate()[1] <= 2.0
    if variant == "dgse-o":
        assert b.wind_mean is None and b.log_conc_mean is None
    else:
        assert b.wind_mean.shape == b.wind_var.shape == (2, 20, 30)
        assert b.log_conc_var.shape == (20, 30) and (b.conc_mean_ppm > -1).all()
    if variant == "dgse-s":  # a seed makes the estimate reproducible
        b2 = est.estimate(occ, 0.1, obs)
        np.testing.assert_array_equal(b.source_probs, b2.source_probs)


def test_default_canvas_and_large_map():
    est = DGSEEstimator(tiny_model("dgse-o"))
    assert est.canvas_shape((20, 30)) == (100, 100)
    assert est.canvas_shape((102, 40)) == (112, 112)


def test_bfloat16_channels_last_option():
    occ, obs = _map()
    est = DGSEEstimator(
        tiny_model("dgse-s"), K=2, T=1, seed=0, canvas_minimum=32, dtype="bf16", channels_last=True
    )
    b = est.estimate(occ, 0.1, obs)
    assert b.info["dtype"] == "bfloat16" and b.source_probs.sum() == pytest.approx(1.0)
    with pytest.raises(InputDataError, match="dtype"):
        DGSEEstimator(tiny_model("dgse-s"), dtype="int8")


def test_auto_dtype_is_bf16_only_where_the_cpu_has_it(monkeypatch: pytest.MonkeyPatch):
    for native in (True, False):
        monkeypatch.setattr(torch.cpu, "_is_avx512_bf16_supported", lambda v=native: v, raising=False)
        monkeypatch.setattr(torch.cpu, "_is_amx_tile_supported", lambda: False, raising=False)
        assert native_bf16("cpu") is native
        est = DGSEEstimator(tiny_model("dgse-s"), dtype="auto")
        assert est.dtype == (torch.bfloat16 if native else torch.float32)


def test_resolution_and_observation_checks():
    occ, obs = _map()
    est = DGSEEstimator(tiny_model("dgse-o"), canvas_minimum=32)
    for resolution in (0.05, 0.15):  # finer than the network's cells, or not a whole multiple
        with pytest.raises(InputDataError, match=r"0\.1 m cells"):
            est.estimate(occ, resolution, obs)
    wall = Observations(np.array([[0, 15]]), np.array([1.0]), np.zeros((1, 2)))
    with pytest.raises(InputDataError):
        est.estimate(occ, 0.1, wall)
    b = est.estimate(occ, 0.1, Observations.empty())
    assert b.info["n_observations"] == 0


@pytest.mark.parametrize("variant", ["dgse-o", "dgse-s"])
def test_coarse_map_runs_on_the_networks_cells(variant):
    """A 0.2 m map is the 0.1 m map of 2 x 2 blocks, its readings at one cell of their block;
    the belief is that map's, summed (source) and averaged (fields) over the blocks."""
    from dgse.world.grid import coarsen, refine_cells, refine_occupancy

    occ, obs = _map()
    est = DGSEEstimator(tiny_model(variant), K=2, T=2, seed=0, canvas_minimum=32)
    coarse = est.estimate(occ, 0.2, obs)
    fine_obs = Observations(refine_cells(obs.cells, 2), obs.gas, obs.wind)
    fine = est.estimate(refine_occupancy(occ, 2), 0.1, fine_obs)
    assert coarse.info["refinement"] == 2 and fine.info["refinement"] == 1
    assert coarse.info["canvas"] == fine.info["canvas"] == (64, 64)
    assert coarse.source_probs.shape == (20, 30) and coarse.resolution == 0.2
    np.testing.assert_allclose(coarse.source_probs, coarsen(fine.source_probs, 2, "sum"), rtol=1e-9)
    assert (coarse.source_probs[occ == 1] == 0).all() and coarse.source_probs.sum() == pytest.approx(1.0)
    if variant == "dgse-s":
        np.testing.assert_allclose(coarse.wind_mean, coarsen(fine.wind_mean, 2), rtol=1e-9)
        np.testing.assert_allclose(coarse.log_conc_var, coarsen(fine.log_conc_var, 2), rtol=1e-9)
    # readings are checked on the map they were given for
    with pytest.raises(InputDataError):
        est.estimate(occ, 0.2, Observations(np.array([[0, 15]]), np.array([1.0]), np.zeros((1, 2))))


def test_registry_factories_with_checkpoints(tmp_path):
    occ, obs = _map()
    path = save_model(tiny_model("dgse-s"), tmp_path / "s.safetensors")
    est = get_estimator("dgse-s", model=path, K=1, T=1, canvas_minimum=32, seed=1)
    assert isinstance(est, DGSEEstimator) and est.checkpoint == path
    stream = StreamingEstimator(est, occ, 0.1)
    assert stream.update(obs).source_probs.sum() == pytest.approx(1.0)
    with pytest.raises(CheckpointError, match="expected 'dgse-p'"):
        get_estimator("dgse-p", model=path)
    net = get_estimator("dgse-o", model=tiny_model("dgse-o"))
    assert isinstance(net, DGSEEstimator)
    with pytest.raises(InputDataError):
        get_estimator("dgse-o", model=tiny_model("dgse-s"))
    assert DGSEEstimator.from_checkpoint(path, K=1, T=1).name == "dgse-s"


def test_missing_shipped_weights_is_unsupported():
    try:
        default_model_path("dgse-s")
    except UnsupportedError as e:
        assert "model=" in str(e)
        with pytest.raises(UnsupportedError):
            get_estimator("dgse-s")
    else:  # weights shipped: the default model loads
        assert isinstance(get_estimator("dgse-s"), DGSEEstimator)


def test_device_and_k_validation():
    with pytest.raises(InputDataError):
        DGSEEstimator(tiny_model("dgse-s"), K=0)
    with pytest.raises(InputDataError):
        DGSEEstimator(torch.nn.Linear(2, 2))  # type: ignore[arg-type]
