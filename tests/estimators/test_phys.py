"""dgse-phys: the adjoint posterior mixed over flow hypotheses."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from dgse.belief.knowledge import Knowledge, PerLevel
from dgse.errors import InputDataError
from dgse.estimators.phys import (
    FUSION_SAMPLES,
    FlowHypotheses,
    GasEvidence,
    NetworkFusion,
    PhysicsGuidedEstimator,
    PredictedFields,
)
from dgse.estimators.registry import get_estimator
from dgse.evaluation.evaluate import draw_observations
from dgse.physics.scenario import solve_cases
from dgse.posterior.adjoint import AdjointResponseModel, adjoint_log_evidence, flow_model
from dgse.posterior.mixture import (
    MIXED_NOISE_WEIGHTS,
    FlowHypothesis,
    gas_misfit,
    mix_posteriors,
    predictive_sources,
    relative_wind_misfit,
    standardized_residuals,
    wind_log_likelihood,
)
from dgse.presets import PRESETS
from dgse.sensing.sensors import Observations
from tests.conftest import two_rooms

PHYS = PRESETS["dgse-phys"]
SEARCH_ESTIMATOR = dict(PHYS.search_estimator_options)


def search_estimator(level: str) -> dict:
    return PHYS.estimator_options_at(level, search=True)


def search_planner(level: str) -> dict:
    return PHYS.planner_options_at(level)


@pytest.fixture(scope="module")
def case():
    return solve_cases(two_rooms(), 1.2, [((2.05, 0.55), 0.8)])[0]


def test_mixture_with_one_weighty_hypothesis_is_that_posterior():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=50) * 3, rng.normal(size=50) * 3
    post, hw = mix_posteriors([a, b], [0.0, -1e6])
    single = np.exp(a - a.max())
    assert hw[0] == pytest.approx(1.0) and np.allclose(post, single / single.sum())
    # equal hypotheses mix to themselves; weights follow the evidence
    post2, hw2 = mix_posteriors([a, a + 2.0], [0.0, 0.0])
    assert np.allclose(post2, single / single.sum())
    assert hw2[1] / hw2[0] == pytest.approx(np.exp(2.0))
    with pytest.raises(InputDataError, match="prior weights"):
        mix_posteriors([a, b], [0.0])


def test_wind_likelihood_prefers_the_right_flow():
    u = np.array([[1.0, 0.0], [0.5, 0.5], [0.0, -1.0]])
    assert wind_log_likelihood(u, u, (0.2,), 0.05) > wind_log_likelihood(2 * u, u, (0.2,), 0.05)


def test_one_hypothesis_equals_the_adjoint_posterior(case):
    """With one flow hypothesis, dgse-phys's source posterior is the mean of the adjoint
    evidence's posteriors with the two noise models of :data:`MIXED_NOISE_WEIGHTS`, DGSE-S's
    floor left out."""
    est = PhysicsGuidedEstimator(fusion=NetworkFusion(floor=0.0))
    est.set_knowledge(Knowledge.from_case(case, "openings"))
    fm = flow_model(case.layout, case.inlet_velocity)
    est._hypotheses = [FlowHypothesis("true speed", fm, 1.0)]
    obs = draw_observations(case, 30, seed=1)
    b = est.estimate(case.occupancy, case.resolution, obs)
    posts = []
    for mode in MIXED_NOISE_WEIGHTS:
        logl, _ = adjoint_log_evidence(fm.responses(obs.cells), obs.gas, noise_weights=mode)
        p = np.exp(logl - logl.max())
        posts.append(p / p.sum())
    assert MIXED_NOISE_WEIGHTS == ("plug-in", "candidate")
    assert not np.allclose(posts[0], posts[1])
    assert np.allclose(b.source_probs[case.free], np.mean(posts, axis=0))
    assert b.info["gas_misfit"] > 0
    h = b.info["hypotheses"][0]
    assert h["weight"] == pytest.approx(1.0)
    # the hypothesis's own terms: the peak of its posterior (the first noise model's), the wind
    # terms its flow's
    i, j = fm.mesh.cells[int(np.argmax(posts[0]))]
    assert h["source_mode_xy"] == pytest.approx([(j + 0.5) * case.resolution, (i + 0.5) * case.resolution])
    u = fm.wind[:, obs.cells[:, 0], obs.cells[:, 1]].T
    assert h["wind_misfit"] == pytest.approx(relative_wind_misfit(u, obs.wind))
    assert h["wind_log_likelihood"] == pytest.approx(
        wind_log_likelihood(u, obs.wind, est.flows.wind_noise_levels, est.flows.wind_noise_floor)
    )
    assert np.isfinite(h["gas_log_evidence"])


def test_noise_weight_mixture_averages_the_two_posteriors(case, monkeypatch):
    """The posterior is the mean of the plug-in and candidate source posteriors and hypothesis
    weights (each one alone: :data:`MIXED_NOISE_WEIGHTS` cut to it); a mass stop then needs both."""
    from dgse.estimators import phys

    k = Knowledge.from_case(case, "openings")
    obs = draw_observations(case, 25, seed=4)
    opts = {"knowledge": k, "flows.speeds": (0.6, 1.2), "flows.refine_speeds": 0}
    b = {"mixture": get_estimator("dgse-phys", **opts).estimate(case.occupancy, case.resolution, obs)}
    for mode in ("plug-in", "candidate"):
        monkeypatch.setattr(phys, "MIXED_NOISE_WEIGHTS", (mode,))
        b[mode] = get_estimator("dgse-phys", **opts).estimate(case.occupancy, case.resolution, obs)
    assert not np.allclose(b["plug-in"].source_probs, b["candidate"].source_probs)
    mean = (b["plug-in"].source_probs + b["candidate"].source_probs) / 2
    assert np.allclose(b["mixture"].source_probs, mean)
    w = [[h["weight"] for h in b[m].info["hypotheses"]] for m in ("plug-in", "candidate", "mixture")]
    assert np.allclose(w[2], (np.array(w[0]) + np.array(w[1])) / 2)
    # the fields come from the plug-in's evidence, mixed with the mixture's hypothesis weights;
    # here one flow carries all the weight in every mode, so they are the plug-in's to the bit
    # and not the candidate's
    assert w[2] == w[0]
    for field in ("log_conc_mean", "log_conc_var", "wind_mean", "wind_var"):
        np.testing.assert_array_equal(getattr(b["mixture"], field), getattr(b["plug-in"], field))
    assert not np.allclose(b["mixture"].log_conc_mean, b["candidate"].log_conc_mean)


def test_noise_weight_modes_share_the_zeros_factors_without_changing_the_belief(case, monkeypatch):
    """Where both modes' most probable kappa gives the same noise weights, the second reuses the
    zeros' factors the first integrated: the belief is the one computed with no sharing."""
    from dgse.estimators import phys

    k = Knowledge.from_case(case, "openings")
    obs = draw_observations(case, 40, seed=6)
    assert (obs.gas <= 0).any()
    opts = {"knowledge": k, "flows.speeds": (0.6, 1.2), "flows.refine_speeds": 0, "evidence.kappas": (0.0,)}
    shared = get_estimator("dgse-phys", **opts).estimate(case.occupancy, case.resolution, obs)
    asked: list[bool] = []
    same = phys.same_noise_weights

    def never(modes):
        asked.append(same(modes))
        return False

    monkeypatch.setattr(phys, "same_noise_weights", never)
    alone = get_estimator("dgse-phys", **opts).estimate(case.occupancy, case.resolution, obs)
    assert asked == [True]  # kappa = 0 only: weights 1 in both modes
    np.testing.assert_array_equal(shared.source_probs, alone.source_probs)
    np.testing.assert_array_equal(shared.log_conc_mean, alone.log_conc_mean)


