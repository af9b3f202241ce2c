"""Export of the DGSE networks to ONNX (for TensorRT on embedded GPUs, ONNX Runtime, ...).

What is exported
----------------
The predictive distributions of :func:`dgse.models.inference.predict`, not
raw logits: an embedded user wants one engine call per estimate, with the
softmax, the variances and (DGSE-S) the Monte Carlo marginalization inside
the graph.  Two export variants (``variant=``):

``"pipeline"`` (default; the only one of DGSE-O and DGSE-P): one file.

* DGSE-O / DGSE-P: input ``x`` ``(B, 5, H, W)`` (the canvas of
  :func:`dgse.data.rasterize.rasterize`); outputs ``source_probs``
  ``(B, H, W)`` and, for DGSE-P, ``wind_mean``, ``wind_var`` ``(B, 2, H, W)``,
  ``logc_mean``, ``logc_var`` ``(B, H, W)``.
* DGSE-S: the whole ``K, T``-marginalized pipeline (Eq. 12-22) with the
  noise as explicit inputs: ``x`` ``(B, 5, H, W)``, ``eps_wind``
  ``(K, B, 2, H, W)`` and ``eps_logc`` ``(T, K, B, H, W)`` (standard normal);
  same outputs as DGSE-P (``logc_*`` moment-matched over the ``K`` wind
  samples, ``source_probs`` the mean over the ``K T`` samples).  ``K`` and
  ``T`` are dynamic: they are the leading sizes of the noise inputs, so one
  engine serves every sample count.  The noise is an input because ONNX's
  ``RandomNormal`` is not reproducible across runtimes (and TensorRT supports
  it only partly): pass fresh ``N(0, 1)`` noise per call (cuRAND, or
  ``numpy.random.standard_normal``), or fixed noise for deterministic
  results.  With the noise drawn as :func:`~dgse.models.inference.predict`
  draws it from a generator (``eps_wind`` first, then ``eps_logc``, whole
  tensors) the outputs equal ``predict``'s.

``"stages"`` (DGSE-S only): three files ``<out>.wind.onnx``,
``<out>.conc.onnx``, ``<out>.source.onnx``, for memory-bounded devices that
run the ``K T`` replicas in chunks (``max_batch``) or schedule the stages
themselves; the sampling is inside the graphs, the replication and the
averaging are the caller's:

* wind: ``x (B, 5, H, W) -> wind_mean, wind_var (B, 2, H, W)``;
* conc: ``x (N, 5, H, W), wind_mean, wind_var, eps_wind (N, 2, H, W) ->
  wind_sample (N, 2, H, W), logc_mean, logc_var (N, H, W)`` with
  ``wind_sample = (mean + sqrt(var) eps) * valid`` (Eq. 17);
* source: ``x (N, 5, H, W), wind_sample (N, 2, H, W), logc_mean, logc_var,
  eps_logc (N, H, W) -> source_probs (N, H, W)`` with the concentration sample
  ``(mean + sqrt(var) eps) * valid`` (Eq. 18);

then ``source_probs`` = the mean of the ``K T`` replicas of a canvas, and the
concentration Gaussian is moment-matched over the ``K`` conc outputs
(``mean = mean_k mu_k``, ``var = mean_k var_k + mean_k (mu_k - mean)^2``).

Dynamic axes: batch (``B``, ``N``), canvas height and width (any size: the
U-Nets pad to a multiple of their stride *inside* the graph, as in PyTorch)
and ``K``, ``T``.  TensorRT needs an optimization profile for them, e.g.
``trtexec --onnx=dgse-s.onnx --minShapes=x:1x5x100x100,eps_wind:1x1x2x100x100,eps_logc:1x1x1x100x100
--optShapes=x:1x5x100x100,eps_wind:5x1x2x100x100,eps_logc:5x5x1x100x100 --maxShapes=...
--fp16``.  Opset 17 by default (TensorRT 8.6+; GroupNorm is exported as
InstanceNormalization on reshaped tensors).  Float32 weights and inputs;
reduced precision is the runtime's choice (``--fp16``): the masked softmax
uses ``-65504`` (the float16 minimum), not ``-inf``, for cells off the valid
region, and its output is exactly 0 there.

Each file carries metadata (``metadata_props``): ``dgse_variant``,
``export_variant``, ``stage``, ``model_config`` (JSON), ``stride``,
``inputs``, ``outputs`` and ``dgse_version``.

Exporter: PyTorch's TorchScript-based exporter (``torch.onnx.export(...,
dynamo=False)``): it needs no extra package (the ``torch.export``-based one
needs ``onnxscript``).  The graph is traced from the stage methods'
building blocks (U-Net encoder and decoder, heads) with the padding computed
from the input shape, so the shapes stay symbolic; :func:`check_onnx`
compares a file with PyTorch on ONNX Runtime.
"""

