"""Case and layout figures: panels, colorbars, markers; Agg only, no solver run."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.quiver import Quiver

from dgse.errors import InputDataError
from dgse.viz import plot_case, plot_layout
from dgse.world.case import Case
from dgse.world.generate import random_ood_layout
from dgse.world.layout import Layout, Opening


def _layout() -> Layout:
    """3 x 2.5 m, a wall with a gap, inlet west, outlet north."""
    occ = np.zeros((25, 30), np.uint8)
    occ[:15, 14:16] = 1
    return Layout(occ, (Opening("west", 1.0, 1.8),), (Opening("north", 2.0, 2.8),), name="tiny")


def _case(layout: Layout) -> Case:
    """Analytic fields: a uniform eastward wind and a Gaussian plume around the source."""
    X, Y = layout.grid.meshgrid()
    free = layout.free
    wind = np.stack([np.where(free, 1.0, 0.0), np.where(free, 0.2 * np.sin(X), 0.0)])
    src = (0.55, 0.55)
    ppm = np.where(free, 800.0 * np.exp(-((X - src[0]) ** 2 + (Y - src[1]) ** 2)), 0.0)
    meta = {
        "name": "tiny_src0",
        **layout.meta(),
        "inlet_velocity": 1.25,
        "release_rate_gps": 0.5,
        "solver": "analytic",
    }
    return Case(layout.occupancy, wind, ppm, src, layout.resolution, meta)


@pytest.fixture(scope="module")
def case() -> Case:
    return _case(_layout())


def test_plot_case_panels_colorbars_title(case, tmp_path):
    fig = plot_case(case)
    assert isinstance(fig, Figure) and isinstance(fig.canvas, FigureCanvasAgg)
    assert len(fig.axes) == 5  # 3 maps + 2 colorbars
    maps = fig.axes[:3]
    for ax in maps:
        assert ax.get_xlim() == pytest.approx((0, 3.0)) and ax.get_ylim() == pytest.approx((0, 2.5))
        assert ax.images and ax.images[0].origin == "lower"
        assert ax.images[0].get_extent() == pytest.approx([0, 3.0, 0, 2.5])
    title = fig.get_suptitle()
    assert "tiny_src0" in title and "1.25 m/s" in title and "0.5 g/s" in title
    labels = [ax.get_ylabel() for ax in fig.axes[3:]]
    assert "wind speed [m/s]" in labels and any("ppm" in s for s in labels)
    assert any(isinstance(c, Quiver) for c in maps[1].collections)
    # the source star on the layout and concentration panels
    for ax in (maps[0], maps[2]):
        assert any(ln.get_marker() == "*" for ln in ax.get_lines())
    # inlet/outlet bars on the boundary: one green and one red line per panel
    bars = [ln for ln in maps[0].get_lines() if ln.get_marker() != "*"]
    assert len(bars) == 2
    # solid cells are masked in the field panels
    assert np.ma.getmaskarray(maps[2].images[0].get_array())[5, 14]
    out = tmp_path / "case.png"
    fig.savefig(out, dpi=50)
    assert out.read_bytes()[:4] == b"\x89PNG"


def test_plot_case_without_arrows_and_into_given_axes(case):
    fig = plot_case(case, arrows=False)
    assert not any(isinstance(c, Quiver) for c in fig.axes[1].collections)
    user = Figure()
    axes = user.subplots(1, 3)
    assert plot_case(case, ax=axes) is user
    assert len(user.axes) == 5
    with pytest.raises(InputDataError, match="needs 3 matplotlib Axes"):
        plot_case(case, ax=axes[:2])


def test_plot_layout_single_and_many_openings(tmp_path):
    fig = plot_layout(_layout())
    assert isinstance(fig, Figure) and len(fig.axes) == 1
    assert "tiny" in fig.axes[0].get_title()
    ood = random_ood_layout(5)
    fig = plot_layout(ood)
    assert len(fig.axes) == 1
    assert len(fig.axes[0].get_lines()) == len(ood.inlets) + len(ood.outlets)
    fig.savefig(tmp_path / "layout.svg")
    user = Figure()
    ax = user.subplots()
    assert plot_layout(ood, ax=ax) is user
