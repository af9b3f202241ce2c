"""The adjoint Bayesian baseline: the exact posterior of the discretized physics on one flow.

``adjoint`` solves the built-in RANS flow of the known openings at candidate
inlet speeds (or, ``adjoint-oracle``, uses the case's wind field) and returns
the posterior of :mod:`dgse.posterior.adjoint` (the model, its noise and its
cost are described there).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from dgse.belief.belief import Belief, log_moments_from_ppm
from dgse.belief.inputs import check_inputs
from dgse.belief.knowledge import Knowledge, KnowledgeUser, Level
from dgse.errors import InputDataError, UnsupportedError
from dgse.options import options_from
from dgse.physics.constants import DEFAULT_PHYSICS, Physics
from dgse.physics.engines import FlowField
from dgse.physics.rans import FlowSettings
from dgse.physics.transport import TransportSolver
from dgse.posterior.adjoint import (
    DEFAULT_KAPPAS,
    AdjointResponseModel,
    FlowModel,
    adjoint_log_evidence,
    check_noise_weights,
    flow_model,
    sigma_floor,
)
from dgse.sensing.sensors import Observations
from dgse.threads import with_one_blas_thread
from dgse.world.layout import Layout

__all__ = ["AdjointEstimator", "make_adjoint", "make_adjoint_oracle"]


@dataclass(eq=False)
class AdjointEstimator(KnowledgeUser):
    """Exact Bayesian posterior of the discretized physics (see the module docstring).

    Knowledge (:meth:`set_knowledge`): the estimated variant works at
    ``openings`` and ``wind`` and needs the openings; the oracle works at
    ``wind`` only and needs the openings and the inlet speed (it re-solves
    the flow the user's CFD gave), unless it was built with a precomputed
    ``transport``.

    Args:
        wind: ``"oracle"`` (the true flow) or ``"estimated"`` (inlet speed
            fitted to the wind readings).
        transport: a precomputed transport operator (oracle; ``flow`` gives its wind).
        flow: the :class:`FlowField` (or a ``(2, H, W)`` wind) of ``transport``.
        q_max: release-rate prior ``U[0, q_max]`` g/s (None: flat on ``q >= 0``).
        kappas: proportional-noise grid (``(0,)``: homoscedastic).
        alpha0, sigma0_fraction: the noise-precision prior.
        noise_weights: the proportional noise's concentrations, ``"plug-in"`` or each
            candidate's own (``"candidate"``; :func:`adjoint_log_evidence`).
        censored: read zero readings as censored (:func:`censored_correction`); False: as exact zeros.
        candidate_speeds: inlet speeds solved for the wind fit (estimated variant), m/s.
        refine_speed: solve once more at the fitted speed (else use the best candidate).
        speed_step: relative log-grid step the fitted speed is snapped to.
        conc_components: most probable source cells mixed into the concentration estimate.
        flow_settings: SIMPLEC controls of the built-in solver.
        physics: physical constants.
    """

    wind: Literal["oracle", "estimated"] = "estimated"
    inlet_velocity: float | None = None
    transport: TransportSolver | None = None
    flow: FlowField | np.ndarray | None = None
    q_max: float | None = 5.0
    kappas: Sequence[float] = DEFAULT_KAPPAS
    alpha0: float = 1.0
    sigma0_fraction: float = 0.25
    noise_weights: Literal["plug-in", "candidate"] = "plug-in"
    censored: bool = True
    candidate_speeds: Sequence[float] = (0.5, 1.0, 2.0, 3.5, 5.0)
    refine_speed: bool = True
    speed_step: float = 0.1
    conc_components: int = 32
    flow_settings: FlowSettings | None = None
    physics: Physics = DEFAULT_PHYSICS
    _fixed: FlowModel | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        if self.wind not in ("oracle", "estimated"):
            raise InputDataError(f"wind must be 'oracle' or 'estimated', got {self.wind!r}")
        check_noise_weights(self.noise_weights)
        if self.q_max is not None:
            q = float(self.q_max)
            if not (q > 0 and math.isfinite(q)):
                raise InputDataError(f"q_max must be a positive number of g/s or None, got {self.q_max}")
            self.q_max = q
        speeds = [float(v) for v in self.candidate_speeds]
        if not speeds or any(not (v > 0 and math.isfinite(v)) for v in speeds):
            raise InputDataError(f"candidate_speeds must be positive, got {self.candidate_speeds}")
        self.candidate_speeds = tuple(speeds)
        if not (self.speed_step > 0):
            raise InputDataError(f"speed_step must be > 0, got {self.speed_step}")
        if self.transport is not None:
            if self.wind != "oracle":
                raise InputDataError("a precomputed transport operator is only for wind='oracle'")
            wind = self.flow.wind if isinstance(self.flow, FlowField) else self.flow
            if wind is None:
                wind = np.zeros((2, *self.transport.mesh.shape))
            wind = np.asarray(wind, dtype=np.float64)
            if wind.shape != (2, *self.transport.mesh.shape):
                raise InputDataError(f"flow wind {wind.shape} does not match the transport mesh")
            v = float("nan") if self.inlet_velocity is None else float(self.inlet_velocity)
            self._fixed = FlowModel(wind, self.transport, v, {"precomputed": True}, self.transport.physics)

    @property
    def name(self) -> str:
        """Registry name: ``adjoint-oracle`` or ``adjoint``."""
        return "adjoint-oracle" if self.wind == "oracle" else "adjoint"

    @property
    def knowledge_levels(self) -> tuple[Level, ...]:  # type: ignore[override]
        """``("openings", "wind")``; the oracle ``("wind",)``."""
        return ("wind",) if self.wind == "oracle" else ("openings", "wind")

    # -- what it is told ---------------------------------------------------------------------
    def _use_knowledge(self, knowledge: Knowledge) -> None:
        if self._fixed is not None:
            return  # the oracle with a precomputed flow needs nothing more
        if not knowledge.has_openings:
            raise UnsupportedError(
                f"{self.name} needs the openings (inlets and outlets), which knowledge "
                f"{knowledge.level!r} of {knowledge.name or 'this map'!r} does not include"
            )
        if self.wind == "oracle" and knowledge.inlet_velocity is None:
            raise UnsupportedError(f"{self.name} needs the inlet speed of the flow it is told")

    def _scenario(self, occ: np.ndarray, res: float) -> tuple[Layout, float]:
        k = self.knowledge
        if k is None:
            need = "'wind' (openings and inlet speed)" if self.wind == "oracle" else "'openings'"
            raise InputDataError(
                f"{self.name} needs knowledge {need}: call set_knowledge(Knowledge.from_case(case, ...)) "
                "or give --knowledge"
            )
        k.check_map(occ, res, self.name)
        v = k.inlet_velocity if self.wind == "oracle" and k.inlet_velocity is not None else float("nan")
        return k.layout, float(v)

    # -- flows ---------------------------------------------------------------------------
    def _oracle_flow(self, occ: np.ndarray, res: float) -> tuple[FlowModel, dict[str, Any]]:
        if self._fixed is not None:
            if self._fixed.free.shape != occ.shape or not np.array_equal(self._fixed.free, occ == 0):
                raise InputDataError("the precomputed transport operator is for another map")
            return self._fixed, {"inlet_velocity": self._fixed.inlet_velocity, "flow": "precomputed"}
        layout, v = self._scenario(occ, res)
        fm = flow_model(layout, v, self.physics, self.flow_settings)
        return fm, {"inlet_velocity": v, "flow": "true scenario, built-in solver", **_flow_info(fm)}

    def _snap(self, v: float) -> float:
        step = math.log1p(self.speed_step)
        return float(f"{math.exp(round(math.log(v) / step) * step):.4g}")

    def _estimated_flow(
        self, occ: np.ndarray, res: float, obs: Observations
    ) -> tuple[FlowModel, dict[str, Any]]:
        layout, _ = self._scenario(occ, res)
        c = obs.cells
        wobs = obs.wind
        fits: list[dict[str, Any]] = []
        resid = np.empty(len(self.candidate_speeds))
        scale = np.empty(len(self.candidate_speeds))
        for n, v in enumerate(self.candidate_speeds):
            fm = flow_model(layout, v, self.physics, self.flow_settings)
            u = fm.wind[:, c[:, 0], c[:, 1]].T  # (m, 2)
            uu = float((u * u).sum())
            scale[n] = max(float((u * wobs).sum()) / uu, 0.0) if uu > 0 else 0.0
            resid[n] = float(((wobs - scale[n] * u) ** 2).sum())
            fits.append(
                {
                    "speed": v,
                    "scale": float(scale[n]),
                    "residual": float(resid[n]),
                    "converged": fm.info["converged"],
                }
            )
        k = int(np.argmin(resid))
        v_fit = float(scale[k] * self.candidate_speeds[k])
        lo, hi = min(self.candidate_speeds) / 4.0, max(self.candidate_speeds) * 2.0
        info: dict[str, Any] = {"speed_fits": fits, "speed_fitted": v_fit}
        v_use = (
            self._snap(min(max(v_fit, lo), hi))
            if self.refine_speed and v_fit > 0
            else self.candidate_speeds[k]
        )
        fm = flow_model(layout, v_use, self.physics, self.flow_settings)
        info.update(inlet_velocity=v_use, flow="fitted to the wind readings", **_flow_info(fm))
        return fm, info

    # -- estimate ------------------------------------------------------------------------
    @with_one_blas_thread
    def estimate(self, occupancy: np.ndarray, resolution: float, observations: Observations) -> Belief:
        """The posterior over source cells given the readings (see the module docstring).

        Raises:
            InputDataError: no readings, a reading in a wall or off the map, or a
                map the estimator has no scenario (layout) for.
        """
        t0 = time.perf_counter()
        occ, res, obs = check_inputs(occupancy, resolution, observations)
        if self.wind == "oracle":
            fm, finfo = self._oracle_flow(occ, res)
        else:
            fm, finfo = self._estimated_flow(occ, res, obs)
        if fm.free.shape != occ.shape or not np.array_equal(fm.free, occ == 0):
            raise InputDataError(f"{self.name}: the scenario's map differs from the map passed to estimate()")
        t_flow = time.perf_counter() - t0
        A = fm.responses(obs.cells, growing=True)
        z = obs.gas
        logl, det = adjoint_log_evidence(
            A,
            z,
            q_max=self.q_max,
            kappas=self.kappas,
            alpha0=self.alpha0,
            sigma0_fraction=self.sigma0_fraction,
            censored=self.censored,
            noise_weights=self.noise_weights,
        )
        post = np.exp(logl - logl.max())
        post /= post.sum()
        mesh = fm.mesh
        probs = mesh.field(post)
        qmax = np.inf if self.q_max is None else self.q_max
        qmap = np.clip(det["qhat"], 0.0, qmax)
        best = int(np.argmax(post))
        # concentration: mixture of the most probable sources' forward fields
        order = np.argsort(post)[::-1]
        k = int(np.searchsorted(np.cumsum(post[order]), 0.99)) + 1
        top = order[: max(1, min(k, int(self.conc_components)))]
        wts = post[top] / post[top].sum()
        fields = fm.forward(mesh.cells[top], qmap[top])
        mean = wts @ fields
        var = np.maximum(wts @ fields**2 - mean**2, 0.0)
        mu, s2 = log_moments_from_ppm(mesh.field(np.maximum(mean, 0.0)), mesh.field(var))
        sig = sigma_floor(A, z, det["r"], best, self.alpha0, self.alpha0 * det["s0"] ** 2)
        model = AdjointResponseModel(fm, qmap, sig, float(det["kappa"]), float(det.get("cbar", 1.0)))
        bi, bj = (int(v) for v in mesh.cells[best])
        info: dict[str, Any] = {
            "method": self.name,
            "n_observations": len(obs),
            "wind_model": self.wind,
            "knowledge": None if self.knowledge is None else self.knowledge.level,
            **finfo,
            "q_max_gps": self.q_max,
            "map_cell": [bi, bj],
            "release_rate_at_map_gps": float(qmap[best]),
            "kappa": float(det["kappa"]),
            "kappa_weights": [float(x) for x in det["kappa_weights"]],
            "kappas": [float(x) for x in self.kappas],
            "noise_floor_ppm": sig,
            "conc_components": len(top),
            "response_model": model,
            "timings": {"preprocessing": t_flow},
            "conc_space": "ppm",  # ppm moments of a mixture, stored as lognormal moments
        }
        info["seconds"] = time.perf_counter() - t0
        return Belief(
            occupancy=occ,
            resolution=res,
            source_probs=probs,
            wind_mean=fm.wind,
            log_conc_mean=mu,
            log_conc_var=s2,
            info=info,
        )


def _flow_info(fm: FlowModel) -> dict[str, Any]:
    return {"flow_converged": fm.info.get("converged"), "flow_solve_seconds": fm.info.get("seconds")}


@options_from(AdjointEstimator, drop=("wind", "transport", "flow", "inlet_velocity"))
def make_adjoint(**kwargs: Any) -> AdjointEstimator:
    """Registry factory ``adjoint``: wind fitted to the readings; needs knowledge ``openings``."""
    return AdjointEstimator(wind="estimated", **kwargs)


@options_from(AdjointEstimator, drop=("wind",))
def make_adjoint_oracle(**kwargs: Any) -> AdjointEstimator:
    """Registry factory ``adjoint-oracle``: the true flow; needs knowledge ``wind`` (or ``transport=``
    (+ ``flow=``, ``inlet_velocity=``))."""
    return AdjointEstimator(wind="oracle", **kwargs)