def test_modes_share_the_zeros_factors_only_where_every_weighted_input_agrees():
    """Equal zeros' weights are not enough: the positive readings' sums must agree too."""
    from dgse.estimators import phys

    r = np.ones(2)
    sums = (np.array([1.0, 2.0]), np.array([0.5, 0.1]), 3.0)

    def mode(r_, sums_):
        return [(None, {"censor": {"r": r_, "sums": sums_}}), (None, {})]

    assert phys.same_noise_weights([mode(r, sums), mode(r.copy(), tuple(sums))])
    other = (sums[0], sums[1], 3.5)
    assert not phys.same_noise_weights([mode(r, sums), mode(r, other)])
    assert not phys.same_noise_weights([mode(r, sums), mode(np.ones((2, 4)), sums)])
    assert not phys.same_noise_weights([mode(r, sums)])


def test_misfit_is_the_mean_squared_standardized_residual():
    model = AdjointResponseModel(flow=None, q_map=np.ones(1), sigma_floor=2.0, kappa=0.5, cbar=10.0)
    mu = np.array([0.0, 10.0, 20.0])
    sig = 2.0 * (1 + 0.5 * mu / 10.0)
    assert gas_misfit(mu, mu, model) == 0.0
    assert gas_misfit(mu, mu + sig, model) == pytest.approx(1.0)
    assert gas_misfit(mu, mu - 3 * sig, model) == pytest.approx(9.0)
    assert np.allclose(standardized_residuals(mu, mu + 2 * sig, model), 2.0)


