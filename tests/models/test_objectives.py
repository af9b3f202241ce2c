"""Losses: hand-computed NLL and CE, weighted totals, the Jensen surrogate, the MC objective, overfitting."""

from __future__ import annotations

import math

import pytest
import torch

from dgse.errors import InputDataError
from dgse.models.objectives import (
    LossWeights,
    TargetBatch,
    dgse_loss,
    gaussian_nll,
    mc_marginal_nll,
    source_cross_entropy,
)
from tests.models.helpers import canvas_batch, tiny_model

LOG2PI = math.log(2 * math.pi)


def test_gaussian_nll_hand_computed():
    # one sample, 1 x 3 cells, the last one invalid
    mean = torch.tensor([[[0.0, 1.0, 5.0]]])
    logvar = torch.tensor([[[0.0, math.log(4.0), 0.0]]])
    target = torch.tensor([[[1.0, 3.0, 0.0]]])
    valid = torch.tensor([[[True, True, False]]])
    cell0 = 0.5 * (LOG2PI + 0.0 + 1.0)
    cell1 = 0.5 * (LOG2PI + math.log(4.0) + 4.0 / 4.0)
    got = gaussian_nll(mean, logvar, target, valid)
    torch.testing.assert_close(got, torch.tensor([(cell0 + cell1) / 2]))
    # two components are summed per cell, then averaged over the valid cells
    m2, lv2, t2 = (torch.stack([a, a], dim=1) for a in (mean, logvar, target))
    torch.testing.assert_close(gaussian_nll(m2, lv2, t2, valid), 2 * got)
    with pytest.raises(InputDataError):
        gaussian_nll(mean, logvar, target[..., :2], valid)


def test_cross_entropy_hand_computed_index_and_one_hot():
    logits = torch.tensor([[[1.0, 2.0], [3.0, 100.0]]])
    valid = torch.tensor([[[True, True], [True, False]]])
    expected = -(3.0 - math.log(math.exp(1) + math.exp(2) + math.exp(3)))
    torch.testing.assert_close(
        source_cross_entropy(logits, torch.tensor([2]), valid), torch.tensor([expected])
    )
    one_hot = torch.zeros(1, 2, 2)
    one_hot[0, 1, 0] = 1
    torch.testing.assert_close(source_cross_entropy(logits, one_hot, valid), torch.tensor([expected]))
    assert torch.isinf(source_cross_entropy(logits, torch.tensor([3]), valid)).all()


@pytest.mark.parametrize("variant", ["dgse-o", "dgse-p", "dgse-s"])
def test_dgse_loss_components_and_weights(variant):
    model = tiny_model(variant)
    x, t = canvas_batch(2, (32, 32))
    out = model(x, generator=torch.Generator().manual_seed(0))
    w = LossWeights(wind=0.5, conc=2.0, source=0.1)
    loss = dgse_loss(out, t, w)
    if variant == "dgse-o":
        assert set(loss) == {"loss", "source_ce"}
        torch.testing.assert_close(loss["loss"], loss["source_ce"])
        return
    assert set(loss) == {"loss", "wind_nll", "conc_nll", "source_ce"}
    torch.testing.assert_close(
        loss["loss"], 0.5 * loss["wind_nll"] + 2.0 * loss["conc_nll"] + 0.1 * loss["source_ce"]
    )
    torch.testing.assert_close(
        loss["wind_nll"], gaussian_nll(out.wind_mean, out.wind_logvar, t.wind, t.valid).mean()
    )
    assert LossWeights() == LossWeights(1.0, 1.0, 0.05)
    with pytest.raises(InputDataError):
        LossWeights(source=-1.0)


def test_jensen_objective_backpropagates_into_all_subnetworks():
    model = tiny_model("dgse-s")
    x, t = canvas_batch(2, (32, 32))
    loss = dgse_loss(model(x, generator=torch.Generator().manual_seed(0)), t)["loss"]
    assert torch.isfinite(loss)
    loss.backward()
    for name, sub in (("wind", model.wind_net), ("conc", model.conc_net), ("source", model.source_net)):
        assert all(p.grad is not None and torch.isfinite(p.grad).all() for p in sub.parameters()), name
        assert sum(float(p.grad.abs().sum()) for p in sub.parameters()) > 0, name


