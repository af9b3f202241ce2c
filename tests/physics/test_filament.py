"""Filament dispersion (GADEN's model): mean field, mass balance, walls, intermittency, CLI.

The reference for the mean field is the analytic 2-D plume of a point source
in uniform flow along a straight channel, with the diffusivity the random walk
implies (``noise_std^2 dt / 2`` per axis plus ``gamma / 2`` from the filament
growth) and image sources for the channel walls.  The built-in steady solver
is compared only loosely: on recirculating flows its upwinded scheme is
diffusive enough to move the content of the recirculation zones by 10-20 %
(upwind vs limited linear upwind differ by 35 %), while the filaments have no
numerical diffusion.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.special import erf
from typer.testing import CliRunner

from dgse.cli.common import new_app
from dgse.cli.plume import register
from dgse.errors import InputDataError
from dgse.physics.constants import DEFAULT_PHYSICS
from dgse.physics.filament import (
    RECOMMENDED_MAX_FILAMENTS,
    FilamentSettings,
    face_velocities,
    make_filament_case,
    run_filaments,
    simulate_filaments,
)
from dgse.world.case import Case
from dgse.world.layout import Layout, Opening
from tests.conftest import two_rooms

RES = 0.1
PPM = DEFAULT_PHYSICS.ppm_per_gm3


def _channel(height: int = 20, width: int = 40, u: float = 0.5):
    """A straight channel: inlet the whole west side, outlet the whole east side, uniform wind."""
    occ = np.zeros((height, width), np.uint8)
    wind = np.zeros((2, height, width))
    wind[0] = u
    mask = np.zeros((height, width), bool)
    mask[:, 0] = mask[:, -1] = True
    return occ, wind, mask


def _plume_cells(x: float, q: float, u: float, var_rate: float, sigma0: float, src_y: float, height: float):
    """Analytic cell-averaged plume (ppm) across the channel at ``x`` m downstream, walls as images."""
    s = np.sqrt(sigma0**2 + var_rate * x / u) * np.sqrt(2.0)
    y0 = np.arange(round(height / RES)) * RES
    frac = np.zeros_like(y0)
    for k in range(-2, 3):
        for yk in (src_y + 2 * k * height, -src_y + 2 * k * height):
            frac += 0.5 * (erf((y0 + RES - yk) / s) - erf((y0 - yk) / s))
    return q / (DEFAULT_PHYSICS.slab_depth * u * RES) * frac * PPM


@pytest.fixture(scope="module")
def channel_run():
    occ, wind, mask = _channel()
    settings = FilamentSettings(
        release_rate=0.5,
        noise="constant",
        noise_std=0.3,
        sigma_max=None,
        warmup=10.0,
        duration=30.0,
        frame_dt=0.1,
    )
    return settings, run_filaments(occ, wind, (0.55, 1.05), settings, 0, mask)


# -- the mean field and the mass balance ---------------------------------------------------------
def test_time_mean_matches_the_analytic_plume(channel_run):
    settings, run = channel_run
    mean = run.frames.mean(axis=0)
    var_rate = settings.noise_std**2 * settings.step + settings.gamma  # 2 D_walk + gamma
    for j in (10, 15, 20, 25, 30, 35):  # 0.5 to 3 m downstream
        x = (j + 0.5) * RES - 0.55
        ref = _plume_cells(x, 0.5, 0.5, var_rate, settings.sigma0, 1.05, 2.0)
        assert mean[10, j] == pytest.approx(ref[10], rel=0.12), (j, mean[10, j], ref[10])
        assert np.abs(mean[:, j] - ref).sum() / ref.sum() < 0.1, j


def test_mass_balance(channel_run):
    settings, run = channel_run
    # every frame holds exactly the filaments in the air
    grams = run.frames.sum(axis=(1, 2), dtype=np.float64) * RES**2 * DEFAULT_PHYSICS.slab_depth / PPM
    np.testing.assert_allclose(grams, run.n_alive * run.filament_mass, rtol=1e-4)
    # at steady state the filaments leave as fast as they are released: outlet mass flux = q
    assert run.exit_rate() * run.filament_mass == pytest.approx(settings.release_rate, rel=0.05)
    # and the mass flux through every cross-section is q
    flux = run.frames.mean(axis=0).sum(axis=0) * RES * 0.5 * DEFAULT_PHYSICS.slab_depth / PPM
    np.testing.assert_allclose(flux[10:36], settings.release_rate, rtol=0.05)


def test_frames_are_intermittent(channel_run):
    _, run = channel_run
    mean = run.frames.mean(axis=0)
    std = run.frames.std(axis=0)
    cv = []
    for j in range(10, 36):
        col = mean[:, j]
        edge = (col > 0.05 * col.max()) & (col < 0.3 * col.max())
        cv.extend(std[edge, j] / col[edge])
    assert len(cv) > 20
    assert np.median(cv) > 0.3  # the plume edge flickers
    assert (run.frames[:, 10, 20] == 0).any() or np.ptp(run.frames[:, 10, 20]) > 0.3 * mean[10, 20]


# -- walls -----------------------------------------------------------------------------------------
def test_filaments_never_cross_or_enter_walls():
    occ, wind, mask = _channel(20, 40, u=3.0)
    occ[:, 20] = 1  # a wall across the whole channel: nothing may get past it
    wind = np.where(occ == 0, wind, 0.0)
    settings = FilamentSettings(
        release_rate=1.0, noise="constant", noise_std=0.5, warmup=5.0, duration=1.0, frame_dt=0.5
    )
    run = run_filaments(occ, wind, (0.55, 1.05), settings, 1, mask)
    x, y = run.positions.T
    assert run.positions.shape[0] > 100
    assert (x < 2.0).all()
    assert not occ[(y / RES).astype(int), (x / RES).astype(int)].any()
    assert (run.frames[:, :, 20:] == 0).all()  # no line of sight through the wall
    assert run.frames[:, :, 17:20].max() > 0


def test_filaments_stay_in_free_cells_of_a_room_layout():
    layout = two_rooms()
    occ = layout.occupancy
    wind = np.zeros((2, *occ.shape))
    wind[0] = 2.0
    wind[1] = -0.5
    wind = np.where(occ == 0, wind, 0.0)
    mask = layout.opening_mask("inlet") | layout.opening_mask("outlet")
    settings = FilamentSettings(
        release_rate=1.0, noise="constant", noise_std=1.0, warmup=5.0, duration=1.0, frame_dt=0.5, dt=0.5
    )
    run = run_filaments(occ, wind, (0.45, 1.25), settings, 2, mask)
    x, y = run.positions.T
    i, j = np.floor(y / RES).astype(int), np.floor(x / RES).astype(int)
    assert ((i >= 0) & (i < occ.shape[0]) & (j >= 0) & (j < occ.shape[1])).all()
    assert not occ[i, j].any()
    assert (x > 1.6).any()  # some went through the door
    assert (run.frames[:, occ == 1] == 0).all()


def test_well_mixed_gas_stays_well_mixed():
    """Uniform gas in a closed room with an eddy and a 50-fold range of eddy diffusivity stays uniform."""
    n = 20
    occ = np.zeros((n, n), np.uint8)
    occ[8:12, 6:14] = 1
    free = occ == 0
    yy, xx = (np.mgrid[0:n, 0:n] + 0.5) * RES
    wind = np.where(free, np.stack([-(yy - 1.0), xx - 1.0]), 0.0)  # 1 rad/s solid-body rotation
    nut = np.tile(np.linspace(0.001, 0.05, n), (n, 1))
    settings = FilamentSettings(
        release_rate=2e-3, filaments_per_second=1.0, warmup=10.0, duration=1.0, frame_dt=1.0, gamma=0.0
    )
    steady = np.where(free, 1000.0, 0.0)
    run = run_filaments(occ, wind, (0.35, 0.35), settings, 3, None, nut=nut, steady=steady)
    assert run.info["n_prefilled"] > 3000
    x, y = run.positions.T
    counts = np.zeros((n, n))
    np.add.at(counts, (np.floor(y / RES).astype(int), np.floor(x / RES).astype(int)), 1)
    assert counts[~free].sum() == 0
    blocks = counts.reshape(4, 5, 4, 5).sum(axis=(1, 3))
    whole = free.reshape(4, 5, 4, 5).all(axis=(1, 3))
    expected = counts.sum() / free.sum() * 25
    assert np.abs(blocks[whole] / expected - 1).max() < 4 / np.sqrt(expected)
    left, right = counts[:, : n // 2].sum(), counts[:, n // 2 :].sum()  # low D | high D
    assert left / right == pytest.approx(1.0, abs=0.06)


def test_uniform_gas_reads_uniform_up_to_the_walls():
    """Filament kernels fold back at walls: a uniform cloud of wide filaments reads uniform next to walls."""
    layout = two_rooms()
    occ = layout.occupancy
    free = occ == 0
    settings = FilamentSettings(
        release_rate=1e-3,
        filaments_per_second=1.0,
        noise="constant",
        noise_std=0.0,
        gamma=1.0,
        sigma_max=0.2,
        prefill_max_age=1e4,
        warmup=0.0,
        duration=1.0,
        frame_dt=1.0,
    )
    steady = np.where(free, 2000.0, 0.0)
    run = run_filaments(occ, np.zeros((2, *occ.shape)), (0.35, 0.35), settings, 4, None, steady=steady)
    frame = run.frames[0]
    near_wall = free.copy()
    near_wall[1:-1, 1:-1] &= ~(free[:-2, 1:-1] & free[2:, 1:-1] & free[1:-1, :-2] & free[1:-1, 2:])
    assert frame[near_wall].mean() == pytest.approx(2000.0, rel=0.03)
    assert frame[free].mean() == pytest.approx(2000.0, rel=0.02)


def test_max_filaments_caps_the_prefill_and_keeps_the_mass():
    """Over the cap, fewer and heavier filaments stand for the steady field; the release is unchanged."""
    layout = two_rooms()
    occ = layout.occupancy
    free = occ == 0
    settings = FilamentSettings(
        release_rate=1e-3, filaments_per_second=1.0, noise="constant", noise_std=0.0, gamma=1.0,
        sigma_max=0.2, prefill_max_age=1e4, warmup=0.0, duration=1.0, frame_dt=1.0,
    )  # fmt: skip
    steady = np.where(free, 2000.0, 0.0)
    args = (occ, np.zeros((2, *occ.shape)), (0.35, 0.35))
    full = run_filaments(*args, settings.with_(max_filaments=None), 4, None, steady=steady)
    capped = run_filaments(*args, settings.with_(max_filaments=400), 4, None, steady=steady)
    assert full.info["n_prefilled"] > 2000
    assert capped.info["n_prefilled"] == 400
    weight = capped.info["prefill_filament_weight"]
    assert weight == pytest.approx(full.info["n_prefilled"] / 400, rel=0.01)
    assert capped.filament_mass == full.filament_mass
    assert capped.info["n_released"] == full.info["n_released"]
    assert capped.frames[0][free].sum() == pytest.approx(steady.sum(), rel=0.01)
    assert capped.frames[0][free].mean() == pytest.approx(2000.0, rel=0.03)  # still uniform on average
    # a cap above the count changes nothing
    same = run_filaments(*args, settings.with_(max_filaments=10**7), 4, None, steady=steady)
    np.testing.assert_array_equal(same.frames, full.frames)
    with pytest.raises(InputDataError, match="max_filaments"):
        settings.with_(max_filaments=0)
    # capped unless asked otherwise: an uncapped quiet room can hold millions of filaments
    assert FilamentSettings().max_filaments == RECOMMENDED_MAX_FILAMENTS


def test_heavy_prefilled_filaments_leave_with_their_mass():
    """Capped prefill in a ventilated channel: every frame holds the mass of the filaments in the air."""
    occ, wind, mask = _channel(10, 30, u=0.5)
    settings = FilamentSettings(
        release_rate=0.05, noise="constant", warmup=0.0, duration=4.0, frame_dt=0.5, max_filaments=300
    )
    run = run_filaments(occ, wind, (0.55, 0.55), settings, 2, mask, steady=np.full(occ.shape, 500.0))
    w = run.info["prefill_filament_weight"]
    assert w > 2 and run.info["n_exited"] > 50  # heavy ones left through the outlet
    assert set(np.unique(run.weights)) == {1.0, w}
    grams = run.frames[-1].sum(dtype=np.float64) * RES**2 * DEFAULT_PHYSICS.slab_depth / PPM
    assert grams == pytest.approx(run.weights.sum() * run.filament_mass, rel=1e-4)


# -- the turbulent random walk on a RANS flow ------------------------------------------------------
def test_turbulent_mean_follows_the_builtin_steady_solution():
    from dgse.physics.builtin import BuiltinEngine
    from dgse.physics.engines import Source
    from dgse.physics.scenario import solution_to_cases

    layout = two_rooms()
    solution = BuiltinEngine().solve(layout, 1.0, [Source((0.75, 1.05), 0.5)])
    case = solution_to_cases(layout, 1.0, solution)[0]
    settings = FilamentSettings(warmup=10.0, duration=30.0, frame_dt=0.2)
    out = make_filament_case(case, settings, seed=5, nut=solution.flow.nut)
    assert out.frames is not None and out.frames.shape == (150, *case.occupancy.shape)
    assert out.meta["frame_dt"] == 0.2
    assert out.meta["filament"]["nut_source"] == "given"
    mean = out.frames.mean(axis=0)
    steady = case.concentration
    free = case.free
    assert np.corrcoef(mean[free], steady[free])[0, 1] > 0.95
    assert 0.85 < mean[free].sum() / steady[free].sum() < 1.4
    plume = free & (steady > 0.2 * steady.max())
    assert 0.8 < np.median(mean[plume] / steady[plume]) < 1.45
    np.testing.assert_array_equal(out.concentration, case.concentration)  # the steady field is kept


def test_face_velocities_are_divergence_free():
    layout = two_rooms()
    rng = np.random.default_rng(0)
    wind = np.where(layout.free, rng.normal(size=(2, *layout.occupancy.shape)), 0.0)
    mask = layout.opening_mask("inlet") | layout.opening_mask("outlet")
    ufx, ufy = face_velocities(layout.occupancy, wind, mask)
    div = (ufx[:, 1:] - ufx[:, :-1]) + (ufy[1:, :] - ufy[:-1, :])
    assert np.abs(div[layout.free]).max() < 1e-9
    # no flow through walls or closed edges
    assert (ufx[:, 1:-1][(layout.occupancy[:, 1:] + layout.occupancy[:, :-1]) > 0] == 0).all()
    assert (ufx[~mask[:, 0], 0] == 0).all() and (ufy[0, :] == 0).all() and (ufy[-1, :] == 0).all()


# -- determinism and input checks ------------------------------------------------------------------
def test_seeded_runs_are_deterministic():
    occ, wind, mask = _channel(10, 20)
    settings = FilamentSettings(release_rate=0.1, noise="constant", warmup=2.0, duration=1.0, frame_dt=0.5)
    a = simulate_filaments(occ, wind, (0.55, 0.55), settings, 7, mask)
    b = simulate_filaments(occ, wind, (0.55, 0.55), settings, np.random.default_rng(7), mask)
    c = simulate_filaments(occ, wind, (0.55, 0.55), settings, 8, mask)
    assert a.dtype == np.float32 and a.shape == (2, 10, 20)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_bad_inputs_raise_input_data_error():
    occ, wind, mask = _channel(10, 20)
    occ[5, 5] = 1
    wind = np.where(occ == 0, wind, 0.0)
    ok = FilamentSettings(release_rate=0.1, noise="constant", warmup=0.0, duration=0.5, frame_dt=0.5)
    with pytest.raises(InputDataError, match="wall"):
        run_filaments(occ, wind, (0.55, 0.55), ok, 0, mask)
    with pytest.raises(InputDataError, match="outside"):
        run_filaments(occ, wind, (5.0, 0.55), ok, 0, mask)
    for bad in ({"dt": 0.0}, {"dt": -0.1}, {"frame_dt": 0.0}, {"noise": "loud"}, {"sigma0": -1.0}):
        with pytest.raises(InputDataError):
            FilamentSettings(**bad)
    with pytest.raises(InputDataError, match="release_rate"):
        run_filaments(occ, wind, (0.25, 0.25), FilamentSettings(noise="constant"), 0, mask)
    with pytest.raises(InputDataError, match="nut"):
        run_filaments(occ, wind, (0.25, 0.25), ok.with_(noise="turbulent"), 0, mask)
    with pytest.raises(InputDataError, match="wind"):
        run_filaments(occ, wind[:, :5], (0.25, 0.25), ok, 0, mask)
    with pytest.raises(InputDataError, match="unknown"):
        FilamentSettings.from_dict({"dt": 0.1, "speed": 2})
    assert FilamentSettings.from_dict(ok.to_dict()) == ok


# -- the command -----------------------------------------------------------------------------------
def _channel_case(path) -> Case:
    occ, wind, _ = _channel(10, 20)
    layout = Layout(occ, (Opening("west", 0.0, 1.0),), (Opening("east", 0.0, 1.0),), name="channel")
    meta = {**layout.meta(), "name": "channel", "inlet_velocity": 0.5, "release_rate_gps": 0.2}
    case = Case(occ, wind, np.zeros(occ.shape), np.array([0.55, 0.55]), RES, meta)
    case.save(path)
    return case


def test_cli_writes_a_loadable_case_with_frames(tmp_path):
    app = new_app("dgse", "test")

    @app.callback()
    def _root() -> None:
        """Test app."""

    register(app)
    src, out = tmp_path / "in.npz", tmp_path / "out.npz"
    _channel_case(src)
    args = ["plume", str(src), "-o", str(out), "--duration", "2", "--frame-dt", "0.5", "--warmup", "3"]
    result = CliRunner().invoke(app, [*args, "--seed", "3", "--noise", "constant"])
    assert result.exit_code == 0, result.output
    case = Case.load(out)
    assert case.frames is not None and case.frames.shape == (4, 10, 20)
    assert case.meta["frame_dt"] == 0.5
    assert case.meta["filament"]["seed"] == 3
    assert case.meta["filament"]["settings"]["noise"] == "constant"
    assert case.frames.max() > 0
    json.dumps(case.meta)  # plain JSON
    again = tmp_path / "again.npz"
    args2 = [*args[:3], str(again), *args[4:]]
    assert CliRunner().invoke(app, [*args2, "--seed", "3", "--noise", "constant"]).exit_code == 0
    np.testing.assert_array_equal(Case.load(again).frames, case.frames)
    # user errors: one line, exit status 2
    bad = CliRunner().invoke(app, ["plume", str(tmp_path / "nope.npz"), "-o", str(out)])
    assert bad.exit_code == 2 and "error:" in bad.output
    bad = CliRunner().invoke(app, [*args, "--dt", "0", "--noise", "constant"])
    assert bad.exit_code == 2 and "dt" in bad.output


def test_an_unconverged_flow_is_refused_not_used():
    """nu_t of a flow that missed its tolerance, or a case whose flow did not converge, is an error."""
    from dgse.errors import ConvergenceError
    from dgse.physics.rans import FlowSettings

    occ, wind, _ = _channel(10, 20)
    layout = Layout(occ, (Opening("west", 0.0, 1.0),), (Opening("east", 0.0, 1.0),), name="channel")
    meta = {**layout.meta(), "name": "channel", "inlet_velocity": 0.5, "release_rate_gps": 0.2}
    case = Case(occ, wind, np.zeros(occ.shape), np.array([0.55, 0.55]), RES, meta)
    settings = FilamentSettings(warmup=0.0, duration=0.5, frame_dt=0.5)
    capped = FlowSettings(max_iterations=2, retry_relaxation=None, coarse_retry=False)
    with pytest.raises(ConvergenceError, match="did not converge in 2 iterations") as e:
        make_filament_case(case, settings, flow_settings=capped)
    assert 'noise="constant"' in str(e.value) and e.value.info["converged"] is False
    out = make_filament_case(case, settings)  # the same case, its flow solved to convergence
    assert out.meta["filament"]["nut_source"] == "builtin flow (converged)"
    with pytest.raises(ConvergenceError, match="flow_converged false"):
        make_filament_case(case.with_meta(flow_converged=False), settings.with_(noise="constant"))


def test_cli_refuses_a_case_whose_flow_did_not_converge(tmp_path):
    app = new_app("dgse", "test")

    @app.callback()
    def _root() -> None:
        """Test app."""

    register(app)
    src, out = tmp_path / "in.npz", tmp_path / "out.npz"
    _channel_case(src).with_meta(flow_converged=False).save(src)
    result = CliRunner().invoke(app, ["plume", str(src), "-o", str(out), "--noise", "constant"])
    assert result.exit_code == 2 and not out.exists()
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "did not converge" in errors[0] and "Traceback" not in result.output
