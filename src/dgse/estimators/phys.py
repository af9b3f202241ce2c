r"""``dgse-phys``: the physics-guided estimator, a posterior mixed over flow hypotheses.

The source posterior of the discretized physics (the adjoint evidence of
:func:`dgse.posterior.adjoint.adjoint_log_evidence`: release rate and
Table I noise marginalized) is computed on every *flow hypothesis* the
knowledge allows, and the hypotheses are weighed by how well they explain
both the wind and the gas readings:

``p(s | z, w) = sum_h p(h | z, w) p(s | z, h)``, ``p(h | z, w) ∝ p(w | h) p(z | h)``

with ``p(z | h) = mean_s p(z | s, h)`` (uniform source prior over the free
cells; the evidence's constant does not depend on the flow, so hypotheses
compare directly).  Flow hypotheses per knowledge level
(:mod:`dgse.belief.knowledge`; the settings are :class:`FlowHypotheses`):

* ``openings``: the built-in RANS flow of the layout for each of the
  candidate inlet speeds ``flows.speeds`` (cached per layout and speed): a
  posterior over the speed, not one best fit;
* ``wind``: the given wind field made mass-conserving on the map, with
  k-epsilon on that frozen flow (:mod:`dgse.physics.projection`; the map's
  edges are open where the field says so when the openings are unknown; on a
  map with no open face, a slice of a 3-D flow, the field's divergence is kept
  as air entering and leaving through the slice, the leaving air a gas sink),
  beside the RANS flows of its openings (``flows.given_wind_prior``);
* ``map``: opening hypotheses proposed from the wind readings
  (:func:`dgse.physics.openings.potential_flow_proposals`: the edge-window
  pairs whose potential flow best fits the readings), each solved with the
  built-in RANS at one inlet speed (``flows.map_speed``); the wind likelihood fits
  each flow's scale to the readings (the source posterior hardly depends on
  the speed: concentrations scale as ``q / v_in``).  Proposed again each time
  the readings have doubled.  With few readings the proposals are guesses, so
  at ``map`` the source posterior is mixed with DGSE-S's (:class:`NetworkFusion`).
  A map whose edge has no two free windows (walled) has no proposals: the
  belief is DGSE-S's alone, and its ``info`` says why.

The wind likelihood ``p(w | h)`` treats every wind reading as the flow's
wind plus isotropic Gaussian noise of standard deviation ``sqrt((r |u|)^2 +
sigma_w^2)`` (Table I's speed and direction noise grow with the speed;
``sigma_w`` absorbs small-scale model error), averaged over the relative
levels ``r`` in ``flows.wind_noise_levels``.  The gas evidence is the
equal-weight mixture of two noise models (the proportional noise's weights
from the plug-in concentrations and from each candidate's own,
:data:`MIXED_NOISE_WEIGHTS`): the planner follows the sharper posterior and a
mass stop needs both.

Belief: ``source_probs`` is the mixture; ``wind_mean``/``wind_var`` the
mixture mean and variance of the hypotheses' winds; ``log_conc_mean``/``log_conc_var``
the moment-matched mixture of every hypothesis's posterior-predictive
concentration (the most probable sources' forward fields, as the adjoint
estimator forms it).  Both variances then get a model error
(:func:`field_error_variance`, ``fields.model_error``): the spread between
hypotheses alone rarely covers the true wind (the hypotheses agree where they
are all wrong); that spread stays in ``wind_var_reducible``/``log_conc_var_reducible``,
which the planner uses.  ``info`` lists the hypotheses and their weights.

Cost: the flows once per map (one RANS solve per candidate speed, or one
projection and k-epsilon solve), then per estimate one adjoint row per new
sensor cell and hypothesis, and the evidence (a few ``(m, N)`` products per
hypothesis and noise model; hypotheses whose weight falls below
``fields.min_weight`` are skipped in the predictive).
"""

from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar

import numpy as np