def test_openings_weigh_the_inlet_speeds(case):
    k = Knowledge.from_case(case, "openings")
    est = get_estimator("dgse-phys", knowledge=k, **{"flows.speeds": (0.4, 1.2, 3.6)})
    obs = draw_observations(case, 40, seed=2)
    b = est.estimate(case.occupancy, case.resolution, obs)
    w = {h["inlet_velocity"]: h["weight"] for h in b.info["hypotheses"]}
    assert w[1.2] > 0.9  # the readings' winds pick the true speed
    assert b.localization_error(tuple(case.source)) < 0.5
    assert b.wind_mean is not None and b.wind_var is not None and b.log_conc_mean is not None
    assert b.info["knowledge"] == "openings" and b.method == "dgse-phys"


def test_wind_level_works_without_openings(case):
    """A given wind without openings (a GADEN-style slice): as good as the oracle on the true flow."""
    k = Knowledge("wind", case.occupancy, case.resolution, wind=case.wind, name="no openings")
    est = get_estimator("dgse-phys", knowledge=k)
    oracle = get_estimator("adjoint-oracle", knowledge=Knowledge.from_case(case, "wind"))
    for seed in (0, 1, 2):
        obs = draw_observations(case, 40, seed=seed)
        b = est.estimate(case.occupancy, case.resolution, obs)
        ref = oracle.estimate(case.occupancy, case.resolution, obs)
        src = tuple(case.source)
        assert b.localization_error(src) < ref.localization_error(src) + 0.15
    assert b.info["hypotheses"][0]["label"] == "given wind"


def test_given_wind_is_weighed_against_the_rans_flows_of_its_openings(case):
    """``flows.given_wind_prior < 1``: the RANS flows of the openings share the rest of the prior;
    a given field that is wrong (here twice too fast everywhere) loses to them, the true one does not."""
    speeds = (0.4, 1.2, 3.6)
    opts = {"flows.speeds": speeds, "flows.refine_speeds": 0, "flows.given_wind_prior": 0.3}
    obs = draw_observations(case, 40, seed=2)
    weights = {}
    for told, wind in (("true", case.wind), ("too fast", 2.0 * case.wind)):
        k = Knowledge.from_case(replace(case, wind=wind), "wind")
        est = get_estimator("dgse-phys", knowledge=k, **opts)
        hyps = est.hypotheses()
        assert hyps[0].label == "given wind"
        assert [h.flow.inlet_velocity for h in hyps[1:]] == pytest.approx(speeds)
        assert hyps[0].prior == pytest.approx(0.3) and sum(h.prior for h in hyps) == pytest.approx(1.0)
        b = est.estimate(case.occupancy, case.resolution, obs)
        weights[told] = {h["label"]: h["weight"] for h in b.info["hypotheses"]}
        assert b.localization_error(tuple(case.source)) < 0.5
    # the true field (the RANS flow at 1.2 m/s made mass-conserving) keeps its weight
    assert weights["true"]["given wind"] + weights["true"]["v_in 1.2 m/s"] > 0.99
    assert weights["too fast"]["given wind"] < 0.01 and weights["too fast"]["v_in 1.2 m/s"] > 0.9
    # 1: the given field alone; the default shares the prior evenly
    k = Knowledge.from_case(case, "wind")
    alone = get_estimator("dgse-phys", knowledge=k, **{"flows.given_wind_prior": 1.0}).hypotheses()
    assert [h.label for h in alone] == ["given wind"]
    shared = get_estimator("dgse-phys", knowledge=k, **{"flows.speeds": speeds}).hypotheses()
    assert len(shared) == 4 and shared[0].prior == pytest.approx(FlowHypotheses().given_wind_prior) == 0.5
    with pytest.raises(InputDataError, match=r"flows\.given_wind_prior"):
        get_estimator("dgse-phys", **{"flows.given_wind_prior": 0.0})


