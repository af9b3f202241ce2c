"""DGSE networks as :class:`~dgse.belief.estimator.Estimator`\\ s.

:class:`DGSEEstimator` rasterizes the observations onto the network canvas
(:func:`dgse.data.rasterize.canvas_shape_for`, :func:`~dgse.data.rasterize.rasterize`:
100 x 100 for maps up to 100 x 100 cells, the map at the lower-left corner),
runs :func:`dgse.models.inference.predict` (one pass for DGSE-O/P, ``K``
and ``K * T`` samples for DGSE-S), crops the fields back to the map and
returns a :class:`~dgse.belief.belief.Belief` whose source probabilities
are renormalized over the free map cells (the networks spread their mass over
all valid cells, walls included).

Registered names ``"dgse-o"``, ``"dgse-p"``, ``"dgse-s"``: their factories
take ``model=`` a checkpoint path, a loaded network, or ``"default"`` for the
weights shipped in ``dgse/assets/models/<name>.safetensors`` (an
:class:`~dgse.errors.UnsupportedError` when they are not installed), plus the
keyword arguments of :class:`DGSEEstimator`.

CPU latency of one DGSE-S estimate (``K = T = 5``, 100 x 100 canvas, untrained
weights, one AVX-512-bf16 EPYC core shared with other jobs): ``"paper"`` preset
0.78 s float32, 0.52 s float32 channels-last, 0.40 s bf16, 0.33 s bf16
channels-last; ``"small"`` preset 0.21 / 0.15 / 0.12 / 0.14 s.  With two
threads on two busy cores it took 2.4-3.6 s: when the cores are shared,
``torch.set_num_threads(1)`` is much faster.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import replace
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import torch

from dgse.belief.belief import Belief, normalize_source_probs
from dgse.belief.knowledge import KnowledgeUser
from dgse.data.rasterize import DEFAULT_CANVAS, DEFAULT_STRIDE, canvas_shape_for, rasterize
from dgse.errors import InputDataError, UnsupportedError
from dgse.models.checkpoint import load_checkpoint
from dgse.models.inference import Prediction, make_generator, native_bf16, predict, resolve_device
from dgse.models.networks import DGSEModel
from dgse.options import options_from
from dgse.sensing.sensors import Observations, check_sensor_cells
from dgse.world.grid import coarsen, refine_cells, refine_occupancy, refinement_factor

__all__ = ["DGSEEstimator", "default_model_path", "make_dgse_o", "make_dgse_p", "make_dgse_s"]

_DTYPES: dict[str, torch.dtype] = {
    "float32": torch.float32,
    "fp32": torch.float32,
    "bfloat16": torch.bfloat16,
    "bf16": torch.bfloat16,
    "float16": torch.float16,
    "fp16": torch.float16,
}


#: ``dtype="auto"``: bfloat16 where the device computes it natively, else float32
AUTO_DTYPE = "auto"


def _as_dtype(dtype: torch.dtype | str, device: torch.device) -> torch.dtype:
    if isinstance(dtype, torch.dtype):
        if dtype in (torch.float32, torch.bfloat16, torch.float16):
            return dtype
    elif dtype == AUTO_DTYPE:
        return torch.bfloat16 if native_bf16(device) else torch.float32
    elif dtype in _DTYPES:
        return _DTYPES[dtype]
    raise InputDataError(f"dtype must be float32, bfloat16, float16 or auto, got {dtype!r}")


class DGSEEstimator(KnowledgeUser):
    """A DGSE network behind the :class:`~dgse.belief.estimator.Estimator` protocol.

    Args:
        model: a DGSE-O, -P or -S network (:mod:`dgse.models.networks`).
        K, T: MC samples of DGSE-S (paper: 5 and 5); ignored by O and P.
        device: where the network runs (``"cpu"``, ``"cuda"``, ...).
        seed: if given, every :meth:`estimate` uses noise from a generator
            seeded with it (equal inputs give equal beliefs); None: PyTorch's
            global RNG.
        dtype: ``float32`` (default) or ``bfloat16`` / ``float16``: run the
            networks under ``torch.autocast`` with that type (sampling,
            softmax and moment matching stay float32); ``"auto"``: bfloat16
            where the device computes it natively
            (:func:`~dgse.models.inference.native_bf16`), else float32.
        channels_last: use the channels-last memory format (faster convolutions
            on some CPUs with bf16).
        model_resolution: the cell size (m) the network was trained on.  A map whose
            cells are a whole multiple ``f`` of it (0.2 m office floors for 0.1 m
            networks) is refined first: each cell becomes ``f x f`` network cells (a
            reading at the one nearest its centre), and the network's fields come back
            as block sums (source mass) and block means (wind, concentration and their
            variances).  Other resolutions are rejected.
        canvas_minimum, stride: canvas rule (:func:`~dgse.data.rasterize.canvas_shape_for`).
        max_batch: at most this many canvases per network call (memory bound).

    The model is moved to ``device`` (and channels-last) in place and put in ``eval()`` mode.
    """

    def __init__(
        self,
        model: DGSEModel,
        K: int = 5,
        T: int = 5,
        device: torch.device | str = "cpu",
        seed: int | None = None,
        dtype: torch.dtype | str = torch.float32,
        channels_last: bool = False,
        model_resolution: float = 0.1,
        canvas_minimum: int = DEFAULT_CANVAS,
        stride: int = DEFAULT_STRIDE,
        max_batch: int | None = None,
    ) -> None:
        if not isinstance(model, DGSEModel):
            raise InputDataError(f"model must be a DGSE network, got {type(model).__name__}")
        if int(K) < 1 or int(T) < 1:
            raise InputDataError(f"K and T must be >= 1, got K={K}, T={T}")
        if not (model_resolution > 0 and math.isfinite(model_resolution)):
            raise InputDataError(f"model_resolution must be positive, got {model_resolution}")
        self.device = resolve_device(device)
        self.dtype = _as_dtype(dtype, self.device)
        self.channels_last = bool(channels_last)
        self.model = model.to(self.device).eval()
        if self.channels_last:
            self.model = self.model.to(memory_format=torch.channels_last)  # type: ignore[call-overload]
        self.K, self.T = int(K), int(T)
        self.seed = seed
        self.model_resolution = float(model_resolution)
        self.canvas_minimum, self.stride = int(canvas_minimum), int(stride)
        self.max_batch = max_batch
        #: the checkpoint file the network came from (set by :meth:`from_checkpoint`)
        self.checkpoint: Path | None = None

    def describe(self) -> dict[str, Any]:
        """The network, its checkpoint, the samples and where and how it runs."""
        return {
            "name": self.name,
            "K": self.K,
            "T": self.T,
            "checkpoint": self.checkpoint,
            "device": self.device,
            "dtype": self.dtype,
            "channels_last": self.channels_last,
        }

    @property
    def name(self) -> str:
        """``"dgse-o"``, ``"dgse-p"`` or ``"dgse-s"``."""
        return self.model.config.variant

    @classmethod
    def from_checkpoint(
        cls, path: str | os.PathLike[str], variant: str | None = None, **kwargs: Any
    ) -> DGSEEstimator:
        """An estimator for the network in checkpoint ``path`` (optionally checking its variant).

        ``kwargs`` go to :class:`DGSEEstimator`; ``device`` also places the weights.
        """
        kwargs["device"] = resolve_device(kwargs.get("device", "cpu"))
        model, info = load_checkpoint(path, variant=variant, device=kwargs["device"])
        est = cls(model, **kwargs)
        est.checkpoint = info.path
        return est

    def canvas_shape(self, map_shape: tuple[int, int]) -> tuple[int, int]:
        """The canvas used for a map of ``map_shape`` cells."""
        return canvas_shape_for(map_shape, minimum=self.canvas_minimum, stride=self.stride)

    def predict_canvas(self, inputs: np.ndarray | torch.Tensor) -> Prediction:
        """Run the network on a canvas input ``(5, S, S)`` or ``(B, 5, S, S)`` (see :func:`predict`)."""
        x = torch.as_tensor(
            np.asarray(inputs, dtype=np.float32) if isinstance(inputs, np.ndarray) else inputs
        )
        x = x.to(self.device, torch.float32)
        return predict(
            self.model,
            x,
            self.K,
            self.T,
            generator=make_generator(self.device, None, self.seed),
            autocast_dtype=None if self.dtype == torch.float32 else self.dtype,
            channels_last=self.channels_last,
            max_batch=self.max_batch,
        )

    def estimate(self, occupancy: np.ndarray, resolution: float, observations: Observations) -> Belief:
        """The belief on the map grid (see the module docstring).

        Args:
            occupancy: ``(H, W)`` map, 1 solid, 0 free.
            resolution: cell size in m; must equal ``model_resolution``.
            observations: readings at free cells of the map.
        """
        t0 = time.perf_counter()
        occ = np.asarray(occupancy)
        if occ.ndim != 2:
            raise InputDataError(f"occupancy must be 2-D, got shape {occ.shape}")
        factor = refinement_factor(float(resolution), self.model_resolution)
        if factor is None:
            raise InputDataError(
                f"this {self.name} model works on {self.model_resolution} m cells or whole multiples "
                f"of them; the map has {resolution} m cells (resample the map, e.g. with "
                "dgse.world.floorplan.resample_occupancy)"
            )
        net_occ, net_obs = occ, observations
        if factor > 1:  # each map cell as factor x factor network cells
            cells = check_sensor_cells(occ, observations.cells)
            net_occ = refine_occupancy(occ, factor)
            net_obs = replace(observations, cells=refine_cells(cells, factor))
        H, W = net_occ.shape
        canvas = self.canvas_shape((H, W))
        pred = self.predict_canvas(rasterize(net_occ, net_obs, canvas))
        free = occ == 0
        probs = coarsen(pred.source_probs[0, :H, :W].double().cpu().numpy(), factor, "sum")
        info: dict[str, Any] = {
            "method": self.name,
            "K": pred.K,
            "T": pred.T,
            "canvas": canvas,
            "n_observations": len(observations),
            "dtype": str(self.dtype).removeprefix("torch."),
            "device": str(self.device),
            "refinement": factor,  # network cells per map cell along each axis
        }
        if not (probs[free] > 0).any():  # float32 underflow: all mass on walls
            probs = free.astype(np.float64)
            info["degenerate_posterior"] = True
        probs = normalize_source_probs(probs, occ)

        def crop(t: torch.Tensor | None) -> np.ndarray | None:
            return None if t is None else coarsen(t[0, ..., :H, :W].double().cpu().numpy(), factor, "mean")

        info["seconds"] = time.perf_counter() - t0
        return Belief(
            occupancy=occ,
            resolution=float(resolution),
            source_probs=probs,
            wind_mean=crop(pred.wind_mean),
            wind_var=crop(pred.wind_var),
            log_conc_mean=crop(pred.logc_mean),
            log_conc_var=crop(pred.logc_var),
            info=info,
        )


def default_model_path(variant: str) -> Path:
    """The shipped weights ``dgse/assets/models/<variant>.safetensors``.

    Raises:
        UnsupportedError: when this installation has no shipped weights for ``variant``.
    """
    res = resources.files("dgse") / "assets" / "models" / f"{variant}.safetensors"
    if not res.is_file():
        raise UnsupportedError(
            f"no shipped {variant} weights in this installation (expected dgse/assets/models/"
            f"{variant}.safetensors); pass {{model}}=<path to a .safetensors checkpoint>",
            names={"model": "model"},
        )
    return Path(str(res))


def _make(variant: str, model: str | os.PathLike[str] | DGSEModel, **kwargs: Any) -> DGSEEstimator:
    if isinstance(model, DGSEModel):
        if model.config.variant != variant:
            raise InputDataError(f"estimator {variant!r} got a {model.config.variant!r} network")
        return DGSEEstimator(model, **kwargs)
    path = default_model_path(variant) if str(model) == "default" else Path(model)
    return DGSEEstimator.from_checkpoint(path, variant=variant, **kwargs)


@options_from(DGSEEstimator)
def make_dgse_o(model: str | os.PathLike[str] | DGSEModel = "default", **kwargs: Any) -> DGSEEstimator:
    """Factory of ``"dgse-o"``: ``model`` is a checkpoint path, a network or ``"default"``."""
    return _make("dgse-o", model, **kwargs)


@options_from(DGSEEstimator)
def make_dgse_p(model: str | os.PathLike[str] | DGSEModel = "default", **kwargs: Any) -> DGSEEstimator:
    """Factory of ``"dgse-p"``: ``model`` is a checkpoint path, a network or ``"default"``."""
    return _make("dgse-p", model, **kwargs)


@options_from(DGSEEstimator)
def make_dgse_s(model: str | os.PathLike[str] | DGSEModel = "default", **kwargs: Any) -> DGSEEstimator:
    """Factory of ``"dgse-s"``: ``model`` is a checkpoint path, a network or ``"default"``."""
    return _make("dgse-s", model, **kwargs)