from dgse.belief.belief import Belief, log_moments_from_ppm
from dgse.belief.inputs import check_inputs
from dgse.belief.knowledge import Knowledge, KnowledgeUser, Level
from dgse.errors import ConvergenceError, InputDataError, UnsupportedError
from dgse.estimators.phys_settings import FlowHypotheses, GasEvidence, NetworkFusion, PredictedFields
from dgse.options import options_from
from dgse.physics.constants import DEFAULT_PHYSICS, Physics
from dgse.physics.openings import potential_flow_proposals, propose_openings
from dgse.physics.projection import ProjectedFlow, project_wind, transport_from_wind
from dgse.physics.rans import FlowSettings
from dgse.posterior.adjoint import (
    AdjointResponseModel,
    FlowModel,
    adjoint_log_evidence,
    flow_model,
    sigma_floor,
)
from dgse.posterior.mixture import (
    MIXED_NOISE_WEIGHTS,
    WIND_HOPELESS_NATS,
    FlowHypothesis,
    censor_zeros,
    field_error_variance,
    fitted_wind_scale,
    gas_misfit,
    log_speed_priors,
    logsumexp,
    mix_posteriors,
    predictive_sources,
    relative_wind_misfit,
    same_noise_weights,
    speed_label,
    wind_log_likelihood,
    with_given,
)
from dgse.posterior.predictive import HypothesisPredictive
from dgse.sensing.sensors import Observations
from dgse.threads import map_threads, side_by_side, with_one_blas_thread
from dgse.world.grid import Grid
from dgse.world.layout import Layout

__all__ = [
    "FlowHypotheses",
    "GasEvidence",
    "NetworkFusion",
    "PhysicsGuidedEstimator",
    "PredictedFields",
    "make_dgse_phys",
]