from __future__ import annotations

import json
import math
import os
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from dgse.data.rasterize import CH_GAS, CH_OCCUPANCY, CH_VALID, UNOBSERVED_GAS
from dgse.errors import InputDataError, UnsupportedError
from dgse.files import atomic_path
from dgse.models.networks import DGSE_O, DGSE_P, DGSE_S, INPUT_FILL, DGSEModel
from dgse.models.unet import UNet

__all__ = [
    "DEFAULT_OPSET",
    "EXPORT_VARIANTS",
    "MASK_VALUE",
    "OnnxExport",
    "OnnxFile",
    "check_onnx",
    "example_inputs",
    "export_modules",
    "export_onnx",
    "pipeline_reference",
]

#: Export variants (``"auto"``: ``"pipeline"``).
EXPORT_VARIANTS = ("auto", "pipeline", "stages")
#: Default ONNX opset (TensorRT 8.6 and ONNX Runtime >= 1.14 read it).
DEFAULT_OPSET = 17
#: Logit of cells off the valid region in the exported softmax (the float16 minimum).
MASK_VALUE = -65504.0


# -- graph building blocks (symbolic shapes under tracing) --------------------------------------
def _pad(x: torch.Tensor, multiple: int, fill: float | Sequence[float]) -> torch.Tensor:
    """Pad H and W at their high ends to a multiple of ``multiple`` (as ``pad_to_multiple``)."""
    h, w = x.shape[-2], x.shape[-1]
    ph = (multiple - h % multiple) % multiple
    pw = (multiple - w % multiple) % multiple
    if isinstance(fill, (int, float)):
        return F.pad(x, [0, pw, 0, ph], value=float(fill))
    values = torch.tensor([float(v) for v in fill], dtype=x.dtype, device=x.device).view(1, -1, 1, 1)
    return F.pad(x - values, [0, pw, 0, ph], value=0.0) + values


def _unet(net: UNet, x: torch.Tensor) -> torch.Tensor:
    """``net(x)`` with the padding and cropping traced symbolically."""
    h, w = x.shape[-2], x.shape[-1]
    bottleneck, skips = net.encoder(_pad(x, net.stride, net.pad_value))
    return net.decoder(bottleneck, skips)[..., :h, :w]


