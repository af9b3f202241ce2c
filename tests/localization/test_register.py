"""The localization baselines through the registries, and short searches with each planner."""

from __future__ import annotations

import numpy as np
import pytest

from dgse.errors import InputDataError
from dgse.estimators import estimator_names, get_estimator
from dgse.localization.grgsl import GrGSLEstimator
from dgse.localization.particle_filter import DualModePlanner, ParticleFilterEstimator
from dgse.localization.pmfs import PMFSPlanner
from dgse.planning.planners import get_planner, planner_names
from dgse.search import run_episode
from tests.localization import channel_case


def test_baselines_are_registered() -> None:
    assert {"adjoint", "adjoint-oracle", "dualmode", "pmfs", "grgsl"} <= set(estimator_names())
    assert {"infotaxis", "entrotaxis", "dualmode", "pmfs", "utility"} <= set(planner_names())
    assert isinstance(get_estimator("grgsl"), GrGSLEstimator)
    assert isinstance(get_estimator("dualmode", n_particles=100), ParticleFilterEstimator)
    assert isinstance(get_planner("dualmode"), DualModePlanner)
    assert isinstance(get_planner("pmfs"), PMFSPlanner)
    with pytest.raises(InputDataError):
        get_planner("dualmode", no_such_option=1)


@pytest.mark.parametrize(
    ("estimator", "planner", "kwargs", "planner_kwargs"),
    [
        ("dualmode", "dualmode", {"n_particles": 200}, {}),
        ("adjoint-oracle", "infotaxis", {}, {}),
        ("grgsl", "entrotaxis", {"hit_threshold": 1.0}, {}),
        # a uniform posterior over this 1.6 x 3.6 m channel already has var x + var y < 1.5 m^2
        ("pmfs", "pmfs", {"params": {"hit_threshold_fraction": 0.05}}, {"stop_variance_m2": 0.05}),
    ],
)
def test_short_search(estimator: str, planner: str, kwargs: dict, planner_kwargs: dict) -> None:
    case = channel_case()
    # the oracle knows the flow (level wind); PMFS uses the openings when it is told them
    level = {"adjoint-oracle": "wind", "pmfs": "openings"}.get(estimator, "map")
    est = get_estimator(estimator, **kwargs)
    result = run_episode(
        case, est, get_planner(planner, **planner_kwargs), rng=0, time_limit=60.0, record=False,
        knowledge=level,
    )  # fmt: skip
    assert result.n_steps >= 2
    assert np.isfinite(result.error_m)
    cells = result.measurement_cells
    assert (case.occupancy[cells[:, 0], cells[:, 1]] == 0).all()