@dataclass(eq=False)
class PhysicsGuidedEstimator(KnowledgeUser):
    """``dgse-phys``: the adjoint posterior mixed over flow hypotheses (module docstring).

    Args:
        flows: the flow hypotheses and the wind likelihood (:class:`FlowHypotheses`).
        evidence: the gas evidence's priors, the zeros' factor and the tempering
            (:class:`GasEvidence`).
        fusion: DGSE-S's share of the source posterior (:class:`NetworkFusion`).  On a map
            whose cells the network cannot take (not a whole multiple of its own) the physics
            stands alone and ``info["learned_note"]`` says why.
        fields: the predicted fields' model error and predictive (:class:`PredictedFields`).
        flow_settings: SIMPLEC controls of the built-in solver.
        physics: physical constants.

    Every field of the settings objects can be set by a dotted key
    (``get_estimator("dgse-phys", **{"fusion.floor": 0.0})``, ``-p fusion.floor=0.0``).
    """

    knowledge_levels: ClassVar[tuple[Level, ...]] = ("map", "openings", "wind")

    flows: FlowHypotheses = FlowHypotheses()
    evidence: GasEvidence = GasEvidence()
    fusion: NetworkFusion = NetworkFusion()
    fields: PredictedFields = PredictedFields()
    flow_settings: FlowSettings | None = None
    physics: Physics = DEFAULT_PHYSICS
    name: str = field(default="dgse-phys", init=False)
    _hypotheses: list[FlowHypothesis] | None = field(default=None, init=False, repr=False)
    _proposed_at: int = field(default=0, init=False, repr=False)
    _proposed_from: tuple[np.ndarray, np.ndarray] | None = field(default=None, init=False, repr=False)
    _speed_layout: Layout | None = field(default=None, init=False, repr=False)
    _family_note: str | None = field(default=None, init=False, repr=False)
    _networks: dict[str, Any] = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self) -> None:
        for key, cls in (
            ("flows", FlowHypotheses),
            ("evidence", GasEvidence),
            ("fusion", NetworkFusion),
            ("fields", PredictedFields),
        ):
            if not isinstance(getattr(self, key), cls):
                raise InputDataError(f"{key} must be a {cls.__name__}, got {getattr(self, key)!r}")

    # -- knowledge and flows --------------------------------------------------------------------
    def _use_knowledge(self, knowledge: Knowledge) -> None:
        if knowledge.level == "openings" and not knowledge.has_openings:
            raise UnsupportedError("dgse-phys at 'openings' needs the inlets and outlets")
        self._hypotheses = None  # built on the first estimate (solves take seconds)
        self._speed_layout = None
        self._family_note = None
        self._proposed_at = 0

    def _map_hypotheses(self, obs: Observations) -> list[FlowHypothesis]:
        """Opening hypotheses from the wind readings (map level).

        Kept while the readings extend those they were proposed from by less than
        as many again; proposed anew otherwise (an estimate depends on its own
        readings only).
        """
        k = self.knowledge
        assert k is not None
        n0 = self._proposed_at
        if (
            self._hypotheses is not None
            and n0 <= len(obs) < 2 * n0
            and self._proposed_from is not None
            and np.array_equal(obs.cells[:n0], self._proposed_from[0])
            and np.array_equal(obs.wind[:n0], self._proposed_from[1])
        ):
            return self._hypotheses  # the same readings and some more: keep the proposals
        self._family_note = None
        try:
            proposals = potential_flow_proposals(
                k.occupancy, k.resolution, obs.cells, obs.wind, top=self.flows.map_proposals
            )
        except InputDataError as exc:  # a map whose edge has no room for openings (walled)
            self._family_note = f"no opening hypotheses: {exc}"
            proposals = []

        def solve(prop: Any) -> FlowModel:
            layout = Layout(
                k.occupancy, prop.inlets, prop.outlets, resolution=k.resolution, name=k.name or "map"
            )
            # the flow's shape is what matters: one speed, the wind fit scales it (see estimate)
            return flow_model(layout, self.flows.map_speed, self.physics, self.flow_settings)

        # the proposals' solves are independent (cold starts): one per thread, as many at once
        # as the machine has cores (the solver's kernels release the GIL)
        flows = map_threads(solve, proposals)
        hyps = [
            FlowHypothesis(prop.label(), fm, 1.0 / len(proposals))
            for prop, fm in zip(proposals, flows, strict=True)
        ]
        self._hypotheses = hyps
        self._proposed_at = len(obs)
        self._proposed_from = (obs.cells.copy(), obs.wind.copy())
        return hyps

    def hypotheses(self, observations: Observations | None = None) -> list[FlowHypothesis]:
        """The flow hypotheses of the current knowledge (solved on first use, then cached).

        At knowledge ``map`` they come from ``observations`` (proposed again each time
        the readings have doubled since).
        """
        k = self.knowledge
        if k is None:
            raise InputDataError(
                "dgse-phys needs knowledge 'openings' or 'wind': call "
                "set_knowledge(Knowledge.from_case(...)) or give --knowledge"
            )
        if k.level == "map":
            if observations is None or len(observations) == 0:
                raise InputDataError("dgse-phys at 'map' proposes openings from wind readings: give readings")
            return self._map_hypotheses(observations)
        if self._hypotheses is None:
            if k.level == "wind":
                proj = self._project_given(k)
                fm = FlowModel(
                    proj.wind, transport_from_wind(proj, self.physics), math.nan, proj.info, self.physics
                )
                given = FlowHypothesis("given wind", fm, 1.0)
                p = self.flows.given_wind_prior
                self._speed_layout = None if p >= 1.0 else self._openings_of(k)
                family: list[FlowHypothesis] = []
                if self._speed_layout is not None:
                    try:
                        family = self._speed_family(self._speed_layout, list(self.flows.speeds))
                    except (ConvergenceError, InputDataError) as exc:  # the hedge is optional
                        self._speed_layout = None
                        self._family_note = f"the RANS flows of the openings left out: {exc}"
                self._hypotheses = with_given(given, p, family) if family else [given]
            else:
                self._speed_layout = k.layout
                self._hypotheses = self._speed_family(k.layout, list(self.flows.speeds))
        return self._hypotheses

    def _project_given(self, k: Knowledge) -> ProjectedFlow:
        """The given wind of knowledge ``k`` made a flow the transport can use (on its openings
        where known; through the slice where the map has no open face)."""
        assert k.wind is not None
        layout = k.layout if k.has_openings else None
        return project_wind(k.occupancy, k.resolution, k.wind, layout, physics=self.physics)

    def _speed_family(self, layout: Layout, speeds: list[float]) -> list[FlowHypothesis]:
        """The built-in RANS flows of ``layout`` at ``speeds``, with the log-uniform prior over
        the speed; in order of speed, with ``flows.warm_start`` each solve starting from the one
        before (scaled)."""
        hyps: list[FlowHypothesis] = []
        for v in sorted(speeds):
            prev = hyps[-1].flow if hyps and self.flows.warm_start else None
            fm = flow_model(layout, v, self.physics, self.flow_settings, warm_start=prev)
            hyps.append(FlowHypothesis(speed_label(v), fm))
        return log_speed_priors(hyps)

    def _openings_of(self, k: Knowledge) -> Layout | None:
        """The openings of the RANS flows at knowledge ``wind``: the knowledge's, or the
        strongest inlet-outlet pair where the given field crosses the map's edge (None, and a
        note, where it crosses it nowhere)."""
        if k.has_openings:
            return k.layout
        assert k.wind is not None
        try:
            props = propose_openings(k.occupancy, k.resolution, k.wind)
            if not props:
                raise InputDataError("no separate inflow and outflow at the map's edge")
            prop = props[0]
            name = k.name or "wind"
            return Layout(k.occupancy, prop.inlets, prop.outlets, resolution=k.resolution, name=name)
        except InputDataError as exc:
            self._family_note = f"the given field alone: no openings found in it ({exc})"
            return None

    def _refine_speed(self, hyps: list[FlowHypothesis], weights: np.ndarray, n_obs: int) -> None:
        """Add one inlet speed between the most probable one and its heavier neighbour.

        The true speed is continuous, the candidates a grid: a plume solved at a speed
        between two candidates differs from both, most near the source, where a search
        measures most.  So once ``flows.refine_readings`` readings weigh the speeds, each
        estimate may bisect (in log speed) the interval between the best speed and its
        heavier neighbour while they are more than ``flows.refine_ratio`` apart, at most
        ``flows.refine_speeds`` times per map (with ``flows.warm_start``, the new flow starts
        from the best one's).  It is weighed from the next estimate on.
        """
        fl = self.flows
        layout = self._speed_layout
        speed = [i for i, h in enumerate(hyps) if math.isfinite(h.flow.inlet_velocity)]
        full = len(speed) >= len(fl.speeds) + fl.refine_speeds
        if layout is None or n_obs < fl.refine_readings or full:
            return
        order = sorted(speed, key=lambda i: hyps[i].flow.inlet_velocity)
        best = max(speed, key=lambda i: weights[i])
        pos = order.index(best)
        sides = [order[j] for j in (pos - 1, pos + 1) if 0 <= j < len(order)]
        if not sides:
            return
        other = max(sides, key=lambda i: weights[i])
        v0, v1 = hyps[best].flow.inlet_velocity, hyps[other].flow.inlet_velocity
        if max(v0, v1) / min(v0, v1) <= fl.refine_ratio:
            return
        v = math.sqrt(v0 * v1)
        start = hyps[best].flow if fl.warm_start else None
        fm = flow_model(layout, v, self.physics, self.flow_settings, warm_start=start)
        family = log_speed_priors([*(hyps[i] for i in speed), FlowHypothesis(speed_label(v), fm)])
        given = [h for h in hyps if not math.isfinite(h.flow.inlet_velocity)]
        self._hypotheses = with_given(given[0], given[0].prior, family) if given else family

    # -- the learned source belief, the tempering ---------------------------------------------
    def _level(self) -> Level:
        if self.knowledge is None:
            self.hypotheses()  # raises the message
        assert self.knowledge is not None
        return self.knowledge.level

    def _learned_weight(self, m: int) -> float:
        """DGSE-S's weight in the source posterior with ``m`` readings (:class:`NetworkFusion`)."""
        if self.knowledge is None:
            return 0.0
        level, fu = self.knowledge.level, self.fusion
        fading = fu.weight[level] * max(0.0, 1.0 - m / fu.readings)
        return float(max(fu.floor[level], fading))

    def _readings_factor(self, m: int) -> float:
        """``max(1, (m / effective_readings) ** (1 - effective_growth))`` at the knowledge level:
        by how much ``m`` readings are tempered for not being independent (the gas evidence's
        temperature)."""
        level = self._level()
        m_eff, growth = self.evidence.effective_readings[level], self.evidence.effective_growth[level]
        return max(1.0, (m / m_eff) ** (1.0 - growth))

    def _counted_readings(self, m: int) -> float:
        """How many independent readings ``m`` readings count as: ``m`` up to
        ``effective_readings``, then ``effective_readings ** (1 - g) * m ** g``."""
        return m / self._readings_factor(m)

    def _learned_belief(
        self, occupancy: np.ndarray, resolution: float, obs: Observations, *, source_only: bool = False
    ) -> Belief:
        """DGSE-S's belief from the same readings (the shipped network, built on first use and
        shared by every estimate).  ``source_only``: only its source posterior is used (the
        mixture's share), which :data:`FUSION_SAMPLES` Monte Carlo samples give as well as the
        paper's 5 x 5 do."""
        samples = FUSION_SAMPLES if source_only else (5, 5)
        key = f"{samples[0]}x{samples[1]}"
        if key not in self._networks:
            self._networks[key] = _shipped_network(*samples)
        return self._networks[key].estimate(occupancy, resolution, obs)

    def _gas_evidence(
        self,
        hyps: list[FlowHypothesis],
        rows: dict[int, np.ndarray],
        z: np.ndarray,
        noise_weights: str,
    ) -> tuple[list[np.ndarray], list[tuple[Any, dict[str, Any]]]]:
        """The positive readings' log evidence per hypothesis with one noise-weight mode, the
        zeros' factor deferred: ``(log evidence, (rows, details))`` per hypothesis.  ``rows``:
        the readings' response rows of the live hypotheses (by index); the others (ruled out by
        the wind) get no gas evidence.  Reads no state that another mode's call, run beside
        it, writes."""

        ev = self.evidence

        def evidence(k: int) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
            A = rows[k]
            logl, det = adjoint_log_evidence(
                A,
                z,
                q_max=ev.q_max,
                kappas=ev.kappas,
                alpha0=ev.alpha0,
                sigma0_fraction=ev.sigma0_fraction,
                censored="deferred",
                noise_weights=noise_weights,  # type: ignore[arg-type]
            )
            return A, logl, det

        got = dict(zip(rows, map_threads(evidence, list(rows)), strict=True))
        log_ev: list[np.ndarray] = []
        details: list[tuple[Any, dict[str, Any]]] = []
        for k, h in enumerate(hyps):
            if k not in got:
                log_ev.append(np.full(h.flow.mesh.n, -np.inf))
                details.append((None, {}))
                continue
            A, logl, det = got[k]
            log_ev.append(logl)
            details.append((A, det))
        return log_ev, details

    def _gas_posterior(
        self,
        log_ev: list[np.ndarray],
        details: list[tuple[Any, dict[str, Any]]],
        log_prior: list[float],
        temp: float,
        memos: dict[int, dict[str, Any]] | None,
    ) -> tuple[np.ndarray, np.ndarray, list[np.ndarray], list[tuple[Any, dict[str, Any]]]]:
        """The source posterior and hypothesis weights from one noise-weight mode's evidence
        (:meth:`_gas_evidence`) and the zeros' factor: ``(post, weights, tempered log evidence
        per hypothesis, (rows, details) per hypothesis)``.  ``memos``: the zeros' factors
        computed for another mode, reused where the noise weights agree (:func:`censor_zeros`)."""
        tilt = self.evidence.censored_tilt[self._level()]
        zeros = censor_zeros(log_ev, log_prior, [d for _, d in details], temp, tilt, memos=memos)
        log_ev = [x / temp for x in zeros]
        post, hw = mix_posteriors(log_ev, log_prior)
        return post, hw, log_ev, details

    def _without_flows(self, occ: np.ndarray, res: float, obs: Observations, t0: float) -> Belief:
        """DGSE-S's belief, where the knowledge allows no flow hypothesis: at ``map``, a map
        whose edge has no two free windows for an inlet and an outlet (a walled edge, as an
        imported GADEN slice has) — the air there crosses the slice at places the map does not
        show, and a closed room without them has no steady plume."""
        note = self._family_note or "no flow hypotheses"
        try:
            net = self._learned_belief(occ, res, obs)
        except InputDataError as exc:
            raise UnsupportedError(
                f"dgse-phys at {self._level()!r}: {note}; and DGSE-S left out: {exc}"
            ) from None
        info = {
            **net.info,
            "method": self.name,
            "knowledge": self._level(),
            "n_observations": len(obs),
            "hypotheses": [],
            "best_hypothesis": None,
            "learned_weight": 1.0,
            "given_wind_note": note,
            "seconds": time.perf_counter() - t0,
        }
        return replace(net, info=info)

    # -- estimate ---------------------------------------------------------------------------------
    @with_one_blas_thread
    def estimate(self, occupancy: np.ndarray, resolution: float, observations: Observations) -> Belief:
        """The mixture posterior and fields given the readings (module docstring).

        Raises:
            InputDataError: no readings, a reading in a wall or off the map, no
                knowledge, or a map other than the knowledge's.
        """
        t0 = time.perf_counter()
        occ, res, obs = check_inputs(occupancy, resolution, observations)
        if self.knowledge is None:
            self.hypotheses()  # raises the message
        assert self.knowledge is not None
        self.knowledge.check_map(occ, res, self.name)
        hyps = self.hypotheses(obs)
        if not hyps:
            return self._without_flows(occ, res, obs, t0)
        t_flow = time.perf_counter() - t0
        free_scale = self.knowledge.level == "map"  # proposals are solved at one speed
        cells, z = obs.cells, obs.gas
        log_prior: list[float] = []
        wind_ll: list[float] = []
        scales: list[float] = []
        misfits: list[float] = []
        temp = self._readings_factor(len(obs))
        for h in hyps:
            u = h.flow.wind[:, cells[:, 0], cells[:, 1]].T
            scale = fitted_wind_scale(u, obs.wind) if free_scale else 1.0
            scales.append(scale)
            misfits.append(relative_wind_misfit(scale * u, obs.wind))
            lw = wind_log_likelihood(
                scale * u, obs.wind, self.flows.wind_noise_levels, self.flows.wind_noise_floor
            )
            wind_ll.append(lw)
            log_prior.append(math.log(h.prior) + lw)
        # flows the wind readings rule out (WIND_HOPELESS_NATS below the best) get no gas evidence
        lp_best = max(log_prior)
        live = [k for k, lp in enumerate(log_prior) if lp >= lp_best - WIND_HOPELESS_NATS]
        modes = MIXED_NOISE_WEIGHTS
        # the live flows' response rows, one flow per thread (each flow keeps its own cache),
        # then the modes' evidence side by side (they share the rows and write nothing the other
        # reads), then their zeros' factors: where the modes' most probable kappa gives every
        # flow the same noise weights (often kappa = 0, weights 1), one mode after the other,
        # the second reusing the factors the first integrated; otherwise side by side
        flows = {id(hyps[k].flow): hyps[k].flow for k in live}  # a flow two hypotheses share: once
        grown = map_threads(lambda f: f.responses(cells, growing=True), flows.values())
        got = dict(zip(flows, grown, strict=True))
        rows = {k: got[id(hyps[k].flow)] for k in live}
        evidence = side_by_side(
            [functools.partial(self._gas_evidence, hyps, rows, z, mode) for mode in modes]
        )
        if same_noise_weights([det for _ev, det in evidence]):
            memos: dict[int, dict[str, Any]] = {}
            runs = [self._gas_posterior(ev, det, log_prior, temp, memos) for ev, det in evidence]
        else:
            runs = side_by_side(
                [
                    functools.partial(self._gas_posterior, ev, det, log_prior, temp, None)
                    for ev, det in evidence
                ]
            )
        # the mixture: an equal-weight average of the modes' posteriors (a mass stop needs both);
        # the predictive fields and the response model come from the first mode's evidence
        post = np.mean([r[0] for r in runs], axis=0)
        hw = np.mean([r[1] for r in runs], axis=0)
        log_ev, details = runs[0][2], runs[0][3]
        self._refine_speed(hyps, hw, len(obs))
        mesh = hyps[0].flow.mesh
        w_learned = self._learned_weight(len(obs))
        learned_note = None
        if w_learned > 0:
            try:
                net = self._learned_belief(occ, res, obs, source_only=True)
            except InputDataError as exc:  # a map the network cannot take (its cell size)
                w_learned, learned_note = 0.0, f"DGSE-S left out: {exc}"
            else:
                post = (1.0 - w_learned) * post + w_learned * mesh.values(net.source_probs)
                post /= post.sum()
        # wind: mixture mean and variance of the hypotheses' winds
        winds = np.stack([s * h.flow.wind for s, h in zip(scales, hyps, strict=True)])  # (H, 2, H, W)
        wind_mean = np.tensordot(hw, winds, axes=1)
        wind_var = np.tensordot(hw, (winds - wind_mean) ** 2, axes=1)
        # concentration: every weighty hypothesis's predictive, mixed and moment matched
        mean = np.zeros(mesh.n)
        second = np.zeros(mesh.n)
        qmax = np.inf if self.evidence.q_max is None else self.evidence.q_max

        def predictive(k: int) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, ...]]:
            """Hypothesis ``k``'s predictive mean and second moment (its flow's own cache), and
            its sources, their weights, rates and fields (the readings' predictive)."""
            logl, det = log_ev[k], details[k][1]
            ph = np.exp(logl - logl.max())
            top, wts = predictive_sources(ph / ph.sum(), self.fields.conc_components)
            qmap = np.clip(det["qhat"], 0.0, qmax)
            fields = hyps[k].flow.forward(mesh.cells[top], qmap[top])
            return wts @ fields, wts @ fields**2, (top, wts, qmap[top], fields)

        weighty = [k for k, w in enumerate(hw) if w >= self.fields.min_weight]
        parts = []
        for k, (m1, m2, part) in zip(weighty, map_threads(predictive, weighty), strict=True):
            mean += hw[k] * m1
            second += hw[k] * m2
            parts.append(part)
        total = float(hw[hw >= self.fields.min_weight].sum())
        mean /= total
        second /= total
        var = np.maximum(second - mean**2, 0.0)
        mu, s2 = log_moments_from_ppm(mesh.field(np.maximum(mean, 0.0)), mesh.field(var))
        wind_err, conc_err = field_error_variance(
            wind_mean, mu, self.fields.model_error[self.knowledge.level]
        )
        best_h = int(np.argmax(hw))
        A_b, det_b = details[best_h]
        best = int(np.argmax(post))
        a0 = self.evidence.alpha0
        sig = sigma_floor(A_b, z, det_b["r"], best, a0, a0 * det_b["s0"] ** 2)
        qmap_b = np.clip(det_b["qhat"], 0.0, qmax)
        model = AdjointResponseModel(
            hyps[best_h].flow, qmap_b, sig, float(det_b["kappa"]), float(det_b.get("cbar", 1.0))
        )
        misfit = gas_misfit(A_b[:, best] * qmap_b[best], z, model)
        src, src_w, rates, fields_k = zip(*parts, strict=True)
        reading = HypothesisPredictive.from_posteriors(
            [hyps[k].flow for k in weighty], hw[weighty], src, src_w, rates, model, fields_k
        )
        info: dict[str, Any] = {
            "method": self.name,
            "knowledge": self.knowledge.level,
            "n_observations": len(obs),
            "hypotheses": [
                _hypothesis_info(h, float(w), lw, mis, le, mesh, res)
                for h, w, lw, mis, le in zip(hyps, hw, wind_ll, misfits, log_ev, strict=True)
            ],
            "best_hypothesis": hyps[best_h].label,
            "wind_misfit": min(misfits),
            "learned_weight": w_learned,
            "learned_note": learned_note,
            "given_wind_note": self._family_note,
            "temperature": temp,
            "gas_misfit": misfit,
            "noise_floor_ppm": sig,
            "response_model": model,
            "timings": {"preprocessing": t_flow},
            "conc_space": "ppm",
        }
        info["seconds"] = time.perf_counter() - t0
        return Belief(
            occupancy=occ,
            resolution=res,
            source_probs=mesh.field(post),
            wind_mean=wind_mean,
            wind_var=wind_var + wind_err,
            log_conc_mean=mu,
            log_conc_var=s2 + conc_err,
            info=info,
            wind_var_reducible=wind_var,
            log_conc_var_reducible=s2,
            predictive=reading,
        )


