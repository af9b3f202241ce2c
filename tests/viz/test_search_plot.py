"""The search figure: the start, the openings and a colour bar in ppm, as the case figure draws them."""

from __future__ import annotations

import pytest
from matplotlib.colors import to_hex

from dgse.planning.planners import get_planner
from dgse.search.episode import run_episode
from dgse.viz.case import CONCENTRATION_LABEL, INLET_COLOR, OUTLET_COLOR
from dgse.viz.search import START_STYLE, plot_search_step
from tests.search import PeakEstimator, corridor_case


def test_search_figure_shows_start_openings_and_ppm():
    case = corridor_case().with_meta(
        inlets=[{"side": "west", "start_m": 0.2, "end_m": 0.8}],
        outlets=[{"side": "east", "start_m": 0.2, "end_m": 0.8}],
    )
    result = run_episode(
        case, PeakEstimator(adaptive=True), get_planner("utility"), start=(5, 3), time_limit=20.0, record=True
    )
    fig = plot_search_step(result, case)
    x0, y0 = case.grid.center_of(*result.start_cell)
    for ax in fig.axes[:3]:
        starts = [ln for ln in ax.lines if ln.get_marker() == START_STYLE["marker"]]
        assert len(starts) == 1
        assert (starts[0].get_xdata()[0], starts[0].get_ydata()[0]) == pytest.approx((x0, y0))
        colors = {to_hex(ln.get_color()) for ln in ax.lines}
        assert {INLET_COLOR, OUTLET_COLOR} <= colors  # the openings, drawn by the case figure's helper
    conc_bar = fig.axes[4]
    assert conc_bar.get_ylabel() == CONCENTRATION_LABEL
    labels = [t.get_text() for t in conc_bar.get_yticklabels()]
    assert labels[:2] == ["0", "1"]  # ppm values on the log(1 + c) scale
    legend = [t.get_text() for t in fig.legends[0].get_texts()]
    assert {"start", "inlet", "outlet"} <= set(legend)
