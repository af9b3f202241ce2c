"""Active gas source search with a simulated robot (paper Sec. III-D, V-D, App. D).

* :mod:`~dgse.search.robot`: the robot: moves, dwells, reads the Table I sensors, one clock;
* :mod:`~dgse.search.episode`: the search loop (Algorithm 1 for any estimator and planner);
* :mod:`~dgse.search.metrics`: success, error, ST, TD, step time, PER, aggregation;
* :mod:`~dgse.search.campaign`: many seeded trials over a set of cases (``dgse search``'s loop);

Example::

    from dgse.estimators import get_estimator
    from dgse.planning.planners import get_planner
    from dgse.search import run_episode, episode_metrics

    result = run_episode(case, get_estimator("dgse-s", model="dgse-s.safetensors"),
                         get_planner("utility"), rng=0)
    print(episode_metrics(result))
"""

from dgse.search.campaign import load_cases, run_trials, trial_seed
from dgse.search.episode import EpisodeResult, StepRecord, run_episode
from dgse.search.metrics import aggregate, episode_metrics, is_success, path_efficiency_ratio
from dgse.search.robot import Robot, random_start_cell

__all__ = [
    "EpisodeResult",
    "Robot",
    "StepRecord",
    "aggregate",
    "episode_metrics",
    "is_success",
    "load_cases",
    "path_efficiency_ratio",
    "random_start_cell",
    "run_episode",
    "run_trials",
    "trial_seed",
]