def _hypothesis_info(
    h: FlowHypothesis, weight: float, wind_ll: float, misfit: float, log_ev: np.ndarray, mesh: Any, res: float
) -> dict[str, Any]:
    """One flow hypothesis in a belief's info: its weight and what made it (the wind readings'
    log likelihood, their relative misfit, the tempered gas log evidence averaged over the
    candidates, first noise-weight mode) and where its own posterior peaks; the gas terms are
    None for a hypothesis the wind ruled out."""
    live = bool(np.isfinite(log_ev).any())
    mode = None
    if live:
        i, j = mesh.cells[int(np.argmax(log_ev))]
        mode = list(Grid(mesh.shape, res).center_of(int(i), int(j)))
    return {
        "label": h.label,
        "weight": weight,
        "inlet_velocity": h.flow.inlet_velocity,
        "wind_log_likelihood": wind_ll,
        "wind_misfit": misfit,
        "gas_log_evidence": logsumexp(log_ev) - math.log(log_ev.size) if live else None,
        "source_mode_xy": mode,
    }


#: DGSE-S's wind and concentration samples ``(K, T)`` where dgse-phys mixes in only its source
#: posterior: on validation its source error and cross-entropy with one sample of each are
#: those of the paper's 5 x 5 (``docs/decisions.md``), at a fifth of the time.
FUSION_SAMPLES = (1, 1)


@functools.lru_cache(maxsize=2)
def _shipped_network(K: int = 5, T: int = 5) -> Any:
    """DGSE-S with the shipped weights and ``K`` x ``T`` samples, as
    :meth:`PhysicsGuidedEstimator._learned_belief` runs it: loaded once per process and shared
    by every estimator (its estimates depend only on their inputs: each draws its samples from
    a generator seeded afresh)."""
    from dgse.estimators.registry import get_estimator

    return get_estimator("dgse-s", model="default", seed=0, dtype="auto", channels_last=True, K=K, T=T)


@options_from(PhysicsGuidedEstimator)
def make_dgse_phys(**kwargs: Any) -> PhysicsGuidedEstimator:
    """Registry factory ``dgse-phys``; needs knowledge ``openings`` or ``wind``."""
    return PhysicsGuidedEstimator(**kwargs)
