"""Prediction: single pass for O/P, MC marginalization for S, moment matching, reproducibility."""

from __future__ import annotations

import pytest
import torch

from dgse.errors import InputDataError
from dgse.models.inference import moment_match, predict
from tests.models.helpers import canvas_batch, tiny_model


def test_moment_matching_two_component_mixture():
    means = torch.tensor([[0.0, -1.0], [2.0, 3.0]])  # (K=2, 2 cells)
    variances = torch.tensor([[1.0, 0.5], [1.0, 1.5]])
    mu, var = moment_match(means, variances)
    torch.testing.assert_close(mu, torch.tensor([1.0, 1.0]))
    # Eq. 21: mean(var + mu^2) - mu_bar^2
    torch.testing.assert_close(var, torch.tensor([(1 + 0 + 1 + 4) / 2 - 1, (0.5 + 1 + 1.5 + 9) / 2 - 1]))
    torch.testing.assert_close(var, torch.tensor([2.0, 5.0]))
    mu1, var1 = moment_match(means[:1], variances[:1])
    assert torch.equal(mu1, means[0]) and torch.equal(var1, variances[0])


def test_k_t_one_equals_single_stochastic_pass():
    model = tiny_model("dgse-s").eval()
    x, _ = canvas_batch(3, (32, 28))
    with torch.no_grad():
        out = model(x, generator=torch.Generator().manual_seed(42))
    pred = predict(model, x, K=1, T=1, generator=torch.Generator().manual_seed(42))
    torch.testing.assert_close(pred.source_probs, out.source_probs(), rtol=1e-6, atol=1e-7)
    torch.testing.assert_close(pred.logc_mean, out.logc_mean, rtol=1e-6, atol=1e-7)
    torch.testing.assert_close(pred.logc_var, out.logc_logvar.exp(), rtol=1e-6, atol=1e-7)
    torch.testing.assert_close(pred.wind_mean, out.wind_mean)
    torch.testing.assert_close(pred.wind_var, out.wind_logvar.exp())


def test_dgse_s_predict_k_t_properties_and_seed():
    model = tiny_model("dgse-s").eval()
    x, _ = canvas_batch(2, (40, 40))
    a = predict(model, x, K=3, T=4, seed=5)
    b = predict(model, x, K=3, T=4, seed=5)
    c = predict(model, x, K=3, T=4, seed=6)
    assert torch.equal(a.source_probs, b.source_probs) and torch.equal(a.logc_var, b.logc_var)
    assert not torch.equal(a.source_probs, c.source_probs)
    assert (a.K, a.T) == (3, 4)
    torch.testing.assert_close(a.source_probs.flatten(1).sum(1), torch.ones(2))
    assert (a.source_probs[~a.valid] == 0).all()
    assert (a.logc_var > 0).all() and (a.wind_var > 0).all()
    # chunked evaluation: same distributions up to noise, valid probabilities
    d = predict(model, x, K=3, T=4, seed=5, max_batch=5)
    torch.testing.assert_close(d.source_probs.flatten(1).sum(1), torch.ones(2))
    torch.testing.assert_close(d.wind_mean, a.wind_mean)


def test_average_of_per_sample_probabilities():
    """Eq. 22: the predicted source probabilities are the mean of the K*T sample softmaxes."""
    model = tiny_model("dgse-s").eval()
    x, _ = canvas_batch(1, (32, 32))
    K, T = 2, 3
    g = torch.Generator().manual_seed(3)
    pred = predict(model, x, K=K, T=T, generator=g)
    g = torch.Generator().manual_seed(3)
    with torch.no_grad():
        mu_w, lv_w = model.wind_params(x)
        eps_w = torch.randn((K, 1, 2, 32, 32), generator=g)
        eps_c = torch.randn((T, K, 1, 32, 32), generator=g)
        valid = x[:, 4] > 0.5
        probs, mus, lvs = [], [], []
        ws = [model.sample_wind(mu_w, lv_w, eps_w[k], valid) for k in range(K)]
        for k in range(K):
            m, lv = model.conc_params(ws[k], x)
            mus.append(m)
            lvs.append(lv)
        for t in range(T):
            for k in range(K):
                c = model.sample_logc(mus[k], lvs[k], eps_c[t, k], valid)
                logits = model.source_logits(ws[k], c, x)
                probs.append(torch.softmax(logits.flatten(1), 1).reshape(1, 32, 32))
    torch.testing.assert_close(pred.source_probs, torch.stack(probs).mean(0), rtol=1e-5, atol=1e-7)
    torch.testing.assert_close(pred.logc_mean, torch.stack(mus).mean(0), rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("variant", ["dgse-o", "dgse-p"])
def test_single_pass_variants(variant):
    model = tiny_model(variant).eval()
    x, _ = canvas_batch(2, (50, 30))
    pred = predict(model, x, K=5, T=5)
    with torch.no_grad():
        out = model(x)
    torch.testing.assert_close(pred.source_probs, out.source_probs())
    assert (pred.K, pred.T) == (1, 1)
    if variant == "dgse-o":
        assert pred.wind_mean is None and pred.logc_var is None
    else:
        torch.testing.assert_close(pred.logc_var, out.logc_logvar.exp())
    single = predict(model, x[0])  # an unbatched (5, H, W) input
    assert single.source_probs.shape == (1, 50, 30)


def test_bf16_autocast_and_channels_last_run_close_to_float32():
    model = tiny_model("dgse-s").eval()
    x, _ = canvas_batch(1, (32, 32))
    ref = predict(model, x, K=2, T=2, seed=0)
    model_cl = tiny_model("dgse-s").eval().to(memory_format=torch.channels_last)
    low = predict(model_cl, x, K=2, T=2, seed=0, autocast_dtype=torch.bfloat16, channels_last=True)
    assert low.source_probs.dtype == torch.float32
    torch.testing.assert_close(low.source_probs.flatten(1).sum(1), torch.ones(1))
    assert 0.5 * (low.source_probs - ref.source_probs).abs().sum() < 0.2


def test_predict_rejects_bad_input():
    model = tiny_model("dgse-s")
    with pytest.raises(InputDataError):
        predict(model, torch.zeros(1, 4, 8, 8))
    with pytest.raises(InputDataError):
        predict(model, torch.zeros(1, 5, 8, 8), K=0)