def test_given_wind_without_openings_proposes_them_from_the_field(case):
    """Openings unknown at ``wind``: the RANS flows use the pair the field crosses the edge at,
    which on a built-in case are the true openings; the speed is refined as at ``openings``."""
    k = Knowledge("wind", case.occupancy, case.resolution, wind=case.wind, name="no openings")
    flows = FlowHypotheses(speeds=(0.4, 3.6), refine_speeds=1, refine_readings=10, given_wind_prior=0.5)
    est = get_estimator("dgse-phys", knowledge=k, flows=flows)
    hyps = est.hypotheses()
    layout = est._speed_layout
    assert layout is not None and len(hyps) == 3
    for found, true in ((layout.inlets, case.layout.inlets), (layout.outlets, case.layout.outlets)):
        assert [o.side for o in found] == [o.side for o in true]
        for a, b in zip(found, true, strict=True):
            assert abs(0.5 * (a.start_m + a.end_m) - 0.5 * (b.start_m + b.end_m)) <= 0.3
    obs = draw_observations(case, 40, seed=2)
    est.estimate(case.occupancy, case.resolution, obs)
    hyps = est.hypotheses()
    assert [h.flow.inlet_velocity for h in hyps[1:]] == pytest.approx([0.4, 1.2, 3.6])
    assert hyps[0].label == "given wind" and hyps[0].prior == pytest.approx(0.5)
    assert sum(h.prior for h in hyps) == pytest.approx(1.0)
    # a field that crosses the map's edge nowhere: the given field alone, and the belief says why
    still = Knowledge("wind", case.occupancy, case.resolution, wind=np.zeros_like(case.wind), name="still")
    alone = get_estimator("dgse-phys", knowledge=still, **{"flows.given_wind_prior": 0.5})
    assert len(alone.hypotheses()) == 1
    b = alone.estimate(case.occupancy, case.resolution, obs)
    assert "no openings found" in b.info["given_wind_note"]


def test_given_wind_survives_rans_flows_that_fail(case, monkeypatch):
    """The RANS flows beside a given field are a hedge: where they cannot be solved the field
    stands alone and the belief says so (no traceback)."""
    from dgse.errors import ConvergenceError
    from dgse.estimators import phys

    def fail(*_a, **_k):
        raise ConvergenceError("no convergence in 3 iterations")

    monkeypatch.setattr(phys, "flow_model", fail)
    est = get_estimator("dgse-phys", knowledge=Knowledge.from_case(case, "wind"))
    b = est.estimate(case.occupancy, case.resolution, draw_observations(case, 20, seed=1))
    assert [h["label"] for h in b.info["hypotheses"]] == ["given wind"]
    assert "no convergence" in b.info["given_wind_note"]


def test_map_level_proposes_openings_from_the_wind_readings(case):
    est = get_estimator("dgse-phys", knowledge=Knowledge.from_case(case, "map"), **{"flows.map_proposals": 3})
    obs = draw_observations(case, 40, seed=4)
    b = est.estimate(case.occupancy, case.resolution, obs)
    hyps = b.info["hypotheses"]
    assert len(hyps) == 3 and b.info["knowledge"] == "map"
    # two_rooms: inlet west 1.2-1.8 m, outlet east 0.2-0.8 m; the first proposal is the true pair
    assert hyps[0]["label"] == "in west 1.0-2.0 m, out east 0.0-1.0 m"
    assert sum(h["weight"] for h in hyps) == pytest.approx(1.0)
    assert b.localization_error(tuple(case.source)) < 1.0
    # the weights follow the hypotheses' wind and gas terms (at map the wind fit has a free scale)
    best = max(hyps, key=lambda h: h["weight"])
    assert best["wind_log_likelihood"] == max(h["wind_log_likelihood"] for h in hyps)
    # more of the same readings keep the proposals; other readings get their own (no leak across trials)
    first = est.hypotheses(obs)
    more = obs.concat(draw_observations(case, 10, seed=5))
    assert est.hypotheses(more) is first
    other = draw_observations(case, 40, seed=6)
    est.hypotheses(other)
    assert np.array_equal(est._proposed_from[0], other.cells)
    with pytest.raises(InputDataError, match="give readings"):
        est.hypotheses(None)


def test_map_proposals_are_checked():
    with pytest.raises(InputDataError, match=r"flows\.map_proposals must be an integer >= 1"):
        PhysicsGuidedEstimator(flows=FlowHypotheses(map_proposals=0))
    with pytest.raises(InputDataError, match=r"flows\.map_proposals"):
        get_estimator("dgse-phys", **{"flows.map_proposals": 1.5})


def test_wind_misfit_says_how_much_of_the_wind_the_flows_miss(case):
    u = np.array([[1.0, 0.0], [0.5, 0.5]])
    assert relative_wind_misfit(u, u) == 0.0
    assert relative_wind_misfit(np.zeros_like(u), u) == pytest.approx(1.0)
    assert relative_wind_misfit(0.5 * u, u) == pytest.approx(0.5)
    assert relative_wind_misfit(u, np.zeros_like(u)) == np.inf
    # the true openings explain the noiseless wind; a flow turned around does not
    drawn = draw_observations(case, 30, seed=3)
    true_wind = case.wind[:, drawn.cells[:, 0], drawn.cells[:, 1]].T
    obs = Observations(drawn.cells, drawn.gas, true_wind)
    k = Knowledge.from_case(case, "openings")
    right = get_estimator("dgse-phys", knowledge=k, **{"flows.speeds": (1.2,)})
    b = right.estimate(case.occupancy, case.resolution, obs)
    assert b.info["wind_misfit"] < 0.05
    turned = Observations(obs.cells, obs.gas, -obs.wind)
    assert right.estimate(case.occupancy, case.resolution, turned).info["wind_misfit"] > 1.0


