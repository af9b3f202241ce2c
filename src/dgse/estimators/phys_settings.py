"""The settings of ``dgse-phys`` (:class:`~dgse.estimators.phys.PhysicsGuidedEstimator`).

Four frozen settings objects, one per part of the estimator; each field's default is the
value every measurement of ``docs/dgse-phys.md`` was made with, and ``docs/decisions.md``
gives its evidence.  A user sets one field with a dotted key (``-p fusion.floor=0.0``,
``get_estimator("dgse-phys", **{"flows.speeds": [0.5, 1.0]})``; :mod:`dgse.options`), or
passes an object (``PhysicsGuidedEstimator(fusion=NetworkFusion(floor=0.0))``).  A
:class:`~dgse.belief.knowledge.PerLevel` field holds one value per knowledge level; a plain
value given there holds at every level.

* :class:`FlowHypotheses`: which flows explain the readings, and how the wind readings
  weigh them;
* :class:`GasEvidence`: the priors of the gas evidence, the zeros' factor and the
  tempering of many readings;
* :class:`NetworkFusion`: how much of DGSE-S's source belief is mixed in;
* :class:`PredictedFields`: the predicted wind and concentration fields and their model error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from dgse.belief.knowledge import PerLevel, per_level
from dgse.errors import InputDataError
from dgse.options import Settings, check_number, check_positive_numbers, check_switch, check_whole
from dgse.posterior.adjoint import DEFAULT_KAPPAS

__all__ = ["FlowHypotheses", "GasEvidence", "NetworkFusion", "PredictedFields"]


@dataclass(frozen=True)
class FlowHypotheses(Settings):
    """The flow hypotheses and the wind readings' likelihood of each.

    Attributes:
        speeds: candidate inlet speeds at knowledge ``openings`` (and of the RANS flows beside
            a given field at ``wind``), m/s; log-spaced over the training range.
        refine_speeds: at most this many inlet speeds added between the candidates per map
            (0: the candidates only); see ``PhysicsGuidedEstimator._refine_speed``.
        refine_readings: the readings needed before the speeds are refined.
        refine_ratio: neighbouring speeds closer than this ratio are not bisected (> 1).
        warm_start: each speed's RANS solve starts from the flow of the speed below (about
            2.5 times faster); False: every solve from the coarse grid, as ``dgse solve``,
            which can leave other turbulence in quiet rooms.
        map_proposals: opening hypotheses at knowledge ``map``: the best inlet/outlet window
            pairs of :func:`~dgse.physics.openings.potential_flow_proposals` (>= 1).
        map_speed: the inlet speed each ``map`` proposal is solved at, m/s (the wind fit
            scales the flow; the source posterior hardly depends on the speed).
        given_wind_prior: at knowledge ``wind``, the prior weight of the given field; the
            RANS flows of its openings at ``speeds`` share the rest (1: the field alone).
        wind_noise_levels: relative wind-noise levels ``r`` averaged in the wind likelihood
            (noise ``sqrt((r |u|)^2 + wind_noise_floor^2)``; Table I: up to 0.5 in speed).
        wind_noise_floor: the wind noise's absolute floor (and small-scale model error), m/s.
    """

    speeds: tuple[float, ...] = (0.35, 0.6, 1.0, 1.7, 2.9, 5.0)
    refine_speeds: int = 4
    refine_readings: int = 10
    refine_ratio: float = 1.08
    warm_start: bool = True
    map_proposals: int = 5
    map_speed: float = 1.0
    given_wind_prior: float = 0.5
    wind_noise_levels: tuple[float, ...] = (0.1, 0.25, 0.5)
    wind_noise_floor: float = 0.05

    def __post_init__(self) -> None:
        self._set("speeds", check_positive_numbers("flows.speeds", self.speeds, " of m/s"))
        self._set("refine_speeds", check_whole("flows.refine_speeds", self.refine_speeds, 0))
        self._set("refine_readings", check_whole("flows.refine_readings", self.refine_readings, 0))
        if not (float(self.refine_ratio) > 1.0 and math.isfinite(self.refine_ratio)):
            raise InputDataError(f"flows.refine_ratio must be a number > 1, got {self.refine_ratio!r}")
        self._set("warm_start", check_switch("flows.warm_start", self.warm_start))
        self._set("map_proposals", check_whole("flows.map_proposals", self.map_proposals, 1))
        self._set("map_speed", check_positive_numbers("flows.map_speed", (self.map_speed,), " of m/s")[0])
        self._set(
            "given_wind_prior",
            check_number("flows.given_wind_prior", self.given_wind_prior, low=0.0, high=1.0, open_low=True),
        )
        self._set(
            "wind_noise_levels", check_positive_numbers("flows.wind_noise_levels", self.wind_noise_levels)
        )
        self._set(
            "wind_noise_floor",
            check_positive_numbers("flows.wind_noise_floor", (self.wind_noise_floor,), " of m/s")[0],
        )


@dataclass(frozen=True)
class GasEvidence(Settings):
    """The gas evidence (:func:`~dgse.posterior.adjoint.adjoint_log_evidence`) and its tempering.

    Attributes:
        q_max: the release-rate prior ``U[0, q_max]``, g/s (the top of the training range;
            None: flat on ``q >= 0``).
        kappas: the grid of the proportional noise's weight (averaged, equal prior weights).
        alpha0: the shape of the noise precision's Gamma prior (1: two pseudo-readings).
        sigma0_fraction: the prior noise scale ``s0 = sigma0_fraction * mean(z)`` (Table I's
            mean floor with sensors spread over the map).
        censored_tilt: where the zeros pull the release rate far below the positive readings'
            estimate, the zeros' factor lets the rate's nodes follow them
            (:func:`~dgse.posterior.adjoint.censored_correction`); per knowledge level.
        effective_readings, effective_growth: the gas evidence is divided by ``T = max(1,
            (m / effective_readings) ** (1 - effective_growth))`` for ``m`` readings (a power
            posterior: readings of one plume are not independent once the model's own error
            dominates the noise); ``m`` readings then count as ``effective_readings`` (growth
            0) or as ``sqrt(effective_readings m)`` (growth 0.5) once past it.  Per knowledge
            level; ``effective_readings=inf``: never tempered; growth in ``[0, 1)``.
    """

    q_max: float | None = 5.0
    kappas: tuple[float, ...] = DEFAULT_KAPPAS
    alpha0: float = 1.0
    sigma0_fraction: float = 0.25
    censored_tilt: PerLevel[bool] = PerLevel(map=False, openings=True, wind=True)
    effective_readings: PerLevel[float] = PerLevel(map=18.0, openings=100.0, wind=100.0)
    effective_growth: PerLevel[float] = PerLevel(map=0.5, openings=0.0, wind=0.0)

    def __post_init__(self) -> None:
        if self.q_max is not None:
            self._set(
                "q_max", check_positive_numbers("evidence.q_max", (self.q_max,), " of g/s (or None)")[0]
            )
        kappas = tuple(float(k) for k in self.kappas)
        if not kappas or any(not (k >= 0 and math.isfinite(k)) for k in kappas):
            raise InputDataError(f"evidence.kappas must be finite numbers >= 0, got {self.kappas!r}")
        self._set("kappas", kappas)
        self._set("alpha0", check_number("evidence.alpha0", self.alpha0, low=0.0, open_low=True))
        self._set(
            "sigma0_fraction",
            check_number("evidence.sigma0_fraction", self.sigma0_fraction, low=0.0, open_low=True),
        )
        self._set(
            "censored_tilt",
            per_level(self.censored_tilt).apply(lambda v: check_switch("evidence.censored_tilt", v)),
        )
        readings = per_level(self.effective_readings).apply(
            lambda v: check_number("evidence.effective_readings", v, low=0.0, open_low=True)
        )
        self._set("effective_readings", readings)
        growth = per_level(self.effective_growth)
        for _, g in growth.items():
            if not (0.0 <= float(g) < 1.0):
                raise InputDataError(f"evidence.effective_growth must lie in [0, 1), got {g!r}")
        self._set("effective_growth", growth.apply(float))


@dataclass(frozen=True)
class NetworkFusion(Settings):
    """DGSE-S's share of the source posterior: ``max(floor, weight * max(0, 1 - m / readings))``
    for ``m`` readings (the shipped network, where the readings are few, and a floor that caps
    how sure of a wrong spot the physics can make the mixture).

    Attributes:
        weight: the network's weight with no readings, per knowledge level (0: none).
        readings: the readings at which that weight has faded to 0.
        floor: the least weight, per knowledge level (0: the physics alone from ``readings``
            on).  A floor costs a network estimate with every estimate.
    """

    weight: PerLevel[float] = PerLevel(map=0.9, openings=0.0, wind=0.0)
    readings: float = 50.0
    floor: PerLevel[float] = PerLevel(map=0.05, openings=0.02, wind=0.02)

    def __post_init__(self) -> None:
        self._set(
            "weight",
            per_level(self.weight).apply(lambda v: check_number("fusion.weight", v, low=0.0, high=1.0)),
        )
        self._set("readings", check_positive_numbers("fusion.readings", (self.readings,))[0])
        self._set(
            "floor", per_level(self.floor).apply(lambda v: check_number("fusion.floor", v, low=0.0, high=1.0))
        )


@dataclass(frozen=True)
class PredictedFields(Settings):
    """The belief's wind and concentration fields.

    Attributes:
        model_error: ``(a, b, c, d)`` of :func:`~dgse.posterior.mixture.field_error_variance`
            per knowledge level: a wind component errs by ``sqrt((a |u|)^2 + b^2)`` m/s,
            ``log(1 + c)`` by ``sqrt((c L)^2 + d^2)``.  It is added to the spread between the
            hypotheses, which stays apart in the belief's ``*_reducible`` fields (what the
            planner uses); zeros: none.  At ``wind`` it assumes the given field is close to
            the truth.
        conc_components: sources per hypothesis in the concentration's predictive (drawn from
            its source posterior by :func:`~dgse.posterior.mixture.predictive_sources`).
        min_weight: hypotheses below this posterior weight are left out of the predictive.
    """

    model_error: PerLevel[tuple[float, float, float, float]] = PerLevel(
        map=(0.15, 0.3, 0.1, 1.0), openings=(0.1, 0.005, 0.0, 0.5), wind=(0.03, 0.005, 0.0, 0.5)
    )
    conc_components: int = 32
    min_weight: float = 1e-4

    def __post_init__(self) -> None:
        def four(values: tuple[float, ...]) -> tuple[float, float, float, float]:
            try:
                fe = tuple(float(v) for v in values)
            except (TypeError, ValueError):
                fe = ()
            if len(fe) != 4 or any(not (v >= 0 and math.isfinite(v)) for v in fe):
                raise InputDataError(f"fields.model_error must be four numbers >= 0, got {values!r}")
            return fe  # type: ignore[return-value]

        self._set("model_error", per_level(self.model_error).apply(four))
        self._set("conc_components", check_whole("fields.conc_components", self.conc_components, 1))
        self._set("min_weight", check_number("fields.min_weight", self.min_weight, low=0.0, high=1.0))
