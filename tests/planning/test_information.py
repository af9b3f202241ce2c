"""The predictive of a reading, its information about the source, and the information planner."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
import pytest
from scipy import stats

from dgse.belief.belief import Belief, normalize_source_probs, uniform_probs
from dgse.belief.predictive import ReadingMixture, ReadingPredictive, lognormal_predictive
from dgse.errors import InputDataError
from dgse.planning.information import (
    InformationPlanner,
    InformationStop,
    InformationTerm,
    mass_near_point,
    reading_information,
)
from dgse.planning.paths import graph_for
from dgse.planning.planners import SearchHistory, get_planner
from dgse.posterior.adjoint import AdjointResponseModel, flow_model
from dgse.posterior.mixture import predictive_sources
from dgse.posterior.predictive import HypothesisPredictive
from dgse.presets import PROTOCOL
from dgse.search.metrics import SUCCESS_RADIUS_M
from dgse.sensing.noise import NoiseParams, gas_reading
from dgse.sensing.sensors import Observations
from tests.conftest import two_rooms


@functools.cache
def flows():
    """Two flows of the two-room layout (inlet speeds 0.6 and 2 m/s)."""
    return flow_model(two_rooms(), 0.6), flow_model(two_rooms(), 2.0)


def hypothesis_predictive(seed: int = 0) -> HypothesisPredictive:
    """A posterior over two flows and the sources of the left room, as dgse-phys forms it."""
    rng = np.random.default_rng(seed)
    fa, fb = flows()
    mesh = fa.mesh
    left = mesh.cells[:, 1] < 12
    srcs, shares, rates = [], [], []
    for _ in range(2):
        post = np.where(left, rng.gamma(0.3, size=mesh.n), 0.0)
        top, wts = predictive_sources(post / post.sum(), 24)
        srcs.append(top)
        shares.append(wts)
        rates.append(rng.uniform(0.2, 2.0, size=top.size))
    noise = AdjointResponseModel(fa, np.ones(mesh.n), sigma_floor=3.0, kappa=2.0, cbar=40.0)
    return HypothesisPredictive.from_posteriors([fa, fb], [0.3, 0.7], srcs, shares, rates, noise)


def test_reading_predictive_matches_its_monte_carlo_estimate():
    """Sources and flows drawn from the posterior, their readings simulated through the adjoint
    rows with the sensor's noise (Table I form with the likelihood's parameters): the zero
    share, mean, variance and histogram agree with the predictive to sampling error."""
    pred = hypothesis_predictive()
    # cells downwind of the sources, in the door and in clean air upwind
    cells = np.array([[12, 5], [10, 15], [4, 25], [15, 2]])
    mix = pred.at(cells)
    n = 40_000
    rng = np.random.default_rng(1)
    k = rng.choice(pred.weights.size, size=n, p=pred.weights)
    per_part = [p.sources.size for p in pred.parts]
    truth = np.empty((len(cells), n))
    offset = 0
    for part, size in zip(pred.parts, per_part, strict=True):
        sel = (k >= offset) & (k < offset + size)
        rows = part.flow.responses(cells)  # (C, n_free): the reading per g/s of each source
        j = k[sel] - offset
        truth[:, sel] = rows[:, part.sources[j]] * part.rates[j]
        offset += size
    sf, kappa, cbar = pred.noise.sigma_floor, pred.noise.kappa, pred.noise.cbar
    noise = NoiseParams(alpha_g=sf * kappa / cbar, sigma_env=sf, alpha_w=0.0, sigma_a_deg=0.0)
    z = gas_reading(truth, noise, rng)
    mean, var = mix.moments()
    zero = mix.zero_probability()
    se_zero = np.sqrt(zero * (1 - zero) / n) + 1e-4
    assert np.all(np.abs((z == 0).mean(axis=1) - zero) < 5 * se_zero)
    assert np.all(np.abs(z.mean(axis=1) - mean) < 5 * np.sqrt(var / n) + 1e-6)
    assert np.allclose(z.var(axis=1), var, rtol=0.06, atol=1e-3)
    assert zero[-1] > 0.45 and mean[0] > 10 * pred.noise.sigma_floor  # clean air / in the plume
    # histograms over the predictive's own bins
    P = mix.bin_probabilities(n_bins=10) @ mix.weights  # (C, 11)
    top = np.max(mix.mean + 3.0 * mix.sigma, axis=1)
    for c in range(len(cells)):
        edges = np.concatenate([[0.0], top[c] * np.arange(1, 10) / 10, [np.inf]])
        positive = z[c][z[c] > 0]
        hist = np.concatenate([[n - positive.size], np.histogram(positive, bins=edges)[0]]) / n
        assert np.allclose(hist, P[c], atol=5 * np.sqrt(P[c] * (1 - P[c]) / n) + 2e-3)
    # sampling the predictive itself gives the same moments
    own = mix.sample(n, np.random.default_rng(2))
    assert np.all(np.abs(own.mean(axis=1) - mean) < 5 * np.sqrt(var / n) + 1e-6)


def test_dgse_phys_belief_carries_a_predictive_whose_mean_is_its_concentration():
    """dgse-phys's belief answers the predictive itself: the components' mean reading is the
    belief's own predicted concentration (its reducible part, the model error left out), and
    the components' sources carry the posterior's mass."""
    from dgse.belief.knowledge import Knowledge
    from dgse.estimators.phys import NetworkFusion, PhysicsGuidedEstimator
    from dgse.evaluation.evaluate import draw_observations
    from dgse.physics.scenario import solve_cases
    from dgse.posterior.mixture import FlowHypothesis

    case = solve_cases(two_rooms(), 1.2, [((2.05, 0.55), 0.8)])[0]
    est = PhysicsGuidedEstimator(fusion=NetworkFusion(floor=0.0))
    est.set_knowledge(Knowledge.from_case(case, "openings"))
    fa, fb = flows()
    est._hypotheses = [FlowHypothesis("slow", fa, 0.5), FlowHypothesis("fast", fb, 0.5)]
    b = est.estimate(case.occupancy, case.resolution, draw_observations(case, 12, seed=3))
    assert isinstance(b.predictive, HypothesisPredictive)
    cells = np.argwhere(b.free)
    mix = b.reading_predictive(cells)
    assert mix.sources is not None
    conc = np.expm1(b.log_conc_mean + 0.5 * b.log_conc_var_reducible)[cells[:, 0], cells[:, 1]]
    assert np.allclose(mix.mean @ mix.weights, conc, rtol=1e-6, atol=1e-9)
    assert mix.sigma.min() >= b.info["noise_floor_ppm"] * (1 - 1e-12)
    near = mass_near_point(b, b.source_estimate(), 0.5)
    mass = np.zeros(b.source_probs.size)
    np.add.at(mass, mix.sources, mix.weights)
    assert (
        near > 0.5
        and mass_near_point(
            Belief(b.occupancy, b.resolution, normalize_source_probs(mass.reshape(b.shape), b.occupancy)),
            b.source_estimate(),
            0.5,
        )
        > 0.5
    )


def test_lognormal_predictive_of_a_belief_without_one():
    """A belief with only a log-concentration Gaussian (DGSE-S) predicts from it: the noise-free
    median is ``exp(m) - 1`` and, without noise, the moments are the lognormal's (the
    concentration clipped at 0 where ``L < 0``)."""
    occ = np.zeros((4, 5), np.uint8)
    m = np.linspace(2.0, 4.0, 20).reshape(4, 5)  # L < 0 (c < 0, clipped) is then negligible
    v = np.full((4, 5), 0.2)
    b = Belief(occ, 0.1, uniform_probs(occ), log_conc_mean=m, log_conc_var=v, info={"noise_floor_ppm": 1e-9})
    cells = np.argwhere(b.free)
    mix = b.reading_predictive(cells)
    assert mix.sources is None
    quiet = lognormal_predictive(m, v, cells, noise_floor_ppm=0.0, alpha=0.0, nodes=40)
    mean, var = quiet.moments()
    assert np.allclose(mean, b.conc_mean_ppm.reshape(-1), rtol=1e-6)
    assert np.allclose(var, b.conc_var_ppm.reshape(-1), rtol=1e-4)
    noisy_mean, noisy_var = mix.moments()  # Table I noise about the same concentrations
    assert (noisy_mean >= mean).all() and np.allclose(noisy_mean, mean, rtol=0.02)  # clipped noise
    assert (noisy_var > var).all()
    assert Belief(occ, 0.1, uniform_probs(occ)).reading_predictive(cells) is None


def test_information_is_zero_where_every_hypothesis_predicts_the_same_reading():
    rng = np.random.default_rng(0)
    K = 30
    w = rng.dirichlet(np.ones(K))
    sources = rng.integers(0, 10, size=K)
    same = np.tile(rng.uniform(0, 50, size=(4, 1)), (1, K))
    mix = ReadingMixture(w, same, 2.0 + 0.1 * same, sources)
    assert np.allclose(reading_information(mix), 0.0, atol=1e-12)
    # flows and sources that release nothing: every component reads the noise about 0
    pred = hypothesis_predictive()
    fa, fb = flows()
    silent = HypothesisPredictive.from_posteriors(
        [fa, fb],
        [0.5, 0.5],
        [p.sources for p in pred.parts],
        [p.weights for p in pred.parts],
        [np.zeros(p.sources.size) for p in pred.parts],
        pred.noise,
    )
    assert np.allclose(reading_information(silent.at(fa.mesh.cells)), 0.0, atol=1e-12)
    # where they differ it is positive, at most the source's entropy
    pred = hypothesis_predictive()
    near = pred.at(np.array([[12, 5]]))
    labels = np.unique(near.sources, return_inverse=True)[1]
    ps = np.bincount(labels, weights=near.weights)
    h_s = -(ps[ps > 0] * np.log(ps[ps > 0])).sum()
    info = reading_information(near)
    assert 0.3 < info[0] <= h_s


def test_information_agrees_with_a_monte_carlo_estimate():
    """The binned mutual information tends to ``E[log p(z | s) / p(z)]`` (Monte Carlo over the
    clipped Gaussians' densities) from below."""
    w = np.array([0.2, 0.3, 0.5])
    mu = np.array([[0.0, 4.0, 12.0]])
    sd = np.array([[2.0, 2.0, 3.0]])
    mix = ReadingMixture(w, mu, sd, np.array([0, 1, 2]))
    rng = np.random.default_rng(0)
    n = 200_000
    k = rng.choice(3, size=n, p=w)
    z = np.maximum(mu[0, k] + sd[0, k] * rng.standard_normal(n), 0.0)
    dens = np.where(
        z[:, None] > 0, stats.norm.pdf(z[:, None], mu[0], sd[0]), stats.norm.cdf(-mu[0] / sd[0])
    )  # (n, K): the density above 0, the clipped mass at 0
    mc = float(np.mean(np.log(dens[np.arange(n), k] / (dens @ w))))
    coarse, fine = reading_information(mix, n_bins=6)[0], reading_information(mix, n_bins=200)[0]
    assert coarse < fine
    assert fine == pytest.approx(mc, abs=0.01)


@dataclass
class FieldPredictive:
    """A hand-made predictive: component means per cell ``(H, W, K)``, one noise level."""

    mean: np.ndarray
    weights: np.ndarray
    sources: np.ndarray
    sigma: float = 1.0

    def at(self, cells: np.ndarray) -> ReadingMixture:
        mu = self.mean[cells[:, 0], cells[:, 1]]
        return ReadingMixture(self.weights, mu, np.full(mu.shape, self.sigma), self.sources)


def constructed_belief(strong: tuple[int, int], weak: tuple[int, int]) -> Belief:
    """A 7 x 7 room, two source candidates; every cell predicts the same reading for both but
    ``strong`` (far apart readings) and ``weak`` (slightly apart)."""
    occ = np.zeros((7, 7), np.uint8)
    mean = np.full((7, 7, 2), 5.0)
    mean[strong] = (0.0, 20.0)
    mean[weak] = (4.0, 6.0)
    probs = np.zeros((7, 7))
    probs[0, 0] = probs[6, 6] = 0.5
    pred = FieldPredictive(mean, np.array([0.5, 0.5]), np.array([0, 48]))
    assert isinstance(pred, ReadingPredictive)
    return Belief(occ, 0.5, probs, predictive=pred)


@pytest.mark.parametrize(("strong", "weak"), [((3, 0), (3, 6)), ((3, 6), (3, 0))])
def test_planner_prefers_the_more_informative_of_two_equidistant_cells(strong, weak):
    belief = constructed_belief(strong, weak)
    graph = graph_for(belief.occupancy, belief.resolution)
    robot = (3, 3)
    d = graph.distances_from(robot)
    assert d[strong] == d[weak]
    planner = InformationPlanner()
    assert planner.next_goal(belief, robot, d, SearchHistory(graph)) == strong
    scores = planner.last_scores["scores"]
    cells = [tuple(c) for c in planner.last_scores["cells"]]
    assert scores[cells.index(weak)] > 0 and scores[cells.index(strong)] > 2 * scores[cells.index(weak)]
    # per second: the same information nearer wins
    near = InformationPlanner()
    both = constructed_belief(strong, (3, 2))  # a weak cell one step from the robot
    s = near.scores(both, np.array([strong, (3, 2)]), d)
    i_strong, i_weak = near.information(both, np.array([strong, (3, 2)]))
    secs = d[strong] / PROTOCOL.speed + PROTOCOL.dwell, d[3, 2] / PROTOCOL.speed + PROTOCOL.dwell
    assert s == pytest.approx([i_strong / secs[0], i_weak / secs[1]])


def test_stop_fires_iff_the_mass_near_the_declared_point_reaches_its_level():
    rng = np.random.default_rng(0)
    occ = np.zeros((40, 40), np.uint8)
    occ[10:30, 20] = 1
    graph = graph_for(occ, 0.1)
    planner = InformationPlanner(stop=InformationStop(radius_m=1.0, level=0.8))
    seen = set()
    for _ in range(40):
        centres = rng.integers(0, 40, size=(rng.integers(1, 3), 2))
        ii, jj = np.mgrid[0:40, 0:40]
        p = sum(np.exp(-((ii - a) ** 2 + (jj - b) ** 2) / (2 * rng.uniform(1, 30) ** 2)) for a, b in centres)
        belief = Belief(occ, 0.1, normalize_source_probs(p, occ))
        x, y = belief.source_estimate()
        dist = np.hypot((jj + 0.5) * 0.1 - x, (ii + 0.5) * 0.1 - y)
        mass = float(belief.source_probs[dist <= 1.0].sum())
        history = SearchHistory(graph, step=5)
        stops = planner.should_stop(belief, history)
        assert stops == (mass >= 0.8)
        assert planner.stop_mass(belief) == pytest.approx(mass)
        seen.add(stops)
        assert not planner.should_stop(belief, SearchHistory(graph, step=4))  # min_observations
    assert seen == {True, False}
    # the deadline stops it whatever the mass
    flat = Belief(occ, 0.1, uniform_probs(occ))
    assert not planner.should_stop(flat, SearchHistory(graph, step=9, time_s=100.0, time_limit_s=2000.0))
    assert planner.should_stop(flat, SearchHistory(graph, step=9, time_s=1950.0, time_limit_s=2000.0))
    assert planner.deadline_reached(SearchHistory(graph, step=9, time_s=1950.0, time_limit_s=2000.0))


def test_settings_follow_the_protocol_and_are_checked():
    p = get_planner("info", **{"stop.level": 0.9, "info.n_bins": 12})
    assert isinstance(p, InformationPlanner) and p.stop.level == 0.9 and p.info.n_bins == 12
    assert InformationStop().radius_m == SUCCESS_RADIUS_M
    assert (InformationTerm().speed_m_s, InformationTerm().dwell_s) == (PROTOCOL.speed, PROTOCOL.dwell)
    bad = [{"stop.level": 0.0}, {"info.speed_m_s": -1.0}, {"info.n_bins": 0}, {"stop.radius_m": math.inf}]
    for options in bad:
        with pytest.raises(InputDataError):
            get_planner("info", **options)


def test_short_search_with_dgse_phys():
    from dgse.estimators.registry import get_estimator
    from dgse.search import run_episode
    from tests.localization import channel_case

    case = channel_case()
    est = get_estimator("dgse-phys", **{"fusion.floor": 0.0, "flows.speeds": (0.7, 1.4)})
    result = run_episode(
        case, est, get_planner("info"), rng=0, time_limit=120.0, record=False, knowledge="openings"
    )
    assert result.n_steps >= 5
    assert np.isfinite(result.error_m)
    cells = result.measurement_cells
    assert len({tuple(c) for c in cells}) == len(cells)  # never the same cell twice


def test_candidates_are_the_nearest_cells_and_a_random_rest():
    occ = np.zeros((20, 20), np.uint8)
    graph = graph_for(occ, 0.1)
    robot = (10, 10)
    d = graph.distances_from(robot)
    belief = Belief(occ, 0.1, uniform_probs(occ))
    readings = Observations(np.array([[10, 11]]), np.zeros(1), np.zeros((1, 2)))
    history = SearchHistory(graph, observations=readings, rng=np.random.default_rng(0))
    planner = InformationPlanner(info=InformationTerm(max_candidates=50, nearest=20))
    cells = planner.candidates(belief, robot, d, history)
    got = {tuple(c) for c in cells}
    assert len(cells) == 50 and len(got) == 50
    assert robot not in got and (10, 11) not in got  # neither the robot's cell nor a measured one
    dist = d[cells[:, 0], cells[:, 1]]
    nearest = np.sort(d[occ == 0])[2:22]  # the robot's and the measured cell left out
    assert np.sort(dist)[:20] == pytest.approx(nearest)
    assert dist.max() > 2 * nearest.max()  # the rest reach beyond the nearest ring