def test_mc_objective_with_one_sample_equals_surrogate():
    model = tiny_model("dgse-s").eval()
    x, t = canvas_batch(2, (32, 32))
    with torch.no_grad():
        out = model(x, generator=torch.Generator().manual_seed(7))
        sur = dgse_loss(out, t)
    for mode in ("field", "cell"):
        mc = mc_marginal_nll(model, x, t, 1, 1, generator=torch.Generator().manual_seed(7), mode=mode)
        torch.testing.assert_close(mc["conc_nll"], sur["conc_nll"], rtol=1e-5, atol=1e-5)
        torch.testing.assert_close(mc["source_ce"], sur["source_ce"], rtol=1e-5, atol=1e-5)


def test_mc_objective_many_samples_chunked():
    """Chunks of 5 canvases give the objective of one call: the replicas keep their order and
    their noise.  Each chunk's noise is a whole number of 24 x 20 canvases, a multiple of the 16
    normals torch's CPU sampler draws at a time, so the chunks read the one call's stream."""
    model = tiny_model("dgse-s").eval()
    x, t = canvas_batch(2, (24, 20))
    for mode in ("field", "cell"):
        mc = mc_marginal_nll(model, x, t, 4, 3, seed=0, max_batch=5, reduction="none", mode=mode)
        assert mc["conc_nll"].shape == mc["source_ce"].shape == (2,)
        whole = mc_marginal_nll(model, x, t, 4, 3, seed=0, reduction="none", mode=mode)
        for key in ("conc_nll", "source_ce"):
            assert torch.isfinite(mc[key]).all()
            # float32 defaults: the batched convolutions round differently per batch size
            torch.testing.assert_close(mc[key], whole[key])
        mean = mc_marginal_nll(model, x, t, 4, 3, seed=0, max_batch=5, mode=mode)
        for key in ("conc_nll", "source_ce"):
            torch.testing.assert_close(mean[key], mc[key].mean())
    # another seed draws other noise: the agreement above is not that of a noise-free objective
    other = mc_marginal_nll(model, x, t, 4, 3, seed=1, max_batch=5, reduction="none", mode="cell")
    assert not torch.allclose(other["source_ce"], whole["source_ce"])


def test_target_batch_from_rasterize_targets():
    import numpy as np

    from dgse.data.rasterize import Targets

    valid = np.zeros((6, 6), bool)
    valid[:4, :5] = True
    src = np.zeros((6, 6), np.float32)
    src[2, 3] = 1
    tg = Targets(np.ones((2, 6, 6), np.float32), np.zeros((6, 6), np.float32), src, 2 * 6 + 3, valid)
    b = TargetBatch.from_targets([tg, tg])
    assert b.wind.shape == (2, 2, 6, 6) and b.source.tolist() == [15, 15] and b.valid.dtype == torch.bool
    with pytest.raises(InputDataError):
        TargetBatch.from_targets([])


@pytest.mark.parametrize("variant", ["dgse-s", "dgse-p", "dgse-o"])
def test_tiny_model_overfits_tiny_batch(variant):
    torch.manual_seed(0)
    model = tiny_model(variant, base_width=6)
    x, t = canvas_batch(4, (32, 32), seed=3)
    opt = torch.optim.Adam(model.parameters(), lr=5e-3)
    g = torch.Generator().manual_seed(0)
    weights = LossWeights(1.0, 1.0, 1.0)
    history = []
    for _ in range(50):
        opt.zero_grad()
        loss = dgse_loss(model(x, generator=g), t, weights)
        loss["loss"].backward()
        opt.step()
        history.append({k: float(v.detach()) for k, v in loss.items()})
    first, last = history[0], history[-1]
    assert last["loss"] < first["loss"] - 1.0, (first, last)
    assert last["source_ce"] < first["source_ce"] - 0.5, (first, last)
