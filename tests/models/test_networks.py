"""DGSE-O/P/S networks: shapes, masks, presets and parameter counts, sampling and gradients."""

from __future__ import annotations

import pytest
import torch

from dgse.errors import InputDataError
from dgse.models.networks import (
    DGSE_O,
    DGSE_S,
    VARIANTS,
    ModelConfig,
    count_parameters,
    create_model,
    masked_log_softmax,
    preset_config,
    soft_clamp,
)
from dgse.models.objectives import source_cross_entropy
from tests.models.helpers import canvas_batch, tiny_model

#: Appendix A of the paper.
PAPER_PARAMS = {"dgse-o": 0.82e6, "dgse-p": 1.54e6, "dgse-s": 1.59e6}


@pytest.mark.parametrize("variant", VARIANTS)
@pytest.mark.parametrize("shape", [(40, 40), (50, 30), (100, 100)])
def test_any_canvas_shapes_and_masks(variant, shape):
    model = tiny_model(variant)
    x, _ = canvas_batch(2, shape)
    out = model(x, generator=torch.Generator().manual_seed(0))
    B, (H, W) = 2, shape
    assert out.source_logits.shape == (B, H, W)
    assert torch.equal(out.valid, x[:, 4] > 0.5)
    assert torch.isneginf(out.source_logits[~out.valid]).all()
    p = out.source_probs()
    assert torch.isfinite(p).all()
    assert (p[~out.valid] == 0).all()
    torch.testing.assert_close(p.flatten(1).sum(1), torch.ones(B))
    if variant == "dgse-o":
        assert out.wind_mean is None and out.logc_mean is None
        return
    assert out.wind_mean.shape == out.wind_logvar.shape == (B, 2, H, W)
    assert out.logc_mean.shape == out.logc_logvar.shape == (B, H, W)
    cfg = model.config
    for lv in (out.wind_logvar, out.logc_logvar):
        assert (lv > cfg.logvar_min).all() and (lv < cfg.logvar_max).all()
    if variant == "dgse-s":
        assert out.wind_sample.shape == (B, 2, H, W) and out.logc_sample.shape == (B, H, W)
        assert (out.wind_sample[:, :, ~out.valid[0]] == 0).all()


@pytest.mark.parametrize("variant", VARIANTS)
def test_paper_preset_parameter_counts(variant):
    n = count_parameters(create_model(variant, "paper"))
    small = count_parameters(create_model(variant, "small"))
    paper = PAPER_PARAMS[variant]
    print(f"{variant}: paper preset {n / 1e6:.3f} M (paper {paper / 1e6:.2f} M), small {small / 1e6:.3f} M")
    assert abs(n / paper - 1) < 0.10
    assert 4 <= n / small <= 8


def test_config_validation_and_roundtrip():
    cfg = preset_config("small", "dgse-p", activation="silu")
    assert ModelConfig.from_dict(cfg.to_dict()) == cfg
    with pytest.raises(InputDataError, match="variant"):
        ModelConfig(variant="dgse-x")  # type: ignore[arg-type]
    with pytest.raises(InputDataError):
        ModelConfig(base_width=0)
    with pytest.raises(InputDataError):
        ModelConfig(logvar_min=2.0, logvar_max=1.0)
    with pytest.raises(InputDataError, match="unknown model config keys"):
        ModelConfig.from_dict({**cfg.to_dict(), "dropout": 0.1})
    with pytest.raises(InputDataError, match="preset"):
        preset_config("huge", "dgse-s")
    with pytest.raises(InputDataError):
        DGSE_O(preset_config("small", "dgse-s"))


def test_soft_clamp_bounds_and_near_identity():
    x = torch.linspace(-100, 100, 2001, requires_grad=True)
    y = soft_clamp(x, -12.0, 6.0)
    assert (y >= -12).all() and (y <= 6).all()
    inside = (x > -8) & (x < 2)
    torch.testing.assert_close(y[inside], x[inside], atol=0.02, rtol=0)
    y.sum().backward()
    assert (x.grad >= 0).all() and (x.grad[(x > -40) & (x < 30)] > 0).all()


def test_masked_softmax_without_valid_cells_is_zero_not_nan():
    logits = torch.randn(2, 4, 5)
    valid = torch.zeros(2, 4, 5, dtype=torch.bool)
    valid[0, :2, :3] = True
    p = masked_log_softmax(logits, valid).exp()
    assert torch.isfinite(p).all()
    torch.testing.assert_close(p[0].sum(), torch.tensor(1.0))
    assert (p[1] == 0).all() and (p[0][~valid[0]] == 0).all()


def test_dgse_s_source_loss_reaches_all_subnetworks_through_samples():
    model = tiny_model("dgse-s")
    assert isinstance(model, DGSE_S)
    x, t = canvas_batch(2, (32, 32))
    out = model(x, generator=torch.Generator().manual_seed(1))
    source_cross_entropy(out.source_logits, t.source, t.valid).mean().backward()
    for sub in (model.wind_net, model.conc_net, model.source_net):
        grads = [p.grad for p in sub.parameters()]
        assert all(g is not None for g in grads)
        assert sum(float(g.abs().sum()) for g in grads) > 0


def test_dgse_s_explicit_noise_and_gas_only_concentration_input():
    model = tiny_model("dgse-s")
    x, _ = canvas_batch(1, (32, 32))
    eps_w, eps_c = torch.randn(1, 2, 32, 32), torch.randn(1, 32, 32)
    a = model(x, eps_wind=eps_w, eps_logc=eps_c)
    b = model(x, eps_wind=eps_w, eps_logc=eps_c)
    assert torch.equal(a.source_logits, b.source_logits)
    # the concentration net sees the wind sample and the gas channel, not the wind observations (Eq. 12)
    mu1, _ = model.conc_params(a.wind_sample, x)
    x2 = x.clone()
    x2[:, 1:3] = torch.randn_like(x2[:, 1:3])
    mu2, _ = model.conc_params(a.wind_sample, x2)
    assert torch.equal(mu1, mu2)
