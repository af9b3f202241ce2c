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
(:mod:`dgse.belief.knowledge`):

* ``openings``: the built-in RANS flow of the layout for each of the
  candidate inlet speeds ``speeds`` (cached per layout and speed): a
  posterior over the speed, not one best fit;
* ``wind``: the given wind field made mass-conserving on the map, with
  k-epsilon on that frozen flow (:mod:`dgse.physics.projection`; the map's
  edges are open where the field says so when the openings are unknown);
* ``map``: opening hypotheses proposed from the wind readings
  (:func:`dgse.physics.openings.potential_flow_proposals`: the edge-window
  pairs whose potential flow best fits the readings), each solved with the
  built-in RANS at one inlet speed (``MAP_SPEED``); the wind likelihood fits
  each flow's scale to the readings (the source posterior hardly depends on
  the speed: concentrations scale as ``q / v_in``).  Proposed again each time
  the readings have doubled.  With few readings the proposals are guesses, so
  at ``map`` the source posterior is mixed with DGSE-S's, weight ``0.9 (1 -
  m / 50)`` (none from 50 readings on).

The wind likelihood ``p(w | h)`` treats every wind reading as the flow's
wind plus isotropic Gaussian noise of standard deviation ``sqrt((r |u|)^2 +
sigma_w^2)`` (Table I's speed and direction noise grow with the speed;
``sigma_w`` absorbs small-scale model error), averaged over the relative
levels ``r`` in ``wind_noise_levels``.

Belief: ``source_probs`` is the mixture; ``wind_mean``/``wind_var`` the
mixture mean and variance of the hypotheses' winds; ``log_conc_mean``/``log_conc_var``
the moment-matched mixture of every hypothesis's posterior-predictive
concentration (the most probable sources' forward fields, as the adjoint
estimator forms it).  Both variances then get a model error
(:func:`field_error_variance`, per level :data:`FIELD_ERROR`): the spread between
hypotheses alone covered the true wind in 1-19 % of the cells at 1 sigma (the
hypotheses agree where they are all wrong); that spread stays in
``wind_var_reducible``/``log_conc_var_reducible``, which the planner uses.
``info`` lists the hypotheses and their weights.

Cost: the flows once per map (one RANS solve per candidate speed, or one
projection and k-epsilon solve), then per estimate one adjoint row per new
sensor cell and hypothesis, and the evidence (a few ``(m, N)`` products per
hypothesis; hypotheses whose weight falls below ``min_weight`` are skipped
in the predictive).
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, Literal

import numpy as np

from dgse.belief.belief import Belief, log_moments_from_ppm
from dgse.belief.inputs import check_inputs
from dgse.belief.knowledge import Knowledge, KnowledgeUser, Level
from dgse.errors import ConvergenceError, InputDataError, UnsupportedError
from dgse.options import options_from
from dgse.physics.constants import DEFAULT_PHYSICS, Physics
from dgse.physics.openings import (
    merge_proposals,
    potential_flow_proposals,
    propose_openings,
    wind_field_proposals,
)
from dgse.physics.projection import project_wind, transport_from_wind
from dgse.physics.rans import FlowSettings
from dgse.posterior.adjoint import (
    CENSORED_RANKING,
    CENSORED_RANKINGS,
    DEFAULT_KAPPAS,
    NOISE_WEIGHTS,
    AdjointResponseModel,
    FlowModel,
    adjoint_log_evidence,
    check_noise_floor_mode,
    check_noise_weights,
    flow_model,
    prior_noise_floor,
    sigma_floor,
)
from dgse.posterior.mixture import (
    GIVEN_WIND_PRIOR,
    MIXED_NOISE_WEIGHTS,
    WIND_HOPELESS_NATS,
    FlowHypothesis,
    censor_zeros,
    field_error_variance,
    fitted_wind_scale,
    flattened,
    gas_misfit,
    log_speed_priors,
    logsumexp,
    mix_posteriors,
    predictive_sources,
    profile_wind_log_likelihood,
    relative_wind_misfit,
    same_noise_weights,
    speed_label,
    wind_log_likelihood,
    with_given,
)
from dgse.sensing.sensors import Observations
from dgse.threads import map_threads, side_by_side, with_one_blas_thread
from dgse.world.grid import Grid
from dgse.world.layout import Layout

__all__ = [
    "CENSORED_TILT",
    "DEFAULT_SPEEDS",
    "FIELD_ERROR",
    "LEARNED_FLOOR",
    "MISFIT_TEMPERATURE",
    "MISFIT_THRESHOLD",
    "PhysicsGuidedEstimator",
    "make_dgse_phys",
]