def test_learned_belief_is_mixed_in_where_the_readings_are_few(case):
    """DGSE-S's weight is ``max(floor, weight * max(0, 1 - m / readings))``, weight and floor
    per knowledge level (:class:`NetworkFusion`)."""
    obs = draw_observations(case, 10, seed=7)
    k = Knowledge.from_case(case, "map")
    # the mixture's network draws FUSION_SAMPLES (it uses only the source posterior)
    K, T = FUSION_SAMPLES
    learned = get_estimator("dgse-s", seed=0, dtype="auto", channels_last=True, K=K, T=T)
    net = learned.estimate(case.occupancy, case.resolution, obs).source_probs
    only_net = get_estimator("dgse-phys", knowledge=k, **{"fusion.weight": 1.0, "fusion.readings": 1e9})
    b = only_net.estimate(case.occupancy, case.resolution, obs)
    assert b.info["learned_weight"] == pytest.approx(1.0)
    assert np.allclose(b.source_probs, net / net.sum(), atol=1e-7)
    opts = {"fusion.weight.map": 0.5, "fusion.readings": 20.0, "fusion.floor": 0.0}
    half = get_estimator("dgse-phys", knowledge=k, **opts)
    assert half.fusion.weight == PerLevel(map=0.5, openings=0.0, wind=0.0)
    assert half.estimate(case.occupancy, case.resolution, obs).info["learned_weight"] == pytest.approx(0.25)
    # past fusion.readings, or at a level of weight 0, the physics alone
    assert half._learned_weight(25) == 0.0
    half.set_knowledge(Knowledge.from_case(case, "openings"))
    assert half._learned_weight(5) == 0.0
    # a floor keeps the network in past fusion.readings, and only there
    floored = get_estimator("dgse-phys", knowledge=k, **{**opts, "fusion.floor": 0.1})
    assert floored._learned_weight(25) == pytest.approx(0.1)
    assert floored._learned_weight(10) == pytest.approx(0.25)
    with pytest.raises(InputDataError, match=r"fusion.floor must lie in \[0, 1\]"):
        get_estimator("dgse-phys", **{"fusion.floor": 1.5})
    # by default the network keeps the level's floor past fusion.readings; searches keep none
    default = get_estimator("dgse-phys", knowledge=k)
    floor = NetworkFusion().floor
    assert floor == PerLevel(map=0.05, openings=0.02, wind=0.02)
    assert default._learned_weight(400) == pytest.approx(floor.map)
    assert default._learned_weight(10) == pytest.approx(0.9 * (1 - 10 / 50))
    assert get_estimator("dgse-phys", knowledge=k, **SEARCH_ESTIMATOR)._learned_weight(400) == 0.0
    # at a level whose weight is 0 the weight is the level's floor alone, from the first reading
    default.set_knowledge(Knowledge.from_case(case, "wind"))
    assert default._learned_weight(3) == pytest.approx(floor.wind)
    default.set_knowledge(Knowledge.from_case(case, "openings"))
    assert default._learned_weight(3) == pytest.approx(floor.openings)
    assert get_estimator("dgse-phys", knowledge=k, **{"fusion.floor": 0.0})._learned_weight(400) == 0.0
    with pytest.raises(InputDataError, match=r"fusion.weight.plan; known: fusion.weight.map"):
        get_estimator("dgse-phys", **{"fusion.weight.plan": 0.5})


def test_a_map_the_network_cannot_take_leaves_the_physics_alone(case, monkeypatch):
    """Where DGSE-S refuses the map (its cell size), dgse-phys answers with the physics alone
    and says so, instead of failing."""
    k = Knowledge.from_case(case, "map")
    obs = draw_observations(case, 10, seed=7)
    est = get_estimator("dgse-phys", knowledge=k, **{"flows.map_proposals": 1})

    def refuse(*args, **kwargs):
        raise InputDataError("this dgse-s model works on 0.1 m cells or whole multiples of them")

    monkeypatch.setattr(est, "_learned_belief", refuse)
    b = est.estimate(case.occupancy, case.resolution, obs)
    assert b.info["learned_weight"] == 0.0 and "0.1 m cells" in b.info["learned_note"]
    assert np.isclose(b.source_probs.sum(), 1.0)


