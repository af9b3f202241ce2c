"""Symmetry augmentation: group laws, vector rotation, canvases, and solve/transform commutation."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from dgse.data.augment import (
    ALL_SYMMETRIES,
    SYMMETRIES,
    Symmetry,
    as_symmetry,
    compose,
    inverse,
    random_symmetry,
    transform_canvas,
    transform_case,
    transform_cells,
    transform_field,
    transform_input,
    transform_layout,
    transform_observations,
    transform_points,
    transform_sample,
    transform_targets,
    transform_vector_field,
    transform_vectors,
    transformed_shape,
)
from dgse.data.rasterize import canvas_shape_for, make_sample, rasterize, targets
from dgse.errors import InputDataError
from dgse.physics.builtin import BuiltinEngine
from dgse.physics.rans import FlowSettings
from dgse.physics.scenario import solve_cases
from dgse.sensing.sensors import random_observations
from dgse.world.grid import Grid
from dgse.world.layout import Opening
from tests.conftest import two_rooms
from tests.data.test_rasterize import boxed_case
from tests.sensing.test_sensors import synthetic_case

K = list(SYMMETRIES)  # the paper's six
K8 = list(ALL_SYMMETRIES)  # with the two diagonal reflections that close the group
SHAPE = (5, 8)  # non-square on purpose


def test_names_and_indices():
    assert [int(k) for k in SYMMETRIES] == [0, 1, 2, 3, 4, 5]
    assert as_symmetry(1) is Symmetry.ROT90 and as_symmetry("flip_x") is Symmetry.FLIP_X
    for bad in (8, -1, "rot45", True):
        with pytest.raises(InputDataError):
            as_symmetry(bad)
    rng = np.random.default_rng(0)
    assert {random_symmetry(rng) for _ in range(200)} == set(SYMMETRIES)


def test_group_laws():
    a = np.random.default_rng(0).normal(size=SHAPE)
    r = Symmetry.ROT90
    assert np.array_equal(
        transform_field(transform_field(transform_field(transform_field(a, r), r), r), r), a
    )  # rot90^4 = id
    assert compose(compose(r, r), compose(r, r)) is Symmetry.IDENTITY
    assert inverse(Symmetry.ROT90) is Symmetry.ROT270
    assert Symmetry.FLIP_X.inverse is Symmetry.FLIP_X
    assert compose(Symmetry.FLIP_X, Symmetry.FLIP_Y) is Symmetry.ROT180
    assert compose(Symmetry.FLIP_X, Symmetry.ROT90) is Symmetry.ANTI_TRANSPOSE  # not in the six
    for k in K8:
        assert compose(k, inverse(k)) is Symmetry.IDENTITY
        assert np.array_equal(transform_field(transform_field(a, k), inverse(k)), a)


@pytest.mark.parametrize(("k1", "k2"), list(itertools.product(K8, K8)))
def test_composition_matches_the_array_operations(k1, k2):
    rng = np.random.default_rng(1)
    a = rng.normal(size=(3, *SHAPE))
    w = rng.normal(size=(2, *SHAPE))
    k12 = compose(k1, k2)
    assert np.array_equal(transform_field(transform_field(a, k1), k2), transform_field(a, k12))
    np.testing.assert_allclose(
        transform_vector_field(transform_vector_field(w, k1), k2), transform_vector_field(w, k12)
    )
    H, W = SHAPE
    size = (W * 0.1, H * 0.1)
    p = rng.uniform(0, 1, size=(6, 2)) * size
    p1 = transform_points(p, k1, size)
    size1 = transform_points(np.array(size), k1, (0.0, 0.0))
    np.testing.assert_allclose(transform_points(p1, k2, np.abs(size1)), transform_points(p, k12, size))


def test_rot90_on_arrays_follows_the_convention():
    a = np.arange(6).reshape(2, 3)  # H=2 rows (y), W=3 columns (x)
    r = transform_field(a, Symmetry.ROT90)
    assert r.shape == (3, 2)
    for i, j in itertools.product(range(2), range(3)):
        assert r[j, 2 - 1 - i] == a[i, j]  # (i, j) -> (j, H - 1 - i)
    # a point to the east of the origin ends up north of it: (x, y) -> (H_m - y, x)
    np.testing.assert_allclose(transform_points([[0.25, 0.05]], Symmetry.ROT90, (0.3, 0.2)), [[0.15, 0.25]])
    assert transform_cells(np.array([[0, 2]]), Symmetry.ROT90, (2, 3)).tolist() == [[2, 1]]


@pytest.mark.parametrize(
    ("k", "expect"),
    [
        (Symmetry.IDENTITY, (1, 0)),
        (Symmetry.ROT90, (0, 1)),
        (Symmetry.ROT180, (-1, 0)),
        (Symmetry.ROT270, (0, -1)),
        (Symmetry.FLIP_X, (-1, 0)),
        (Symmetry.FLIP_Y, (1, 0)),
    ],
)
def test_uniform_wind_rotates_as_a_vector(k, expect):
    w = np.zeros((2, *SHAPE))
    w[0] = 1.0  # wind blowing east everywhere
    out = transform_vector_field(w, k)
    assert out.shape == (2, *transformed_shape(SHAPE, k))
    np.testing.assert_array_equal(out[0], expect[0])
    np.testing.assert_array_equal(out[1], expect[1])
    np.testing.assert_array_equal(transform_vectors(np.array([[1.0, 0.0]]), k), [expect])
    diag = transform_vectors(np.array([0.3, 0.4]), k)
    assert np.hypot(*diag) == pytest.approx(0.5)


@pytest.mark.parametrize("k", K8)
def test_fields_move_with_the_points(k):
    """A field sampled from a function equals that function moved by the transform."""
    g = Grid(SHAPE)
    X, Y = g.meshgrid()
    size = (g.width_m, g.height_m)
    f = np.sin(3 * X) + Y**2  # no symmetry of its own
    out = transform_field(f, k)
    g2 = Grid(transformed_shape(SHAPE, k))
    X2, Y2 = g2.meshgrid()
    back = transform_points(np.stack([X2, Y2], -1), inverse(k), (g2.width_m, g2.height_m))
    np.testing.assert_allclose(out, np.sin(3 * back[..., 0]) + back[..., 1] ** 2, atol=1e-12)
    # a radial field about the centre is equivariant; a vortex flips with reflections
    c = np.array(size) / 2
    radial = np.stack([X - c[0], Y - c[1]])
    vortex = np.stack([-(Y - c[1]), X - c[0]])
    c2 = np.array([g2.width_m, g2.height_m]) / 2
    radial2 = np.stack([X2 - c2[0], Y2 - c2[1]])
    vortex2 = np.stack([-(Y2 - c2[1]), X2 - c2[0]])
    np.testing.assert_allclose(transform_vector_field(radial, k), radial2, atol=1e-12)
    sign = round(np.linalg.det(k.matrix))  # +1 rotations, -1 reflections
    np.testing.assert_allclose(transform_vector_field(vortex, k), sign * vortex2, atol=1e-12)


def test_transform_layout_moves_the_openings():
    layout = two_rooms(30, 20)  # inlet west y in [1.2, 1.8], outlet east y in [0.2, 0.8]
    r = transform_layout(layout, Symmetry.ROT90)
    assert r.occupancy.shape == (30, 20)
    assert r.inlets == (Opening("south", 0.2, 0.8),)
    assert r.outlets == (Opening("north", 1.2, 1.8),)
    f = transform_layout(layout, Symmetry.FLIP_X)
    assert f.inlets == (Opening("east", 1.2, 1.8),) and f.outlets == (Opening("west", 0.2, 0.8),)
    f = transform_layout(layout, Symmetry.FLIP_Y)
    assert f.inlets == (Opening("west", 0.2, 0.8),) and f.outlets == (Opening("east", 1.2, 1.8),)
    for k in K8:
        t = transform_layout(layout, k)
        # the opening cells are the transformed opening cells
        for kind in ("inlet", "outlet"):
            np.testing.assert_array_equal(t.opening_mask(kind), transform_field(layout.opening_mask(kind), k))
        back = transform_layout(t, inverse(k))
        assert np.array_equal(back.occupancy, layout.occupancy)
        for o, o0 in zip(back.inlets + back.outlets, layout.inlets + layout.outlets, strict=True):
            assert o.side == o0.side
            assert (o.start_m, o.end_m) == pytest.approx((o0.start_m, o0.end_m), abs=1e-9)


@pytest.mark.parametrize("k", K)
def test_transform_case(k):
    case = synthetic_case(frames=2)
    t = transform_case(case, k)
    H2, W2 = transformed_shape(case.occupancy.shape, k)
    assert t.occupancy.shape == (H2, W2) and t.frames is not None
    assert t.frames.shape == (2, H2, W2)
    new_cell = transform_cells(np.array([case.source_cell]), k, case.occupancy.shape)[0]
    assert t.source_cell == tuple(new_cell)
    assert t.concentration[t.source_cell] == case.concentration[case.source_cell]
    assert (t.meta["width_m"], t.meta["height_m"]) == (t.grid.width_m, t.grid.height_m)
    assert t.meta["symmetry"] == k.name.lower()
    assert t.layout.inlets == transform_layout(case.layout, k).inlets  # meta openings follow
    back = transform_case(t, inverse(k))
    assert back.meta["symmetry"] == "identity"
    for f in ("occupancy", "wind", "concentration", "frames"):
        np.testing.assert_array_equal(getattr(back, f), getattr(case, f))
    np.testing.assert_allclose(back.source, case.source, atol=1e-6)


@pytest.mark.parametrize("k", K)
@pytest.mark.parametrize("shape", [(20, 30), (150, 50)])
def test_canvas_transform_commutes_with_rasterization(k, shape):
    case = synthetic_case() if shape == (20, 30) else boxed_case(*shape)
    obs = random_observations(case, 30, np.random.default_rng(int(k)))
    S = canvas_shape_for(shape)
    sample = make_sample(case, obs, S)
    ts = transform_sample(sample, k)
    tcase = transform_case(case, k)
    tobs = transform_observations(obs, k, shape)
    assert ts.map_shape == tcase.occupancy.shape
    np.testing.assert_array_equal(ts.inputs, rasterize(tcase.occupancy, tobs, S))
    tt = targets(tcase, S)
    np.testing.assert_array_equal(ts.targets.wind, tt.wind)
    np.testing.assert_array_equal(ts.targets.log_concentration, tt.log_concentration)
    np.testing.assert_array_equal(ts.targets.source, tt.source)
    np.testing.assert_array_equal(ts.targets.valid, tt.valid)
    assert ts.targets.source_index == tt.source_index
    # observations still sit on free cells of the transformed map
    assert np.all(tcase.free[tobs.cells[:, 0], tobs.cells[:, 1]])


@pytest.mark.parametrize("k", K)
def test_canvas_inverse_is_exact_including_padding(k):
    rng = np.random.default_rng(2)
    a = rng.normal(size=(5, 100, 100))
    map_shape = (20, 30)
    t = transform_input(a, k, map_shape)
    back = transform_input(t, inverse(k), transformed_shape(map_shape, k))
    np.testing.assert_array_equal(back, a)
    # map cells land at the lower-left corner
    m = np.zeros((100, 100), bool)
    m[:20, :30] = True
    tm = transform_canvas(m, k, map_shape)
    H2, W2 = transformed_shape(map_shape, k)
    assert tm[:H2, :W2].all() and tm.sum() == 600
    tg = transform_targets(targets(synthetic_case(), (100, 100)), k, map_shape)
    assert tg.valid[:H2, :W2].all() and tg.valid.sum() == 600


def test_observation_transform_rotates_wind_readings():
    case = synthetic_case()
    obs = random_observations(case, 10, np.random.default_rng(0))
    t = transform_observations(obs, Symmetry.ROT90, case.occupancy.shape)
    np.testing.assert_allclose(t.wind, np.stack([-obs.wind[:, 1], obs.wind[:, 0]], 1))
    np.testing.assert_array_equal(t.gas, obs.gas)


# -- the physics is invariant: transform-then-solve equals solve-then-transform ----------
@pytest.fixture(scope="module")
def engine() -> BuiltinEngine:
    return BuiltinEngine(settings=FlowSettings(tolerance=1e-5))


@pytest.fixture(scope="module")
def solved(engine):
    layout = two_rooms()
    src = ((0.55, 1.25), 0.8)  # left room, cell (12, 5)
    return layout, src, solve_cases(layout, 1.5, [src], engine)[0]


@pytest.mark.parametrize("k", [k for k in K if k is not Symmetry.IDENTITY])
def test_solving_commutes_with_the_symmetry(solved, engine, k):
    layout, (xy, q), case = solved
    expect = transform_case(case, k)
    t_layout = transform_layout(layout, k)
    np.testing.assert_array_equal(t_layout.occupancy, expect.occupancy)
    t_src = transform_points(np.array(xy), k, (layout.grid.width_m, layout.grid.height_m))
    got = solve_cases(t_layout, 1.5, [(tuple(t_src), q)], engine)[0]
    assert got.source_cell == expect.source_cell
    err_w = np.linalg.norm(got.wind - expect.wind) / np.linalg.norm(expect.wind)
    err_c = np.abs(np.log1p(got.concentration) - np.log1p(expect.concentration)).max()
    assert err_w < 1e-2, err_w
    assert err_c < 0.05, err_c