#: Candidate inlet speeds at knowledge ``openings``, m/s (log-spaced over the training range).
DEFAULT_SPEEDS = (0.35, 0.6, 1.0, 1.7, 2.9, 5.0)
#: Readings beyond which the gas evidence is tempered (``T = m / 100``): chosen on generated
#: validation scenarios, ``python benchmarks/tune_phys_temperature.py``.
DEFAULT_EFFECTIVE_READINGS = 100.0
#: The same at knowledge ``map``, ``(effective_readings, effective_growth)``: there the gas
#: evidence is tempered by ``T = max(1, sqrt(m / 18))``, so that ``m`` readings count as
#: ``sqrt(18 m)`` (30 at 50 readings, 52 at 150, 73 at 300).  Until 2026-11-28 g it was
#: ``T = m / 30`` (``benchmarks/tune_phys_map.py``, chosen when the posterior at ``map`` was
#: sure of wrong spots: CE 9.8 nats at 150 readings); with the changes since, that had become
#: too unsure at 150 and 300 readings (the truth's mean credible level 0.38 and 0.25).  Chosen
#: on validation 900-923 (``python benchmarks/tune_phys_calibration.py --seeds 900-923 --counts
#: 150 300 --trials 2 --variants steady --knowledge map -E effective_readings=E [-E
#: effective_growth=0.5]``, and ``--counts 50 150 --variants filament``, ``--counts 50
#: --variants steady``; ``benchmarks/results/phys_map_tempering_validation/``; 48 estimates a
#: cell, chance calibration error 0.043).  Mean SL error (m) / calibration error / CE (nats),
#: steady readings, at 150 and at 300:
#:
#: * ``m / 30`` (``benchmarks/results/phys_tilt_map_validation/notilt/``): 1.06 / 0.11 / 6.33
#:   and 0.90 / 0.23 / 5.64;
#: * ``m / 60``: 1.00 / 0.08 / 6.33 and 0.72 / 0.13 / 5.54;
#: * ``m / 100``: 0.96 / 0.11 / 6.37 and 0.65 / 0.11 / 5.62;
#: * ``m / 200``: 0.93 / 0.15 / 6.44 and 0.61 / 0.11 / 5.85;
#: * ``sqrt(m / 18)``: 1.01 / 0.07 / 6.32 and 0.68 / 0.13 / 5.55.
#:
#: Any ``m / E`` with ``E >= 50`` leaves 50 readings untempered, and there that was sure too
#: soon: calibration error 0.14 against 0.04 with steady readings and 0.11 against 0.03 with
#: filament readings, at the same error (1.13 against 1.13 m, 1.27 against 1.29 m).  The
#: square-root law keeps 50 readings' temperature (5/3) and lets more readings count more.
#: Filament readings at 150: ``m / 30`` 1.12 / 0.13 / 6.33, ``m / 100`` 1.06 / 0.09 / 6.37,
#: ``sqrt(m / 18)`` 1.10 / 0.08 / 6.26.  Searches keep ``m / 30`` (their preset).
MAP_TEMPERING = (18.0, 0.5)
#: DGSE-S's weight in the source posterior at ``map``: ``0.9 (1 - m / 50)`` for ``m`` readings,
#: chosen on validation scenarios (``python benchmarks/tune_phys_learned.py``).
LEARNED_WEIGHT = 0.9
LEARNED_READINGS = 50.0
#: DGSE-S's least weight in the source posterior per knowledge level (``learned_floor=None``;
#: levels not named: none).  The physics on a proposed or given flow can be sure of a wrong
#: spot, and a little of the network bounds how sure.  Chosen on validation scenarios 900-923
#: (``python benchmarks/tune_phys_fusion.py --knowledge L ...``; the physics' and the network's
#: posteriors recorded per estimate, the mixture scored for a grid of weights) as the largest
#: weight of the grid whose calibration error is nowhere more than 0.01 above the physics
#: alone's.
#:
#: * ``map`` (``--counts 50 150 --trials 1``, 24 estimates a cell, chance calibration error
#:   0.06; ``benchmarks/results/phys_fusion_tuning/``): 0.05.  Against no floor, mean source CE
#:   at 50 readings 6.99 to 6.61 nats (steady) and 7.00 to 6.83 (filament), at 150 6.34 to
#:   6.24 and 6.28 to 6.10; mean SL error 0.00-0.02 m lower; calibration error 0.067 to 0.047,
#:   0.055 to 0.055, 0.117 to 0.105, 0.131 to 0.134.  (0.1 lowered the CE a little more but put
#:   the filament calibration at 150 readings 0.026 above.)
#: * ``wind`` (``--variants steady filament`` and ``wind_rotated wind_smoothed wind_x2``,
#:   ``--counts 50 150 --trials 2``, 48 estimates a cell, chance 0.04;
#:   ``benchmarks/results/phys_fusion_tuning_wind_perturbed/``): 0.02 (0.05 put steady and
#:   twice-too-fast winds at 150 readings 0.011 above).  Mean CE 0.04-0.40 nats lower in 5 of
#:   the 10 cells, most with the smoothed wind (6.04 to 5.85, 6.10 to 5.69), the rotated wind
#:   and filament readings at 150 (5.22 to 4.86, 5.94 to 5.63), and at most 0.008 higher in the
#:   others; SL error unchanged to 0.01 m; calibration error lower in 8 of the 10 cells, at
#:   most 0.006 higher in the other two (steady and twice too fast at 150).  Checked again
#:   with the given field weighed against its openings' RANS flows (:data:`GIVEN_WIND_PRIOR`,
#:   2026-11-29; the same command with ``--cache`` of the robustness runs, ``-o
#:   benchmarks/results/phys_fusion_tuning_wind_given``): 0.02 again (0.05 put the rotated
#:   wind at 150 readings 0.018 above); against no floor the calibration error at 50 readings
#:   0.024-0.053 against 0.030-0.062, at 150 at most 0.004 higher.
#: * ``openings`` (``--counts 20 50 150 --trials 5``, 120 estimates a cell, chance 0.027): 0.02
#:   since 2026-11-29 (``benchmarks/results/phys_fusion_tuning_openings_tilt/``, with the
#:   zeros-following rate nodes; none before).  Against no floor the calibration error falls
#:   with filament readings at 20 and 50 (0.048 to 0.035, 0.051 to 0.043) and with steady
#:   ones at 20 (0.038 to 0.032), and rises by at most 0.006 in the other three cells (steady
#:   at 150: 0.094 to 0.100); CE 0.02-0.20 nats lower with filament readings, within 0.01
#:   with steady ones; SL error unchanged to 0.01 m.  0.05 put the steady readings at 50 and
#:   the filament ones at 150 0.015 and 0.013 above (the grid of 2026-11-28, before the
#:   rate nodes followed the zeros, said the same: ``benchmarks/results/phys_fusion_tuning/``).
#:
#: Searches keep no floor (the search preset, :data:`dgse.presets.PRESETS`): they were measured without it.
LEARNED_FLOOR: dict[str, float] = {"map": 0.05, "wind": 0.02, "openings": 0.02}
#: Whether the zeros' factor lets the rate's nodes follow the zeros (``censored_tilt``), per
#: knowledge level; a level not named here has it on.  It was made for the searches at
#: ``openings`` (2026-11-28 e: validation 900-923 found 24 of 24 sources against 22 of 24,
#: and test 2008's failure, a noise floor far above the plume, was fixed).  At ``map`` it is
#: off, as every ``map`` search and random-readings result of ``docs/dgse-phys.md`` up to 2026-11-28 e
#: was measured.  On validation 900-923 (``python benchmarks/tune_phys_calibration.py --seeds
#: 900-923 --counts 150 300 --trials 2 --variants steady --knowledge map [-E
#: censored_tilt=false]``, 48 estimates a count, ``benchmarks/results/phys_tilt_map_validation/``)
#: it changed nothing there beyond noise: SL error with it minus without +0.005 +- 0.027 and
#: +0.013 +- 0.022 m at 150 and 300 readings, CE +0.02 +- 0.02 and +0.04 +- 0.03 nats.  (On the
#: test scenarios it was worse, +0.09 and +0.17 m, which is what prompted that check: see the
#: random-readings results of ``docs/dgse-phys.md``.)
CENSORED_TILT: dict[str, bool] = {"map": False}
#: Why ``noise_weights`` defaults to ``"mixture"`` for estimates from given readings too:
#: on validation scenarios 900-923 (Table I noise; ``python benchmarks/phys_robustness.py
#: --seeds 900-923 --counts 50 150 --trials 5 --variants steady filament --methods
#: dgse-phys@openings -E 'noise_weights="W"'``, and the same at ``map`` and ``wind`` as
#: below; ``benchmarks/results/phys_noise_weights_validation/LEVEL_W/``), mean SL
#: error / source CE / credible-set calibration error, plug-in against mixture.  Openings
#: (120 estimates a cell, chance calibration error 0.03): steady 50 readings 0.96 m / 5.6 /
#: 0.02 against 0.79 m / 5.2 / 0.02, 150: 0.69 / 5.6 / 0.05 against 0.61 / 4.5 / 0.08;
#: filament 50: 1.12 / 6.9 / 0.08 against 0.91 / 6.0 / 0.06, 150: 1.00 / 7.3 / 0.08 against
#: 0.75 / 5.7 / 0.02.  Map (``--counts 50 --trials 2``, 48 estimates, chance 0.04): steady
#: 1.35 / 7.9 / 0.09 against 1.16 / 7.1 / 0.05, filament 1.48 / 8.2 / 0.11 against 1.31 /
#: 6.9 / 0.03.  Wind (``--counts 50 --trials 5``, 120 estimates): steady 0.98 / 5.8 / 0.03
#: against 0.82 / 5.3 / 0.02, filament 1.13 / 7.2 / 0.08 against 0.91 / 6.1 / 0.06.  Before that
#: date the default was ``"plug-in"``, and the random-readings tables of ``docs/dgse-phys.md`` up
#: to then were measured with it.
NOISE_WEIGHTS_CHOICE: Literal["mixture"] = "mixture"