def test_predictive_sources_stand_for_the_whole_posterior():
    """Systematic draws: a thin broad region holding most of the mass gets most of the draws."""
    p = np.zeros(1000)
    p[:10] = 0.3 / 10  # a sharp peak, 30 %
    p[200:] = 0.7 / 800  # a broad region, 70 %
    idx, w = predictive_sources(p, 20)
    assert w.sum() == pytest.approx(1.0)
    # the quantiles 0.025, 0.075, ..., 0.975: 6 of 20 fall in the peak's 30 %, 14 in the rest
    assert w[idx < 10].sum() == pytest.approx(0.3)
    assert w[idx >= 200].sum() == pytest.approx(0.7)
    idx2, w2 = predictive_sources(p, 20)
    assert np.array_equal(idx, idx2) and np.array_equal(w, w2)  # deterministic
    one = np.zeros(50)
    one[7] = 1.0
    idx, w = predictive_sources(one, 8)
    assert idx.tolist() == [7] and w.tolist() == [1.0]


def test_inlet_speed_is_refined_between_the_candidates(case):
    """The true speed (1.2 m/s) lies between the candidates 0.4 and 3.6: refinement adds it."""
    k = Knowledge.from_case(case, "openings")
    est = get_estimator(
        "dgse-phys", knowledge=k, flows=FlowHypotheses(speeds=(0.4, 3.6), refine_speeds=2, refine_readings=10)
    )
    priors = [h.prior for h in est.hypotheses()]
    assert priors == pytest.approx([0.5, 0.5])
    obs = draw_observations(case, 40, seed=2)
    est.estimate(case.occupancy, case.resolution, draw_observations(case, 5, seed=2))
    assert len(est.hypotheses()) == 2  # too few readings to weigh the speeds
    est.estimate(case.occupancy, case.resolution, obs)
    speeds = [h.flow.inlet_velocity for h in est.hypotheses()]
    assert speeds == pytest.approx([0.4, 1.2, 3.6])  # the geometric mean of the two
    assert sum(h.prior for h in est.hypotheses()) == pytest.approx(1.0)
    b = est.estimate(case.occupancy, case.resolution, obs)
    w = {round(h["inlet_velocity"], 6): h["weight"] for h in b.info["hypotheses"]}
    assert w[1.2] > 0.9
    est.estimate(case.occupancy, case.resolution, obs)
    est.estimate(case.occupancy, case.resolution, obs)
    assert len(est.hypotheses()) == 4  # refine_speeds caps the additions
    fixed = get_estimator("dgse-phys", knowledge=k, **{"flows.speeds": (0.4, 3.6), "flows.refine_speeds": 0})
    fixed.estimate(case.occupancy, case.resolution, obs)
    assert len(fixed.hypotheses()) == 2
    with pytest.raises(InputDataError, match=r"flows\.refine_ratio"):
        get_estimator("dgse-phys", **{"flows.refine_ratio": 1.0})
    with pytest.raises(InputDataError, match=r"flows\.refine_speeds"):
        get_estimator("dgse-phys", **{"flows.refine_speeds": -1})


def test_levels_and_bad_input(case):
    est = get_estimator("dgse-phys")
    with pytest.raises(InputDataError, match="needs knowledge"):
        est.estimate(case.occupancy, case.resolution, draw_observations(case, 5, seed=0))
    with pytest.raises(InputDataError, match=r"flows\.speeds must be positive numbers"):
        get_estimator("dgse-phys", **{"flows.speeds": []})
    with pytest.raises(InputDataError, match=r"flows\.wind_noise_floor='x' must be a number"):
        get_estimator("dgse-phys", **{"flows.wind_noise_floor": "x"})
    with pytest.raises(InputDataError, match="flows must be a FlowHypotheses"):
        PhysicsGuidedEstimator(flows={"speeds": (1.0,)})


def test_speed_flows_are_warm_started_unless_told_otherwise(case):
    """Cold: each candidate speed is the flow ``dgse solve`` gives; warm starts are cached apart."""
    from dgse.posterior.adjoint import clear_flow_cache

    clear_flow_cache()
    k = Knowledge.from_case(case, "openings")
    opts = {"knowledge": k, "flows.speeds": (0.6, 1.2), "flows.refine_speeds": 0}
    cold = get_estimator("dgse-phys", **opts, **{"flows.warm_start": False}).hypotheses()
    assert [h.flow.info["warm_start"] for h in cold] == [None, None]
    assert cold[1].flow is flow_model(case.layout, 1.2)
    hot = get_estimator("dgse-phys", **opts).hypotheses()
    assert hot[1].flow.info["warm_start"] == pytest.approx(0.6)
    assert hot[1].flow is not cold[1].flow and flow_model(case.layout, 1.2).info["warm_start"] is None
    # the same flow to the solver's tolerance where the wind is strong
    assert np.allclose(hot[1].flow.wind, cold[1].flow.wind, atol=0.02 * np.abs(cold[1].flow.wind).max())


