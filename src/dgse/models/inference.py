"""Prediction with the DGSE networks: single pass (O, P), MC marginalization (S).

For DGSE-S (paper Eq. 12-13, 17-22) :func:`predict` runs

1. the wind net once on the batch: ``mu_w, sigma_w^2`` ``(B, 2, H, W)``;
2. the concentration net once on the batch replicated ``K`` times with the
   wind samples ``w_k = mu_w + sigma_w * eps_k`` (Eq. 17);
3. the source net once on the batch replicated ``K * T`` times with
   ``c_kt = mu_c^(k) + sigma_c^(k) * eps_kt`` (Eq. 18);

and returns the moment-matched concentration Gaussian (Eq. 20-21,
:func:`moment_match`) and the averaged source probabilities (Eq. 22).
Replicas are ordered sample-major: the concentration stage sees canvas
``k * B + b``, the source stage ``(t * K + k) * B + b``.  The noise is drawn
as ``eps_w`` of shape ``(K, B, 2, H, W)`` then ``eps_c`` of shape
``(T, K, B, H, W)``, so ``K = T = 1`` draws exactly what one
``DGSE_S.forward`` draws from the same generator (and gives the same result).
``max_batch`` splits each stage into several network calls (to bound memory;
the noise is then drawn chunk by chunk, a different but equally valid
stream).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from contextlib import nullcontext
from dataclasses import dataclass
from typing import Any

import torch

from dgse.errors import InputDataError, UnsupportedError
from dgse.models.networks import DGSE_S, DGSEModel, masked_log_softmax

__all__ = [
    "Prediction",
    "SequentialParams",
    "log_mean_exp",
    "make_generator",
    "moment_match",
    "native_bf16",
    "predict",
    "resolve_device",
    "run_sequential",
]


@dataclass(eq=False)
class Prediction:
    """Predictive distributions for a batch on the canvas (float32, no gradients).

    Attributes:
        source_probs: ``(B, H, W)`` source probabilities, sum 1 over valid cells, 0 elsewhere.
        valid: ``(B, H, W)`` bool valid mask.
        wind_mean, wind_var: ``(B, 2, H, W)`` Gaussian wind (m/s, (m/s)^2), None for DGSE-O.
        logc_mean, logc_var: ``(B, H, W)`` Gaussian ``log(c + 1)``, None for DGSE-O.
        K, T: the numbers of samples used (1, 1 for O and P).
    """

    source_probs: torch.Tensor
    valid: torch.Tensor
    wind_mean: torch.Tensor | None = None
    wind_var: torch.Tensor | None = None
    logc_mean: torch.Tensor | None = None
    logc_var: torch.Tensor | None = None
    K: int = 1
    T: int = 1


@dataclass(eq=False)
class SequentialParams:
    """Intermediate distribution parameters of a DGSE-S sample pass (float32).

    Attributes:
        wind_mean, wind_logvar: ``(B, 2, H, W)``.
        logc_mean, logc_logvar: ``(K, B, H, W)``, conditioned on the ``K`` wind samples.
    """

    wind_mean: torch.Tensor
    wind_logvar: torch.Tensor
    logc_mean: torch.Tensor
    logc_logvar: torch.Tensor


def native_bf16(device: torch.device | str) -> bool:
    """Whether ``device`` computes in bfloat16 natively, so that bf16 autocast speeds the
    networks up: a CUDA GPU that supports it, or a CPU with AVX-512-BF16 or AMX.

    Elsewhere bf16 is emulated: on an AVX2-only CPU one DGSE-S estimate took 2.57 s in
    bf16 against 0.35 s in float32 (one thread, ``benchmarks/results/latency_avx2``).
    """
    dev = torch.device(device) if isinstance(device, str) else device
    if dev.type == "cuda":
        return bool(torch.cuda.is_available() and torch.cuda.is_bf16_supported())
    if dev.type != "cpu":
        return False
    names = ("_is_avx512_bf16_supported", "_is_amx_tile_supported")  # private, so looked up
    return any(bool(probe()) for probe in (getattr(torch.cpu, n, None) for n in names) if probe is not None)


def resolve_device(device: torch.device | str) -> torch.device:
    """``device`` as a :class:`torch.device` that this PyTorch build can use.

    Raises:
        InputDataError: a name PyTorch does not know (``"gpu"``).
        UnsupportedError: a device this build or machine does not have
            (``"cuda"`` on a CPU build of PyTorch or a machine without a GPU).
    """
    if isinstance(device, torch.device):
        dev = device
    else:
        try:
            dev = torch.device(str(device).strip())
        except (RuntimeError, ValueError, TypeError):
            raise InputDataError(f"unknown device {device!r}: use cpu, cuda, cuda:N or mps") from None
    if dev.type == "cuda":
        if not torch.cuda.is_available():
            build = "a CPU build of PyTorch" if torch.version.cuda is None else "no usable CUDA GPU"
            raise UnsupportedError(
                f"device {str(device)!r} asked for, but this installation has {build} "
                f"(torch {torch.__version__}): use --device cpu, or install a CUDA build of PyTorch"
            )
        if dev.index is not None and dev.index >= torch.cuda.device_count():
            raise UnsupportedError(
                f"device {str(device)!r}: only {torch.cuda.device_count()} CUDA device(s) here"
            )
    elif dev.type == "mps":
        if not torch.backends.mps.is_available():
            raise UnsupportedError(f"device {str(device)!r}: MPS is not available here: use --device cpu")
    elif dev.type != "cpu":
        raise UnsupportedError(f"device {str(device)!r} is not supported: use cpu, cuda, cuda:N or mps")
    return dev


def make_generator(
    device: torch.device | str, generator: torch.Generator | None = None, seed: int | None = None
) -> torch.Generator | None:
    """``generator`` if given, else a new one on ``device`` seeded with ``seed``, else None (global RNG)."""
    if generator is not None:
        return generator
    if seed is None:
        return None
    return torch.Generator(device=torch.device(device)).manual_seed(int(seed))


def moment_match(
    means: torch.Tensor, variances: torch.Tensor, dim: int = 0
) -> tuple[torch.Tensor, torch.Tensor]:
    """Mean and variance of an equal-weight Gaussian mixture along ``dim`` (Eq. 20-21).

    ``mu = mean_k mu_k`` and ``var = mean_k (var_k + mu_k^2) - mu^2``, computed
    as ``mean_k var_k + mean_k (mu_k - mu)^2`` (same value, no cancellation).

    Args:
        means, variances: component parameters, the components along ``dim``.

    Returns:
        ``(mean, variance)`` with ``dim`` reduced.
    """
    mu = means.mean(dim=dim)
    spread = (means - mu.unsqueeze(dim)).square().mean(dim=dim)
    return mu, variances.mean(dim=dim) + spread


def _chunks(n: int, size: int | None) -> list[tuple[int, int]]:
    step = n if size is None else max(1, int(size))
    return [(a, min(a + step, n)) for a in range(0, n, step)]


def _randn(shape: tuple[int, ...], like: torch.Tensor, generator: torch.Generator | None) -> torch.Tensor:
    return torch.randn(shape, generator=generator, device=like.device, dtype=like.dtype)


def run_sequential(
    model: DGSE_S,
    x: torch.Tensor,
    K: int,
    T: int,
    consume: Callable[[int, int, torch.Tensor], None],
    generator: torch.Generator | None = None,
    max_batch: int | None = None,
) -> SequentialParams:
    """The three DGSE-S stages on ``K`` wind and ``K * T`` concentration samples.

    No gradient handling here: call it inside ``torch.inference_mode()`` (or
    with grad enabled, if wanted) and autocast as needed.

    Args:
        model: a DGSE-S network.
        x: ``(B, 5, H, W)`` canvas input (float32).
        K, T: samples of the wind per input and of the concentration per wind sample.
        consume: called as ``consume(start, stop, log_probs)`` for consecutive
            ranges of the flat replica index ``n = (t * K + k) * B + b``, with
            the masked source log-probabilities ``(stop - start, H, W)``
            (float32, ``-inf`` off the valid cells).
        generator: noise source (global RNG if None).
        max_batch: at most this many canvases per network call (None: one call per stage).

    Returns:
        The wind and conditional concentration parameters (:class:`SequentialParams`).
    """
    if K < 1 or T < 1:
        raise InputDataError(f"K and T must be >= 1, got K={K}, T={T}")
    B, _, H, W = x.shape
    valid = x[:, 4] > 0.5
    mu_w, lv_w = (t.float() for t in model.wind_params(x))
    one_call = max_batch is None or max_batch >= K * B * T
    # stage 2: K wind samples -> concentration parameters
    KB = K * B
    eps_w = _randn((K, B, 2, H, W), x, generator).reshape(KB, 2, H, W) if one_call else None
    w_all = torch.empty((KB, 2, H, W), dtype=torch.float32, device=x.device)
    mu_c = torch.empty((KB, H, W), dtype=torch.float32, device=x.device)
    lv_c = torch.empty_like(mu_c)
    for a, b in _chunks(KB, max_batch):
        bi = torch.arange(a, b, device=x.device) % B
        e = eps_w[a:b] if eps_w is not None else _randn((b - a, 2, H, W), x, generator)
        w = model.sample_wind(mu_w[bi], lv_w[bi], e, valid[bi])
        m, lv = model.conc_params(w.to(x.dtype), x[bi])
        w_all[a:b], mu_c[a:b], lv_c[a:b] = w, m.float(), lv.float()
    # stage 3: T concentration samples per wind sample -> source log-probabilities
    N = T * KB
    eps_c = _randn((T, K, B, H, W), x, generator).reshape(N, H, W) if one_call else None
    for a, b in _chunks(N, max_batch):
        n = torch.arange(a, b, device=x.device)
        mi, bi = n % KB, n % B
        e = eps_c[a:b] if eps_c is not None else _randn((b - a, H, W), x, generator)
        c = model.sample_logc(mu_c[mi], lv_c[mi], e, valid[bi])
        logits = model.source_logits(w_all[mi].to(x.dtype), c.to(x.dtype), x[bi])
        consume(a, b, masked_log_softmax(logits.float(), valid[bi]))
    return SequentialParams(
        wind_mean=mu_w,
        wind_logvar=lv_w,
        logc_mean=mu_c.reshape(K, B, H, W),
        logc_logvar=lv_c.reshape(K, B, H, W),
    )


def predict(
    model: DGSEModel,
    inputs: torch.Tensor,
    K: int = 5,
    T: int = 5,
    *,
    generator: torch.Generator | None = None,
    seed: int | None = None,
    autocast_dtype: torch.dtype | None = None,
    channels_last: bool = False,
    max_batch: int | None = None,
) -> Prediction:
    """Predictive wind, concentration and source distributions for a batch.

    Args:
        model: a :class:`~dgse.models.networks.DGSEModel` (put in ``eval()``
            mode by the caller when it uses BatchNorm; GroupNorm does not care).
        inputs: ``(B, 5, H, W)`` (or one ``(5, H, W)``) canvas input, on the model's device.
        K, T: MC samples of DGSE-S (ignored by O and P, which make one pass).
        generator: noise source; ``seed`` makes a fresh one when no generator is given.
        autocast_dtype: e.g. ``torch.bfloat16`` to run the networks under
            ``torch.autocast``; sampling, softmax and moments stay float32.
        channels_last: feed the networks channels-last inputs (convert the
            model once with ``model.to(memory_format=torch.channels_last)``).
        max_batch: at most this many canvases per network call (memory bound).

    Returns:
        A :class:`Prediction` (float32 tensors, batch dimension kept).
    """
    x = inputs.unsqueeze(0) if inputs.ndim == 3 else inputs
    if x.ndim != 4 or x.shape[1] != 5:
        raise InputDataError(f"inputs must have shape (B, 5, H, W), got {tuple(inputs.shape)}")
    if K < 1 or T < 1:
        raise InputDataError(f"K and T must be >= 1, got K={K}, T={T}")
    if channels_last:
        x = x.contiguous(memory_format=torch.channels_last)
    gen = make_generator(x.device, generator, seed)
    amp: Any = (
        torch.autocast(device_type=x.device.type, dtype=autocast_dtype)
        if autocast_dtype is not None
        else nullcontext()
    )
    with torch.inference_mode(), amp:
        if not isinstance(model, DGSE_S):
            out = model(x)
            probs = masked_log_softmax(out.source_logits.float(), out.valid).exp()
            if out.wind_mean is None or out.wind_logvar is None:
                return Prediction(source_probs=probs, valid=out.valid)
            assert out.logc_mean is not None and out.logc_logvar is not None
            return Prediction(
                source_probs=probs,
                valid=out.valid,
                wind_mean=out.wind_mean.float(),
                wind_var=out.wind_logvar.float().exp(),
                logc_mean=out.logc_mean.float(),
                logc_var=out.logc_logvar.float().exp(),
            )
        B, _, H, W = x.shape
        acc = torch.zeros((B, H * W), dtype=torch.float32, device=x.device)

        def consume(a: int, b: int, logp: torch.Tensor) -> None:
            bi = torch.arange(a, b, device=x.device) % B
            acc.index_add_(0, bi, logp.reshape(b - a, -1).exp())

        params = run_sequential(model, x, K, T, consume, gen, max_batch)
        mu_c, var_c = moment_match(params.logc_mean, params.logc_logvar.exp(), dim=0)
        valid = x[:, 4] > 0.5
        return Prediction(
            source_probs=(acc / (K * T)).reshape(B, H, W),
            valid=valid,
            wind_mean=params.wind_mean,
            wind_var=params.wind_logvar.exp(),
            logc_mean=mu_c,
            logc_var=var_c,
            K=K,
            T=T,
        )


def log_mean_exp(values: torch.Tensor, dim: int = 0) -> torch.Tensor:
    """``log(mean(exp(values)))`` along ``dim``, stable (``logsumexp - log n``)."""
    return torch.logsumexp(values, dim=dim) - math.log(values.shape[dim])