#: The misfit flattening (``misfit_threshold``, ``misfit_temperature``) is off by default. The
#: rule was chosen on validation scenarios 900-923 at ``openings`` (``python
#: benchmarks/tune_phys_calibration.py``, 120 estimates a cell, chance calibration error 0.03;
#: ``benchmarks/results/phys_calibration_tuning/``), where with filament readings the posterior
#: was sure too soon (calibration error 0.054 at 50 readings, steady 0.023): a misfit over 2
#: picked 15 of 120 filament estimates (the truth's mean credible level 0.66) and 6 of 120
#: steady ones, and flattening those by 2 gave 0.023 / 0.027 (steady / filament, 50 readings)
#: and 0.090 / 0.024 (150) against 0.023 / 0.054 and 0.075 / 0.020, mean SL error within 0.01 m.
#: At ``wind`` (``--knowledge wind``, ``..._tuning_wind/``) it did the same (filament 50: 0.061
#: to 0.034; steady 150: 0.063 to 0.079); at ``map`` (48 estimates a cell, ``..._tuning_map/``)
#: steady 0.053 to 0.033 but filament 0.033 to 0.047. Those gains are about one chance level,
#: and on the test scenarios 2000-2019 (``benchmarks/results/phys_calibration50_misfit/``, 100
#: estimates a cell) it fired on 12 steady and 13 filament estimates, 20 of which already held
#: the truth in their 80 % credible set: calibration error 0.04 / 0.04 against 0.026 / 0.060
#: without, mean SL error 0.86 / 1.08 m against 0.78 / 1.01 m (flattening a two-peaked posterior
#: moves its mean between the peaks). So it is an option, not the default: ``MISFIT_THRESHOLD``
#: is the validation's choice.
MISFIT_THRESHOLD = 2.0
MISFIT_TEMPERATURE = 2.0

#: Model error of the predicted fields per knowledge level, ``(a, b, c, d)`` of
#: :func:`field_error_variance`: chosen on generated validation scenarios by maximum
#: likelihood of the true fields (``python benchmarks/tune_phys_fields.py``).
#: On those scenarios the hypotheses' spread alone covered the true wind in 0-7 % of the cells
#: at 1 sigma (nominal 68 %), with the model error 55-95 % (heavy tails: the likelihood picks
#: intervals too wide for most cells and still too narrow for misplaced jets); log(1 + c):
#: 31-54 % before, 75-89 % after.  At ``wind`` the given field was the truth there: a user's
#: own CFD errs more than this says.
FIELD_ERROR: dict[str, tuple[float, float, float, float]] = {
    "map": (0.15, 0.3, 0.1, 1.0),
    "openings": (0.1, 0.005, 0.0, 0.5),
    "wind": (0.03, 0.005, 0.0, 0.5),
}
#: Inlet speed the opening proposals are solved at (map level), m/s.
MAP_SPEED = 1.0
#: Relative wind-noise levels averaged in the wind likelihood (Table I: up to 0.5 in speed, 15 deg).
DEFAULT_WIND_NOISE = (0.1, 0.25, 0.5)