def test_field_variances_add_a_model_error_the_planner_leaves_out(case):
    """The belief's variances are the hypotheses' spread plus the model error; the spread alone
    (what readings reduce) is kept apart, and the utility planner sees only it."""
    from dgse.planning.planners import UtilityPlanner
    from dgse.posterior.mixture import field_error_variance

    k = Knowledge.from_case(case, "openings")
    obs = draw_observations(case, 30, seed=5)
    beliefs = []
    for fe in ((0, 0, 0, 0), (0.3, 0.05, 0.5, 0.2)):
        est = get_estimator(
            "dgse-phys", knowledge=k, **{"flows.speeds": (0.6, 1.2), "fields.model_error": fe}
        )
        beliefs.append(est.estimate(case.occupancy, case.resolution, obs))
    off, on = beliefs
    w_err, c_err = field_error_variance(on.wind_mean, on.log_conc_mean, (0.3, 0.05, 0.5, 0.2))
    assert np.allclose(w_err, 0.09 * (on.wind_mean**2).sum(axis=0) + 0.0025)
    assert np.allclose(on.wind_var, on.wind_var_reducible + w_err)
    assert np.allclose(on.log_conc_var, on.log_conc_var_reducible + c_err)
    assert np.array_equal(on.wind_var_reducible, off.wind_var)
    assert np.array_equal(off.wind_var, off.wind_var_reducible)
    assert (on.wind_var > off.wind_var).all()
    dist = np.where(case.free, 1.0, np.inf)
    planner = UtilityPlanner()
    assert np.array_equal(planner.utility(on, dist), planner.utility(off, dist))
    with pytest.raises(InputDataError, match=r"fields\.model_error must be four numbers"):
        get_estimator("dgse-phys", **{"fields.model_error": (0.1, -1, 0, 0)})
    assert PredictedFields().model_error.map == (0.15, 0.3, 0.1, 1.0)


def test_search_planner_at_map_declares_the_heaviest_disk_at_a_deadline():
    """A search's information planner stops on 95 % within 2 m at every level; at ``map`` a
    deadline stop declares the centre of the 1 m disk with the most mass, elsewhere the mean."""
    from dgse.planning.planners import get_planner

    assert PHYS.planner == "info"
    at_map = get_planner(PHYS.planner, **search_planner("map"))
    assert at_map.deadline.estimate_radius_m == pytest.approx(1.0)
    for level in ("openings", "wind"):
        planner = get_planner(PHYS.planner, **search_planner(level))
        assert planner.deadline.estimate_radius_m is None
        assert planner.stop.radius_m == at_map.stop.radius_m == 2.0
        assert planner.stop.level == at_map.stop.level == 0.95


def test_gas_evidence_tempering_follows_the_level_and_searches_keep_theirs(case):
    """The gas evidence's temperature follows the level's law: ``m / 100`` at ``openings``,
    ``sqrt(m / 18)`` at ``map``, so that 50 readings count as 30 and more count more; a search
    tempers as ``m / 100`` at ``map``, not at all at ``openings``, and as the level does at
    ``wind`` (the searches' own validation)."""
    defaults = GasEvidence()
    assert defaults.effective_readings == PerLevel(map=18.0, openings=100.0, wind=100.0)
    assert defaults.effective_growth == PerLevel(map=0.5, openings=0.0, wind=0.0)
    map_k = Knowledge.from_case(case, "map")
    at_map = get_estimator("dgse-phys", knowledge=map_k)
    assert at_map._readings_factor(150) == pytest.approx((150 / 18) ** 0.5)
    assert at_map._readings_factor(50) == pytest.approx(50 / 30)  # the calibration's 50 readings
    assert at_map._counted_readings(300) > at_map._counted_readings(150) > 30
    assert at_map._readings_factor(10) == 1.0 and at_map._counted_readings(10) == 10
    searching = get_estimator("dgse-phys", knowledge=map_k, **search_estimator("map"))
    assert searching._readings_factor(150) == pytest.approx(1.5)
    assert searching._counted_readings(300) == pytest.approx(100.0)
    at_openings = get_estimator("dgse-phys", knowledge=Knowledge.from_case(case, "openings"))
    assert at_openings._readings_factor(150) == pytest.approx(1.5)
    assert search_estimator("wind") == SEARCH_ESTIMATOR
    openings_k = Knowledge.from_case(case, "openings")
    searching = get_estimator("dgse-phys", knowledge=openings_k, **search_estimator("openings"))
    assert searching._readings_factor(300) == 1.0
    off = get_estimator("dgse-phys", knowledge=map_k, **{"evidence.effective_readings": float("inf")})
    assert off._readings_factor(300) == 1.0 and off._readings_factor(0) == 1.0
    for bad in (-0.1, 1.0):
        with pytest.raises(InputDataError, match=r"evidence\.effective_growth"):
            get_estimator("dgse-phys", **{"evidence.effective_growth": bad})
    with pytest.raises(InputDataError, match=r"evidence\.effective_readings must lie in"):
        get_estimator("dgse-phys", **{"evidence.effective_readings.map": 0.0})


