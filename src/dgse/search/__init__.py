"""Active gas source search with a simulated robot (paper Sec. III-D, V-D, App. D).

* :mod:`~dgse.search.paths`: shortest obstacle-free paths on the free cells (Dijkstra);
* :mod:`~dgse.search.robot`: the robot: moves, dwells, reads the Table I sensors, one clock;
* :mod:`~dgse.search.planners`: the planner interface, the paper's utility planner, the registry;
* :mod:`~dgse.search.episode`: the search loop (Algorithm 1 for any estimator and planner);
* :mod:`~dgse.search.metrics`: success, error, ST, TD, step time, PER, aggregation;
* :mod:`~dgse.search.campaign`: many seeded trials over a set of cases (``dgse search``'s loop);
* :mod:`~dgse.search.animate`: figures and GIFs of an episode (imports matplotlib; not re-exported).

Example::

    from dgse.estimators import get_estimator
    from dgse.search import get_planner, run_episode, episode_metrics

    result = run_episode(case, get_estimator("dgse-s", model="dgse-s.safetensors"),
                         get_planner("utility"), rng=0)
    print(episode_metrics(result))
"""

from dgse.search.campaign import load_cases, run_trials, trial_seed
from dgse.search.episode import DEFAULT_TIME_LIMIT, EpisodeResult, StepRecord, run_episode
from dgse.search.metrics import aggregate, episode_metrics, is_success, path_efficiency_ratio
from dgse.search.paths import FreeSpaceGraph, graph_for
from dgse.search.planners import (
    Planner,
    SearchHistory,
    UtilityPlanner,
    get_planner,
    planner_names,
    register_planner,
)
from dgse.search.robot import Robot, random_start_cell

__all__ = [
    "DEFAULT_TIME_LIMIT",
    "EpisodeResult",
    "FreeSpaceGraph",
    "Planner",
    "Robot",
    "SearchHistory",
    "StepRecord",
    "UtilityPlanner",
    "aggregate",
    "episode_metrics",
    "get_planner",
    "graph_for",
    "is_success",
    "load_cases",
    "path_efficiency_ratio",
    "planner_names",
    "random_start_cell",
    "register_planner",
    "run_episode",
    "run_trials",
    "trial_seed",
]