@dataclass(eq=False)
class PhysicsGuidedEstimator(KnowledgeUser):
    """``dgse-phys``: the adjoint posterior mixed over flow hypotheses (module docstring).

    Args:
        speeds: candidate inlet speeds at knowledge ``openings``, m/s.
        wind_noise_levels: relative wind-noise levels of the wind likelihood.
        wind_noise_floor: absolute wind noise (and model error) floor, m/s.
        q_max, kappas, alpha0, sigma0_fraction: the gas evidence's priors
            (:func:`~dgse.posterior.adjoint.adjoint_log_evidence`).
        noise_floor_prior: when the prior noise scale is kept at least the floor of the
            hypotheses' flows (:func:`~dgse.posterior.adjoint.prior_noise_floor`:
            ``"always"``, ``"unscaled"`` while fewer than two readings are positive, ``"never"``).
        noise_weights: the proportional noise's concentrations, ``"plug-in"``, each
            candidate's own (``"candidate"``) or the larger (``"larger"``;
            :func:`~dgse.posterior.adjoint.adjoint_log_evidence`); ``"mixture"``: the
            equal-weight average of the ``"plug-in"`` and ``"candidate"`` posteriors (the
            planner follows the sharper one, a mass stop needs both; twice the evidence work),
            the default since 2026-11-28 c (:data:`NOISE_WEIGHTS_CHOICE`).
        conc_components: sources per hypothesis in the concentration estimate (drawn from
            its source posterior by :func:`predictive_sources`).
        min_weight: hypotheses below this posterior weight are left out of the predictive.
        learned_weight, learned_readings, learned_levels: at the knowledge levels
            ``learned_levels`` the source posterior is mixed with DGSE-S's (the shipped
            network), weight ``max(learned_floor, learned_weight * max(0, 1 - m /
            learned_readings))`` for ``m`` readings: the network where the readings are few,
            the physics after.  On a map whose cells the network cannot take (not a whole
            multiple of its own) the physics stands alone and ``info["learned_note"]`` says why.
        learned_floor: the network's weight never falls below this, at any level (0: the
            physics alone from ``learned_readings`` on, and at the levels not in
            ``learned_levels``); None: the level's :data:`LEARNED_FLOOR` (0.05 at ``map``,
            0.02 at ``wind`` since 2026-11-28 d and at ``openings`` since 2026-11-29; the
            searches use 0).  A floor caps how sure of a wrong spot the mixture can be, at
            the cost of slower mass stops and of running the network for every estimate.
        learned_opinion: attach to every belief ``info["learned_source_probs"]``, a function
            of no arguments that returns DGSE-S's own source belief from the same readings
            (``(H, W)``), whatever the network's weight in the posterior: a second opinion the
            search's ``min_learned_mass`` hold reads.  The network runs when it is first
            called (the hold asks only when a stop would fire), at most once per belief; on a
            map the network cannot take, it raises :class:`~dgse.errors.InputDataError`.
        hypothesis_readings: beyond this many readings the flow hypotheses' weights are
            tempered, ``T = m / hypothesis_readings`` (None: not tempered).
        wind_likelihood: how the wind readings weigh the flow hypotheses: ``"sensor"``
            (Table I noise, :func:`wind_log_likelihood`) or ``"profile"`` (the residuals'
            variance unknown, readings counted up to the evidence's effective readings:
            :func:`profile_wind_log_likelihood`).
        refine_speeds, refine_readings, refine_ratio: at knowledge ``openings``, up to
            ``refine_speeds`` inlet speeds are added between the candidates once
            ``refine_readings`` readings weigh them (see ``_refine_speed``); 0: the
            candidates only.
        map_proposals: opening hypotheses at knowledge ``map`` (the best pairs of
            :func:`~dgse.physics.openings.potential_flow_proposals`).
        map_learned_proposals: at knowledge ``map``, up to this many more hypotheses from
            a network's wind belief (:func:`~dgse.physics.openings.wind_field_proposals`
            on DGSE-S's mean wind from the same readings), those the potential flow
            did not already propose; 0: none.
        map_proposal_model: the DGSE-S weights whose wind those come from (``"default"``:
            the shipped network, or a weights file).
        temperature: the gas evidence is divided by it (a power posterior: ``T > 1``
            absorbs model error by counting the readings as ``m / T`` independent ones).
        effective_readings: beyond this many readings the evidence is tempered further,
            ``T = max(temperature, (m / effective_readings) ** (1 - effective_growth))``:
            readings of one plume are not independent once the model's own error dominates
            the noise.  None: the level's default, both numbers (:data:`DEFAULT_EFFECTIVE_READINGS`
            with growth 0; at ``map`` :data:`MAP_TEMPERING`); ``inf``: off.
        effective_growth: with ``effective_readings`` given, how the counted readings grow
            beyond it, ``m ** effective_growth``: 0 (default) keeps them at
            ``effective_readings``, 0.5 lets them grow as the square root; ``[0, 1)``.
        censored: read zero readings as censored (the sensor clips negatives; see
            :func:`~dgse.posterior.adjoint.censored_correction`); False: as exact zeros.
        censored_ranking: how that correction picks the candidates it integrates:
            ``"plug-in"`` (the default the searches were chosen with, an approximation) or
            ``"bound"`` (exact to its tolerance; see
            :data:`~dgse.posterior.adjoint.CENSORED_RANKING`).
        censored_tilt: where the zeros pull the release rate far below the positive
            readings' estimate of it (a noise floor far above the plume reads half zeros
            and half noise), the correction's rate nodes and plug-in value follow the zeros
            (:func:`~dgse.posterior.adjoint.censored_correction`); False: as before
            2026-11-28 e, when such a correction could miss the true source's by 21-89 nats
            (test 2008 of the searches); None (the default): the knowledge level's
            :data:`CENSORED_TILT` (off at ``map``, on elsewhere).
        warm_start: at knowledge ``openings``, start each speed's RANS solve from the
            flow of the speed below (about 2.5x faster: 2.4 s against 5.8 s for the six
            speeds of test scenario 2005) instead of from the coarse grid, as ``dgse solve``
            does.  Both meet the residual criteria, but the turbulence of quiet rooms (``k``
            and ``epsilon`` a thousandth of the jet's, invisible to normalised residuals)
            stays where the start left it: on test 2005 the two flows' ``nu_t`` differ by
            71 % (median over free cells) and the estimate from 150 readings is 3.2 m off
            warm, 0.17 m cold (``python benchmarks/phys_diagnostics.py``).  Validation searches
            favour the warm start (900-907 and 908-913, openings, the search preset: 14 of
            14 found warm, 12 of 14 cold; test 2005 failed both ways), and it is the faster,
            so it is the default.
        misfit_threshold, misfit_temperature: when the gas readings' mean squared
            standardized residual on the posterior's most probable source (its heaviest flow,
            the belief's noise model) exceeds ``misfit_threshold``, the source posterior is
            raised to ``1 / misfit_temperature`` (:func:`gas_misfit`):
            readings the physics explains worse than their noise allows (an intermittent
            plume, a wrong flow) make it less sure.  None (the default): never;
            :data:`MISFIT_THRESHOLD` and :data:`MISFIT_TEMPERATURE` are the validation's
            choice, which the test scenarios did not bear out.
        field_error: ``(a, b, c, d)`` of :func:`field_error_variance`, the model error added
            to the wind and concentration variances (the spread between hypotheses, the
            part readings reduce, stays in the belief's ``*_reducible`` fields, which the
            planner uses); None: the level's :data:`FIELD_ERROR`; zeros: none.
        given_wind_prior: at knowledge ``wind``, the prior weight of the given field; the rest
            goes to the built-in RANS flows of the openings at the ``speeds`` (log-uniform over
            the speed, refined as at ``openings``): the knowledge's openings, or where it has
            none those the given field crosses the map's edge at
            (:func:`~dgse.physics.openings.propose_openings`).  The wind and gas readings then
            weigh a user's field against the physics of its openings, which hedges a field
            that is wrong (smoothed, from another speed).  1: the given field alone (the
            default before 2026-11-29); :data:`GIVEN_WIND_PRIOR` has the validation numbers.
        flow_settings: SIMPLEC controls of the built-in solver.
        physics: physical constants.
    """

    knowledge_levels: ClassVar[tuple[Level, ...]] = ("map", "openings", "wind")

    speeds: Sequence[float] = DEFAULT_SPEEDS
    wind_noise_levels: Sequence[float] = DEFAULT_WIND_NOISE
    wind_noise_floor: float = 0.05
    q_max: float | None = 5.0
    kappas: Sequence[float] = DEFAULT_KAPPAS
    alpha0: float = 1.0
    sigma0_fraction: float = 0.25
    noise_floor_prior: Literal["always", "unscaled", "never"] = "never"
    noise_weights: Literal["plug-in", "candidate", "larger", "mixture"] = NOISE_WEIGHTS_CHOICE
    conc_components: int = 32
    min_weight: float = 1e-4
    temperature: float = 1.0
    effective_readings: float | None = None
    effective_growth: float = 0.0
    censored: bool = True
    censored_ranking: str = CENSORED_RANKING
    censored_tilt: bool | None = None
    map_proposals: int = 5
    map_learned_proposals: int = 0
    map_proposal_model: str = "default"
    learned_weight: float = LEARNED_WEIGHT
    learned_readings: float = LEARNED_READINGS
    learned_floor: float | None = None
    learned_levels: Sequence[str] = ("map",)
    learned_opinion: bool = False
    hypothesis_readings: float | None = None
    wind_likelihood: str = "sensor"
    refine_speeds: int = 4
    refine_readings: int = 10
    refine_ratio: float = 1.08
    warm_start: bool = True
    misfit_threshold: float | None = None
    misfit_temperature: float = MISFIT_TEMPERATURE
    field_error: Sequence[float] | None = None
    given_wind_prior: float = GIVEN_WIND_PRIOR
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
        check_noise_floor_mode(self.noise_floor_prior)
        check_noise_weights(self.noise_weights, (*NOISE_WEIGHTS, "mixture"))
        speeds = [float(v) for v in self.speeds]
        if not speeds or any(not (v > 0 and math.isfinite(v)) for v in speeds):
            raise InputDataError(f"speeds must be positive numbers of m/s, got {self.speeds}")
        self.speeds = tuple(speeds)
        levels = [float(r) for r in self.wind_noise_levels]
        if not levels or any(not (r > 0 and math.isfinite(r)) for r in levels):
            raise InputDataError(f"wind_noise_levels must be positive, got {self.wind_noise_levels}")
        self.wind_noise_levels = tuple(levels)
        if self.wind_likelihood not in ("sensor", "profile"):
            raise InputDataError(
                f"wind_likelihood must be 'sensor' or 'profile', got {self.wind_likelihood!r}"
            )
        if not (self.wind_noise_floor > 0 and math.isfinite(self.wind_noise_floor)):
            raise InputDataError(f"wind_noise_floor must be positive, got {self.wind_noise_floor}")
        if not (self.temperature >= 1.0 and math.isfinite(self.temperature)):
            raise InputDataError(f"temperature must be >= 1, got {self.temperature}")
        for name in ("censored", "censored_tilt", "learned_opinion"):
            value = getattr(self, name)
            if not (isinstance(value, bool) or (name == "censored_tilt" and value is None)):
                raise InputDataError(f"{name} must be true or false, got {value!r}")
        mt = self.misfit_threshold
        if mt is not None and not (mt > 0 and math.isfinite(mt)):
            raise InputDataError(f"misfit_threshold must be a positive number or None, got {mt}")
        if not (self.misfit_temperature >= 1.0 and math.isfinite(self.misfit_temperature)):
            raise InputDataError(f"misfit_temperature must be >= 1, got {self.misfit_temperature}")
        if not (0.0 <= self.effective_growth < 1.0):
            raise InputDataError(f"effective_growth must be in [0, 1), got {self.effective_growth}")
        if self.effective_readings is not None and not (self.effective_readings > 0):
            raise InputDataError(
                f"effective_readings must be positive (inf: off) or None, got {self.effective_readings}"
            )
        if self.censored_ranking not in CENSORED_RANKINGS:
            raise InputDataError(
                f"censored_ranking must be one of {CENSORED_RANKINGS}, got {self.censored_ranking!r}"
            )
        levels = tuple(str(v) for v in self.learned_levels)
        bad = [v for v in levels if v not in self.knowledge_levels]
        if bad:
            known = list(self.knowledge_levels)
            raise InputDataError(f"learned_levels: unknown knowledge levels {bad}; use {known}")
        self.learned_levels = levels
        if not (0.0 <= self.learned_weight <= 1.0):
            raise InputDataError(f"learned_weight must be in [0, 1], got {self.learned_weight}")
        if self.learned_floor is not None and not (0.0 <= self.learned_floor <= self.learned_weight):
            raise InputDataError(
                f"learned_floor must be in [0, learned_weight] or None, got {self.learned_floor}"
            )
        if not (self.learned_readings > 0 and math.isfinite(self.learned_readings)):
            raise InputDataError(f"learned_readings must be positive, got {self.learned_readings}")
        rs = self.refine_speeds
        if isinstance(rs, bool) or int(rs) != rs or rs < 0:
            raise InputDataError(f"refine_speeds must be an integer >= 0, got {self.refine_speeds!r}")
        if not (self.refine_ratio > 1.0 and math.isfinite(self.refine_ratio)):
            raise InputDataError(f"refine_ratio must be a number > 1, got {self.refine_ratio}")
        for key, least in (("map_proposals", 1), ("map_learned_proposals", 0)):
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, int | float) or int(v) != v or v < least:
                raise InputDataError(f"{key} must be an integer >= {least}, got {v!r}")
        mpm = str(self.map_proposal_model)
        if mpm != "default" and not Path(mpm).is_file():
            raise InputDataError(f"map_proposal_model: {mpm} is not a weights file (or 'default')")
        if not (0.0 < self.given_wind_prior <= 1.0):
            raise InputDataError(f"given_wind_prior must be in (0, 1], got {self.given_wind_prior}")
        if int(self.conc_components) < 1:
            raise InputDataError(f"conc_components must be >= 1, got {self.conc_components}")
        if self.field_error is not None:
            fe = [float(v) for v in self.field_error]
            if len(fe) != 4 or any(not (v >= 0 and math.isfinite(v)) for v in fe):
                raise InputDataError(f"field_error must be four numbers >= 0, got {self.field_error}")
            self.field_error = tuple(fe)

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
        proposals = potential_flow_proposals(
            k.occupancy, k.resolution, obs.cells, obs.wind, top=self.map_proposals
        )
        n_flow = len(proposals)
        if self.map_learned_proposals > 0:
            wind = self._proposal_wind(k.occupancy, k.resolution, obs)
            learned = wind_field_proposals(
                k.occupancy, k.resolution, wind, obs.cells, obs.wind, top=self.map_learned_proposals
            )
            proposals = merge_proposals(proposals, learned)
        hyps = []
        for n, prop in enumerate(proposals):
            layout = Layout(
                k.occupancy, prop.inlets, prop.outlets, resolution=k.resolution, name=k.name or "map"
            )
            # the flow's shape is what matters: one speed, the wind fit scales it (see estimate)
            fm = flow_model(layout, MAP_SPEED, self.physics, self.flow_settings)
            label = prop.label() + (" (network wind)" if n >= n_flow else "")
            hyps.append(FlowHypothesis(label, fm, 1.0 / len(proposals)))
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
                assert k.wind is not None
                proj = project_wind(
                    k.occupancy,
                    k.resolution,
                    k.wind,
                    k.layout if k.has_openings else None,
                    physics=self.physics,
                )
                fm = FlowModel(
                    proj.wind, transport_from_wind(proj, self.physics), math.nan, proj.info, self.physics
                )
                given = FlowHypothesis("given wind", fm, 1.0)
                p = float(self.given_wind_prior)
                self._speed_layout = None if p >= 1.0 else self._openings_of(k)
                family: list[FlowHypothesis] = []
                if self._speed_layout is not None:
                    try:
                        family = self._speed_family(self._speed_layout, list(self.speeds))
                    except (ConvergenceError, InputDataError) as exc:  # the hedge is optional
                        self._speed_layout = None
                        self._family_note = f"the RANS flows of the openings left out: {exc}"
                self._hypotheses = with_given(given, p, family) if family else [given]
            else:
                self._speed_layout = k.layout
                self._hypotheses = self._speed_family(k.layout, list(self.speeds))
        return self._hypotheses

    def _speed_family(self, layout: Layout, speeds: list[float]) -> list[FlowHypothesis]:
        """The built-in RANS flows of ``layout`` at ``speeds``, with the log-uniform prior over
        the speed; in order of speed, with ``warm_start`` each solve starting from the one
        before (scaled)."""
        hyps: list[FlowHypothesis] = []
        for v in sorted(speeds):
            prev = hyps[-1].flow if hyps and self.warm_start else None
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
        measures most.  So once ``refine_readings`` readings weigh the speeds, each
        estimate may bisect (in log speed) the interval between the best speed and its
        heavier neighbour while they are more than ``refine_ratio`` apart, at most
        ``refine_speeds`` times per map (with ``warm_start``, the new flow starts from the
        best one's).  It is weighed from the next estimate on.
        """
        layout = self._speed_layout
        speed = [i for i, h in enumerate(hyps) if math.isfinite(h.flow.inlet_velocity)]
        full = len(speed) >= len(self.speeds) + self.refine_speeds
        if layout is None or n_obs < self.refine_readings or full:
            return
        order = sorted(speed, key=lambda i: hyps[i].flow.inlet_velocity)
        best = max(speed, key=lambda i: weights[i])
        pos = order.index(best)
        sides = [order[j] for j in (pos - 1, pos + 1) if 0 <= j < len(order)]
        if not sides:
            return
        other = max(sides, key=lambda i: weights[i])
        v0, v1 = hyps[best].flow.inlet_velocity, hyps[other].flow.inlet_velocity
        if max(v0, v1) / min(v0, v1) <= self.refine_ratio:
            return
        v = math.sqrt(v0 * v1)
        start = hyps[best].flow if self.warm_start else None
        fm = flow_model(layout, v, self.physics, self.flow_settings, warm_start=start)
        family = log_speed_priors([*(hyps[i] for i in speed), FlowHypothesis(speed_label(v), fm)])
        given = [h for h in hyps if not math.isfinite(h.flow.inlet_velocity)]
        self._hypotheses = with_given(given[0], given[0].prior, family) if given else family

    # -- the learned source belief ---------------------------------------------------------------
    def _learned_weight(self, m: int) -> float:
        k = self.knowledge
        if self.learned_weight <= 0 or k is None:
            return 0.0
        fading = 0.0
        if k.level in self.learned_levels:
            fading = self.learned_weight * max(0.0, 1.0 - m / self.learned_readings)
        floor = LEARNED_FLOOR.get(k.level, 0.0) if self.learned_floor is None else self.learned_floor
        return float(max(floor, fading))

    def _censored_tilt(self) -> bool:
        """``censored_tilt``, or where it is None the knowledge level's :data:`CENSORED_TILT`."""
        if self.censored_tilt is not None:
            return self.censored_tilt
        return True if self.knowledge is None else CENSORED_TILT.get(self.knowledge.level, True)

    def _tempering(self) -> tuple[float, float]:
        """``(effective_readings, effective_growth)``, or where the first is None the knowledge
        level's pair."""
        if self.effective_readings is not None:
            return self.effective_readings, self.effective_growth
        level = None if self.knowledge is None else self.knowledge.level
        return MAP_TEMPERING if level == "map" else (DEFAULT_EFFECTIVE_READINGS, 0.0)

    def _readings_factor(self, m: int) -> float:
        """``max(1, (m / effective_readings) ** (1 - effective_growth))``: by how much ``m``
        readings are tempered for not being independent."""
        m_eff, growth = self._tempering()
        return max(1.0, (m / m_eff) ** (1.0 - growth))

    def _counted_readings(self, m: int) -> float:
        """How many independent readings ``m`` readings count as: ``m`` up to
        ``effective_readings``, then ``effective_readings ** (1 - g) * m ** g``."""
        return m / self._readings_factor(m)

    def _temperature(self, m: int) -> float:
        """The gas evidence's temperature with ``m`` readings."""
        return max(self.temperature, self._readings_factor(m))

    def _learned_belief(self, occupancy: np.ndarray, resolution: float, obs: Observations) -> Belief:
        """DGSE-S's belief from the same readings (the shipped network, built on first use)."""
        return self._network("default").estimate(occupancy, resolution, obs)

    def _learned_opinion(
        self, occupancy: np.ndarray, resolution: float, obs: Observations, net: Belief | None
    ) -> Callable[[], np.ndarray]:
        """``info["learned_source_probs"]``: DGSE-S's source belief from ``obs``, computed on the
        first call (``net``: already computed)."""

        @functools.cache
        def probs() -> np.ndarray:
            b = net if net is not None else self._learned_belief(occupancy, resolution, obs)
            return np.asarray(b.source_probs, dtype=np.float64)

        return probs

    def _proposal_wind(self, occupancy: np.ndarray, resolution: float, obs: Observations) -> np.ndarray:
        """DGSE-S's mean wind from ``obs`` with ``map_proposal_model``'s weights (built on first use)."""
        net = self._network(self.map_proposal_model)
        return np.asarray(net.estimate(occupancy, resolution, obs).wind_mean)

    def _network(self, model: str) -> Any:
        """The DGSE-S estimator with weights ``model``, built on first use and shared by every use."""
        if model not in self._networks:
            from dgse.estimators.registry import get_estimator

            self._networks[model] = get_estimator(
                "dgse-s", model=model, seed=0, dtype="auto", channels_last=True
            )
        return self._networks[model]

    def _gas_evidence(
        self,
        hyps: list[FlowHypothesis],
        rows: dict[int, np.ndarray],
        z: np.ndarray,
        s0_floor: float,
        noise_weights: str,
    ) -> tuple[list[np.ndarray], list[tuple[Any, dict[str, Any]]]]:
        """The positive readings' log evidence per hypothesis with one noise-weight mode, the
        zeros' factor deferred: ``(log evidence, (rows, details))`` per hypothesis.  ``rows``:
        the readings' response rows of the live hypotheses (by index); the others (ruled out by
        the wind) get no gas evidence.  Reads no state that another mode's call, run beside
        it, writes."""

        def evidence(k: int) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
            A = rows[k]
            logl, det = adjoint_log_evidence(
                A,
                z,
                q_max=self.q_max,
                kappas=self.kappas,
                alpha0=self.alpha0,
                sigma0_fraction=self.sigma0_fraction,
                sigma0_floor=s0_floor,
                censored="deferred" if self.censored else False,
                noise_weights=noise_weights,
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
        t_h: float,
        memos: dict[int, dict[str, Any]] | None,
    ) -> tuple[np.ndarray, np.ndarray, list[np.ndarray], list[tuple[Any, dict[str, Any]]]]:
        """The source posterior and hypothesis weights from one noise-weight mode's evidence
        (:meth:`_gas_evidence`) and the zeros' factor: ``(post, weights, tempered log evidence
        per hypothesis, (rows, details) per hypothesis)``.  ``memos``: the zeros' factors
        computed for another mode, reused where the noise weights agree (:func:`censor_zeros`)."""
        zeros = censor_zeros(
            log_ev,
            log_prior,
            [d for _, d in details],
            temp,
            self.censored_ranking,
            self._censored_tilt(),
            hypothesis_temperature=t_h,
            memos=memos,
        )
        log_ev = [x / temp for x in zeros]
        post, hw = mix_posteriors(log_ev, log_prior, t_h)
        return post, hw, log_ev, details

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
        t_flow = time.perf_counter() - t0
        free_scale = self.knowledge.level == "map"  # proposals are solved at one speed
        cells, z = obs.cells, obs.gas
        log_prior: list[float] = []
        wind_ll: list[float] = []
        scales: list[float] = []
        misfits: list[float] = []
        counted = self._counted_readings(len(obs))
        temp = self._temperature(len(obs))
        for h in hyps:
            u = h.flow.wind[:, cells[:, 0], cells[:, 1]].T
            scale = fitted_wind_scale(u, obs.wind) if free_scale else 1.0
            scales.append(scale)
            misfits.append(relative_wind_misfit(scale * u, obs.wind))
            if self.wind_likelihood == "profile":
                lw = profile_wind_log_likelihood(scale * u, obs.wind, counted)
            else:
                lw = wind_log_likelihood(scale * u, obs.wind, self.wind_noise_levels, self.wind_noise_floor)
            wind_ll.append(lw)
            log_prior.append(math.log(h.prior) + lw)
        # flows the wind readings rule out (WIND_HOPELESS_NATS below the best) get no gas evidence
        lp_best = max(log_prior)
        s0_floor = prior_noise_floor(
            [h.flow for h in hyps], z, self.q_max, self.sigma0_fraction, self.noise_floor_prior
        )
        live = [k for k, lp in enumerate(log_prior) if lp >= lp_best - WIND_HOPELESS_NATS]
        t_h = 1.0 if self.hypothesis_readings is None else max(1.0, len(obs) / self.hypothesis_readings)
        modes = MIXED_NOISE_WEIGHTS if self.noise_weights == "mixture" else (self.noise_weights,)
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
            [functools.partial(self._gas_evidence, hyps, rows, z, s0_floor, mode) for mode in modes]
        )
        if same_noise_weights([det for _ev, det in evidence]):
            memos: dict[int, dict[str, Any]] = {}
            runs = [self._gas_posterior(ev, det, log_prior, temp, t_h, memos) for ev, det in evidence]
        else:
            runs = side_by_side(
                [
                    functools.partial(self._gas_posterior, ev, det, log_prior, temp, t_h, None)
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
        learned_note, net = None, None
        if w_learned > 0:
            try:
                net = self._learned_belief(occ, res, obs)
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
        qmax = np.inf if self.q_max is None else self.q_max

        def predictive(k: int) -> tuple[np.ndarray, np.ndarray]:
            """Hypothesis ``k``'s predictive mean and second moment (its flow's own cache)."""
            logl, det = log_ev[k], details[k][1]
            ph = np.exp(logl - logl.max())
            top, wts = predictive_sources(ph / ph.sum(), int(self.conc_components))
            qmap = np.clip(det["qhat"], 0.0, qmax)
            fields = hyps[k].flow.forward(mesh.cells[top], qmap[top])
            return wts @ fields, wts @ fields**2

        weighty = [k for k, w in enumerate(hw) if w >= self.min_weight]
        for k, (m1, m2) in zip(weighty, map_threads(predictive, weighty), strict=True):
            mean += hw[k] * m1
            second += hw[k] * m2
        total = float(hw[hw >= self.min_weight].sum())
        mean /= total
        second /= total
        var = np.maximum(second - mean**2, 0.0)
        mu, s2 = log_moments_from_ppm(mesh.field(np.maximum(mean, 0.0)), mesh.field(var))
        fe = FIELD_ERROR[self.knowledge.level] if self.field_error is None else self.field_error
        wind_err, conc_err = field_error_variance(wind_mean, mu, fe)
        best_h = int(np.argmax(hw))
        A_b, det_b = details[best_h]
        best = int(np.argmax(post))
        sig = sigma_floor(A_b, z, det_b["r"], best, self.alpha0, self.alpha0 * det_b["s0"] ** 2)
        qmap_b = np.clip(det_b["qhat"], 0.0, qmax)
        model = AdjointResponseModel(
            hyps[best_h].flow, qmap_b, sig, float(det_b["kappa"]), float(det_b.get("cbar", 1.0))
        )
        misfit = gas_misfit(A_b[:, best] * qmap_b[best], z, model)
        flatten = 1.0
        if self.misfit_threshold is not None and misfit > self.misfit_threshold:
            flatten = float(self.misfit_temperature)
            post = flattened(post, flatten)
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
            "misfit_flattening": flatten,
            "noise_floor_ppm": sig,
            "response_model": model,
            "timings": {"preprocessing": t_flow},
            "conc_space": "ppm",
        }
        if self.learned_opinion:
            info["learned_source_probs"] = self._learned_opinion(occ, res, obs, net)
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


@options_from(PhysicsGuidedEstimator)
def make_dgse_phys(**kwargs: Any) -> PhysicsGuidedEstimator:
    """Registry factory ``dgse-phys``; needs knowledge ``openings`` or ``wind``."""
    return PhysicsGuidedEstimator(**kwargs)