def test_censored_tilt_must_be_booleans_and_follows_the_knowledge_level(case):
    """A switch given as text (``-p evidence.censored_tilt='"false"'``) would read as true:
    refused.  Off at ``map`` (where every measured search ran without it), on elsewhere; a value
    given holds at every level, or at the level named."""
    with pytest.raises(InputDataError, match=r"evidence\.censored_tilt must be true or false"):
        PhysicsGuidedEstimator(evidence=GasEvidence(censored_tilt="false"))
    with pytest.raises(InputDataError, match="censored_tilt='false' must be true or false"):
        get_estimator("dgse-phys", **{"evidence.censored_tilt": "false"})
    assert GasEvidence().censored_tilt == PerLevel(map=False, openings=True, wind=True)
    given = {None: {}, True: {"evidence.censored_tilt": True}, False: {"evidence.censored_tilt": False}}
    for level, want in (("map", False), ("openings", True), ("wind", True)):
        for value, opts in given.items():
            est = get_estimator("dgse-phys", knowledge=Knowledge.from_case(case, level), **opts)
            assert est.evidence.censored_tilt[level] is (want if value is None else value)
    only_map = get_estimator("dgse-phys", **{"evidence.censored_tilt.map": True})
    assert only_map.evidence.censored_tilt == PerLevel(map=True, openings=True, wind=True)


def test_a_weak_hypothesis_is_corrected_for_the_zeros_to_the_mixtures_precision(monkeypatch, factor_calls):
    """The zeros' correction of a hypothesis with a small share of the weight may leave out more
    of its own mass (``CENSORED_TAIL / share``): it integrates fewer candidates, and the mixture
    posterior stays where the full correction puts it."""
    from dgse.posterior import mixture as phys

    rng = np.random.default_rng(12)
    m, n = 40, 3000
    z_true = rng.exponential(1.0, m) * (rng.random(m) < 0.6)
    # every candidate explains the readings roughly (a broad posterior), the zeros tell them apart
    flows = []
    for k in range(2):
        A = (z_true / 2.0)[:, None] * rng.uniform(0.3, 1.7, (m, n))
        A[z_true == 0] = rng.exponential(0.02 * (k + 1), ((z_true == 0).sum(), n))
        A[:, 17] = z_true / 2.0  # the source: rate 2
        flows.append(A)
    z = np.maximum(z_true + rng.normal(0.0, 0.05, m), 0.0)
    z[z < 0.1] = 0.0
    z = np.where(z > 0, z + rng.normal(0.0, 0.3, m).clip(0.0), z)
    assert 5 < (z == 0).sum() < m
    evs = [adjoint_log_evidence(A, z, censored="deferred") for A in flows]
    log_ev = [e[0] for e in evs]
    details = [e[1] for e in evs]
    log_prior = [0.0, -6.0]  # the second hypothesis: about e^-6 of the weight

    counted = factor_calls
    runs = {}
    for cap in (phys.CENSORED_TAIL, phys.CENSORED_TAIL_MAX):  # the tail of every hypothesis, the default
        monkeypatch.setattr(phys, "CENSORED_TAIL_MAX", cap)
        counted.clear()
        out = phys.censor_zeros(list(log_ev), log_prior, details, 1.0)
        runs[cap] = (phys.mix_posteriors(out, log_prior)[0], sum(counted))
    (full, n_full), (cut, n_cut) = runs[phys.CENSORED_TAIL], runs[0.5]
    assert n_cut < n_full
    assert 0.5 * np.abs(full - cut).sum() < 1e-3
    assert int(np.argmax(cut)) == 17