def _masked_softmax(logits: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    """Softmax over the cells of each ``(H, W)`` map restricted to ``valid``; exactly 0 elsewhere."""
    flat = logits.flatten(1)
    v = valid.flatten(1)
    z = torch.where(v, flat, torch.full_like(flat, MASK_VALUE))
    return (torch.softmax(z, dim=1) * v.to(z.dtype)).view_as(logits)


def _valid(x: torch.Tensor) -> torch.Tensor:
    return x[:, CH_VALID] > 0.5


def _s_wind(model: DGSE_S, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    out = _unet(model.wind_net, x)
    return out[:, :2], model._logvar(out[:, 2:])


def _s_conc(model: DGSE_S, wind: torch.Tensor, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    inp = torch.cat([wind, x[:, CH_GAS : CH_GAS + 1], x[:, CH_OCCUPANCY : CH_VALID + 1]], dim=1)
    out = _unet(model.conc_net, inp)
    return out[:, 0], model._logvar(out[:, 1])


def _s_source_probs(model: DGSE_S, wind: torch.Tensor, logc: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
    inp = torch.cat([wind, logc.unsqueeze(1), x[:, CH_OCCUPANCY : CH_VALID + 1]], dim=1)
    return _masked_softmax(_unet(model.source_net, inp)[:, 0], _valid(x))


# -- exportable modules -------------------------------------------------------------------------
class _Pipeline(nn.Module):
    def __init__(self, model: DGSEModel) -> None:
        super().__init__()
        self.model = model


class PipelineO(_Pipeline):
    """DGSE-O: ``x -> source_probs``."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        m = self.model
        assert isinstance(m, DGSE_O)
        return _masked_softmax(_unet(m.net, x)[:, 0], _valid(x))


class PipelineP(_Pipeline):
    """DGSE-P: ``x -> source_probs, wind_mean, wind_var, logc_mean, logc_var``."""

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, ...]:
        m = self.model
        assert isinstance(m, DGSE_P)
        h, w = x.shape[-2], x.shape[-1]
        bottleneck, skips = m.encoder(_pad(x, m.stride, INPUT_FILL))
        wind = m.wind_decoder(bottleneck, skips)[..., :h, :w]
        conc = m.conc_decoder(bottleneck, skips)[..., :h, :w]
        logits = m.source_decoder(bottleneck, skips)[..., :h, :w][:, 0]
        return (
            _masked_softmax(logits, _valid(x)),
            wind[:, :2],
            torch.exp(m._logvar(wind[:, 2:])),
            conc[:, 0],
            torch.exp(m._logvar(conc[:, 1])),
        )


class PipelineS(_Pipeline):
    """DGSE-S: ``x, eps_wind (K, B, 2, H, W), eps_logc (T, K, B, H, W)`` -> the predictive outputs."""

    def forward(
        self, x: torch.Tensor, eps_wind: torch.Tensor, eps_logc: torch.Tensor
    ) -> tuple[torch.Tensor, ...]:
        m = self.model
        assert isinstance(m, DGSE_S)
        B, H, W = x.shape[0], x.shape[2], x.shape[3]
        vf = _valid(x).to(x.dtype)  # (B, H, W)
        mu_w, lv_w = _s_wind(m, x)  # (B, 2, H, W)
        w = (mu_w.unsqueeze(0) + torch.exp(0.5 * lv_w).unsqueeze(0) * eps_wind) * vf[None, :, None]
        # replicas k * B + b (sample-major, as in dgse.models.inference)
        xk = (x.unsqueeze(0) + torch.zeros_like(eps_wind[:, :, :1])).flatten(0, 1)  # (KB, 5, H, W)
        wk = w.flatten(0, 1)  # (KB, 2, H, W)
        mu_c, lv_c = _s_conc(m, wk, xk)  # (KB, H, W)
        vk = _valid(xk).to(x.dtype)
        eps_c = eps_logc.flatten(1, 2)  # (T, KB, H, W)
        c = (mu_c.unsqueeze(0) + torch.exp(0.5 * lv_c).unsqueeze(0) * eps_c) * vk.unsqueeze(0)
        zeros = torch.zeros_like(c).unsqueeze(2)  # (T, KB, 1, H, W)
        wt = (wk.unsqueeze(0) + zeros).flatten(0, 1)  # replicas (t * K + k) * B + b
        xt = (xk.unsqueeze(0) + zeros).flatten(0, 1)
        probs = _s_source_probs(m, wt, c.flatten(0, 1), xt)  # (TKB, H, W)
        source_probs = probs.reshape(-1, B, H, W).mean(dim=0)
        mu_k = mu_c.reshape(-1, B, H, W)  # (K, B, H, W)
        var_k = torch.exp(lv_c).reshape(-1, B, H, W)
        logc_mean = mu_k.mean(dim=0)
        logc_var = var_k.mean(dim=0) + (mu_k - logc_mean.unsqueeze(0)).square().mean(dim=0)
        return source_probs, mu_w, torch.exp(lv_w), logc_mean, logc_var


class StageWind(_Pipeline):
    """DGSE-S stage 1: ``x -> wind_mean, wind_var``."""

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        assert isinstance(self.model, DGSE_S)
        mu, lv = _s_wind(self.model, x)
        return mu, torch.exp(lv)


class StageConc(_Pipeline):
    """DGSE-S stage 2: ``x, wind_mean, wind_var, eps_wind -> wind_sample, logc_mean, logc_var``."""

    def forward(
        self, x: torch.Tensor, wind_mean: torch.Tensor, wind_var: torch.Tensor, eps_wind: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        assert isinstance(self.model, DGSE_S)
        vf = _valid(x).to(x.dtype).unsqueeze(1)
        w = (wind_mean + torch.sqrt(wind_var) * eps_wind) * vf
        mu, lv = _s_conc(self.model, w, x)
        return w, mu, torch.exp(lv)


class StageSource(_Pipeline):
    """DGSE-S stage 3: ``x, wind_sample, logc_mean, logc_var, eps_logc -> source_probs``."""

    def forward(
        self,
        x: torch.Tensor,
        wind_sample: torch.Tensor,
        logc_mean: torch.Tensor,
        logc_var: torch.Tensor,
        eps_logc: torch.Tensor,
    ) -> torch.Tensor:
        assert isinstance(self.model, DGSE_S)
        c = (logc_mean + torch.sqrt(logc_var) * eps_logc) * _valid(x).to(x.dtype)
        return _s_source_probs(self.model, wind_sample, c, x)


# -- specs --------------------------------------------------------------------------------------
_FIELD_OUT = ("wind_mean", "wind_var", "logc_mean", "logc_var")
_AXES: dict[str, dict[int, str]] = {
    "x": {0: "batch", 2: "height", 3: "width"},
    "source_probs": {0: "batch", 1: "height", 2: "width"},
    "wind_mean": {0: "batch", 2: "height", 3: "width"},
    "wind_var": {0: "batch", 2: "height", 3: "width"},
    "wind_sample": {0: "batch", 2: "height", 3: "width"},
    "logc_mean": {0: "batch", 1: "height", 2: "width"},
    "logc_var": {0: "batch", 1: "height", 2: "width"},
    "eps_logc_stage": {0: "batch", 1: "height", 2: "width"},
    "eps_wind_stage": {0: "batch", 2: "height", 3: "width"},
    "eps_wind": {0: "K", 1: "batch", 3: "height", 4: "width"},
    "eps_logc": {0: "T", 1: "K", 2: "batch", 3: "height", 4: "width"},
}


@dataclass(frozen=True)
class OnnxFile:
    """One exportable graph: its module, input and output names, and the file suffix."""

    stage: str
    module: nn.Module
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    suffix: str = ""
    axes: dict[str, dict[int, str]] = field(default_factory=dict)


def _resolve_variant(model: DGSEModel, variant: str) -> str:
    if variant not in EXPORT_VARIANTS:
        raise InputDataError(f"unknown export variant {variant!r}; use one of {', '.join(EXPORT_VARIANTS)}")
    v = "pipeline" if variant == "auto" else variant
    if v == "stages" and not isinstance(model, DGSE_S):
        raise InputDataError(
            f"the 'stages' export is for DGSE-S; a {model.config.variant} network is one stage"
        )
    return v


def export_modules(model: DGSEModel, variant: str = "auto") -> list[OnnxFile]:
    """The graphs an export of ``model`` writes (modules in ``eval()`` mode, sharing the weights)."""
    if not isinstance(model, DGSEModel):
        raise InputDataError(f"can only export DGSE networks, got {type(model).__name__}")
    v = _resolve_variant(model, variant)
    model.eval()
    if isinstance(model, DGSE_O):
        return [OnnxFile("pipeline", PipelineO(model).eval(), ("x",), ("source_probs",), axes=_AXES)]
    if isinstance(model, DGSE_P):
        return [
            OnnxFile("pipeline", PipelineP(model).eval(), ("x",), ("source_probs", *_FIELD_OUT), axes=_AXES)
        ]
    assert isinstance(model, DGSE_S)
    if v == "pipeline":
        return [
            OnnxFile(
                "pipeline",
                PipelineS(model).eval(),
                ("x", "eps_wind", "eps_logc"),
                ("source_probs", *_FIELD_OUT),
                axes=_AXES,
            )
        ]
    stage_axes = {**_AXES, "eps_wind": _AXES["eps_wind_stage"], "eps_logc": _AXES["eps_logc_stage"]}
    return [
        OnnxFile("wind", StageWind(model).eval(), ("x",), ("wind_mean", "wind_var"), ".wind", stage_axes),
        OnnxFile(
            "conc",
            StageConc(model).eval(),
            ("x", "wind_mean", "wind_var", "eps_wind"),
            ("wind_sample", "logc_mean", "logc_var"),
            ".conc",
            stage_axes,
        ),
        OnnxFile(
            "source",
            StageSource(model).eval(),
            ("x", "wind_sample", "logc_mean", "logc_var", "eps_logc"),
            ("source_probs",),
            ".source",
            stage_axes,
        ),
    ]


def example_inputs(
    spec: OnnxFile, batch: int = 2, canvas: tuple[int, int] = (20, 28), K: int = 3, T: int = 2, seed: int = 0
) -> dict[str, torch.Tensor]:
    """Plausible float32 inputs for a graph: a canvas with a map, sensors and padding, and noise.

    The map covers ``(canvas_h - 3, canvas_w - 5)`` cells at the lower-left corner
    (so the valid mask and padding are exercised); about 10 % of its cells are
    solid and 10 % observed.
    """
    g = torch.Generator().manual_seed(seed)
    S_h, S_w = canvas
    H, W = max(1, S_h - 3), max(1, S_w - 5)
    x = torch.zeros(batch, 5, S_h, S_w)
    x[:, CH_GAS] = UNOBSERVED_GAS
    x[:, CH_OCCUPANCY] = 1.0
    x[:, CH_OCCUPANCY, :H, :W] = (torch.rand(batch, H, W, generator=g) < 0.1).float()
    x[:, CH_VALID, :H, :W] = 1.0
    obs = (torch.rand(batch, H, W, generator=g) < 0.1) & (x[:, CH_OCCUPANCY, :H, :W] == 0)
    x[:, CH_GAS, :H, :W] = torch.where(obs, torch.rand(batch, H, W, generator=g) * 4, UNOBSERVED_GAS)
    x[:, 1, :H, :W] = torch.where(obs, torch.randn(batch, H, W, generator=g), 0.0)
    x[:, 2, :H, :W] = torch.where(obs, torch.randn(batch, H, W, generator=g), 0.0)
    shapes: dict[str, tuple[int, ...]] = {
        "x": (batch, 5, S_h, S_w),
        "wind_mean": (batch, 2, S_h, S_w),
        "wind_sample": (batch, 2, S_h, S_w),
        "logc_mean": (batch, S_h, S_w),
    }
    out: dict[str, torch.Tensor] = {}
    for name in spec.inputs:
        if name == "x":
            out[name] = x
        elif name == "eps_wind":
            shape: tuple[int, ...] = (
                (K, batch, 2, S_h, S_w) if spec.stage == "pipeline" else (batch, 2, S_h, S_w)
            )
            out[name] = torch.randn(shape, generator=g)
        elif name == "eps_logc":
            shape = (T, K, batch, S_h, S_w) if spec.stage == "pipeline" else (batch, S_h, S_w)
            out[name] = torch.randn(shape, generator=g)
        elif name in ("wind_var", "logc_var"):
            base = "wind_mean" if name == "wind_var" else "logc_mean"
            out[name] = torch.rand(shapes[base], generator=g) * 0.5 + 0.01
        else:
            out[name] = torch.randn(shapes[name], generator=g)
    return out


@dataclass(frozen=True)
class OnnxExport:
    """What :func:`export_onnx` wrote.

    Attributes:
        paths: the ONNX files (one, or three for DGSE-S stages: wind, conc, source).
        dgse_variant: ``"dgse-o"``, ``"dgse-p"`` or ``"dgse-s"``.
        export_variant: ``"pipeline"`` or ``"stages"``.
        opset: the ONNX opset.
        stages: the stage of each file (``"pipeline"``, ``"wind"``, ``"conc"``, ``"source"``).
        inputs, outputs: the input and output names of each file.
    """

    paths: tuple[Path, ...]
    dgse_variant: str
    export_variant: str
    opset: int
    stages: tuple[str, ...]
    inputs: tuple[tuple[str, ...], ...]
    outputs: tuple[tuple[str, ...], ...]


def _stage_path(out: Path, suffix: str) -> Path:
    if not suffix:
        return out
    stem = out.name[: -len(".onnx")] if out.name.endswith(".onnx") else out.name
    return out.with_name(f"{stem}{suffix}.onnx")


def _dgse_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("dgse")
    except PackageNotFoundError:
        return ""


def export_onnx(
    model: DGSEModel | str | os.PathLike[str],
    out: str | os.PathLike[str],
    variant: str = "auto",
    opset: int = DEFAULT_OPSET,
    example_canvas: tuple[int, int] = (20, 28),
) -> OnnxExport:
    """Export a DGSE network (or the network of a checkpoint) to ONNX (see the module docstring).

    Args:
        model: a network, or the path of a checkpoint (:func:`dgse.models.checkpoint.save_model`).
        out: the ``.onnx`` file; the ``"stages"`` variant writes ``<out>.wind.onnx``,
            ``<out>.conc.onnx`` and ``<out>.source.onnx`` (``.onnx`` of ``out`` removed).
        variant: ``"auto"`` / ``"pipeline"`` or ``"stages"`` (DGSE-S only).
        opset: ONNX opset, at least 17.
        example_canvas: canvas of the tracing inputs (any size works afterwards).

    Raises:
        InputDataError: a bad variant or opset, an unreadable checkpoint.
        UnsupportedError: the ``onnx`` package is missing.
    """
    try:
        import onnx
    except ImportError as e:  # pragma: no cover - onnx is an optional dependency
        raise UnsupportedError("ONNX export needs the onnx package: pip install 'dgse[onnx]'") from e
    if isinstance(opset, bool) or not isinstance(opset, int) or opset < 17:
        raise InputDataError(f"the ONNX opset must be an integer >= 17, got {opset!r}")
    if not isinstance(model, DGSEModel):
        from dgse.models.checkpoint import load_model

        model = load_model(model)
    net = model.to("cpu").float()
    specs = export_modules(net, variant)
    v = _resolve_variant(net, variant)
    out_path = Path(out)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    paths: list[Path] = []
    for spec in specs:
        path = _stage_path(out_path, spec.suffix)
        inputs = example_inputs(spec, canvas=example_canvas)
        axes = {name: spec.axes[name] for name in (*spec.inputs, *spec.outputs)}
        # exported, completed with the metadata and checked under a temporary name: an
        # interrupted export leaves no half-written model
        with atomic_path(path) as tmp:
            with warnings.catch_warnings(), torch.no_grad():
                warnings.simplefilter("ignore")
                torch.onnx.export(
                    spec.module,
                    tuple(inputs[n] for n in spec.inputs),
                    str(tmp),
                    dynamo=False,
                    opset_version=opset,
                    input_names=list(spec.inputs),
                    output_names=list(spec.outputs),
                    dynamic_axes=axes,
                    do_constant_folding=True,
                )
            proto = onnx.load(str(tmp))
            meta = {
                "dgse_variant": net.config.variant,
                "export_variant": v,
                "stage": spec.stage,
                "model_config": json.dumps(net.config.to_dict(), sort_keys=True),
                "stride": str(net.stride),
                "inputs": ",".join(spec.inputs),
                "outputs": ",".join(spec.outputs),
                "dgse_version": _dgse_version(),
            }
            onnx.helper.set_model_props(proto, meta)
            proto.doc_string = f"DGSE {net.config.variant} ({spec.stage}); see dgse.models.onnx_export"
            onnx.checker.check_model(proto)
            onnx.save(proto, str(tmp))
        paths.append(path)
    return OnnxExport(
        paths=tuple(paths),
        dgse_variant=net.config.variant,
        export_variant=v,
        opset=opset,
        stages=tuple(s.stage for s in specs),
        inputs=tuple(s.inputs for s in specs),
        outputs=tuple(s.outputs for s in specs),
    )


def pipeline_reference(
    model: DGSEModel, x: torch.Tensor, K: int = 5, T: int = 5, seed: int = 0
) -> tuple[dict[str, torch.Tensor], list[torch.Tensor]]:
    """Inputs and PyTorch outputs (:func:`dgse.models.inference.predict`) of a ``"pipeline"`` graph.

    For DGSE-S the noise inputs are drawn the way ``predict`` draws them from a
    generator seeded ``seed`` (``eps_wind`` ``(K, B, 2, H, W)``, then
    ``eps_logc`` ``(T, K, B, H, W)``), so the ONNX graph fed with them must give
    ``predict(model, x, K, T, seed=seed)``.

    Returns:
        ``(inputs by name, outputs in the graph's output order)``.
    """
    from dgse.models.inference import predict

    x = x.float()
    inputs = {"x": x}
    if isinstance(model, DGSE_S):
        B, _, H, W = x.shape
        g = torch.Generator().manual_seed(int(seed))
        inputs["eps_wind"] = torch.randn((K, B, 2, H, W), generator=g)
        inputs["eps_logc"] = torch.randn((T, K, B, H, W), generator=g)
    pred = predict(model, x, K, T, seed=int(seed))
    if pred.wind_mean is None:
        return inputs, [pred.source_probs]
    assert pred.wind_var is not None and pred.logc_mean is not None and pred.logc_var is not None
    return inputs, [pred.source_probs, pred.wind_mean, pred.wind_var, pred.logc_mean, pred.logc_var]


def check_onnx(
    model: DGSEModel,
    export: OnnxExport,
    batch: int = 2,
    canvas: tuple[int, int] = (37, 29),
    K: int = 2,
    T: int = 3,
    seed: int = 1,
) -> float:
    """Max absolute difference between ONNX Runtime and PyTorch over all outputs of all files.

    Inputs: :func:`example_inputs` of another shape than the tracing inputs (so
    the dynamic axes are exercised), on the CPU.  A ``"pipeline"`` file is
    compared with :func:`dgse.models.inference.predict` itself
    (:func:`pipeline_reference`); a stage file with the PyTorch module it was
    traced from.

    Raises:
        UnsupportedError: onnxruntime is not installed.
    """
    try:
        import onnxruntime as ort
    except ImportError as e:  # pragma: no cover - optional dependency
        raise UnsupportedError("checking an ONNX export needs onnxruntime: pip install 'dgse[onnx]'") from e
    net = model.to("cpu").float().eval()
    specs = {s.stage: s for s in export_modules(net, export.export_variant)}
    worst = 0.0
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = 1
    opts.inter_op_num_threads = 1
    for path, stage in zip(export.paths, export.stages, strict=True):
        spec = specs[stage]
        inputs = example_inputs(spec, batch=batch, canvas=canvas, K=K, T=T, seed=seed)
        if stage == "pipeline":
            inputs, refs = pipeline_reference(net, inputs["x"], K, T, seed)
        else:
            with torch.no_grad():
                ref = spec.module(*(inputs[n] for n in spec.inputs))
            refs = [ref] if isinstance(ref, torch.Tensor) else list(ref)
        sess = ort.InferenceSession(str(path), sess_options=opts, providers=["CPUExecutionProvider"])
        got = sess.run(list(spec.outputs), {n: inputs[n].numpy() for n in spec.inputs})
        for r, o in zip(refs, got, strict=True):
            if tuple(r.shape) != tuple(o.shape):
                raise InputDataError(
                    f"{path}: output shape {o.shape} differs from PyTorch's {tuple(r.shape)}"
                )
            diff = float(np.max(np.abs(r.numpy().astype(np.float64) - o.astype(np.float64)), initial=0.0))
            worst = max(worst, diff if math.isfinite(diff) else math.inf)
    return worst
