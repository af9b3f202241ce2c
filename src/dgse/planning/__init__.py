"""Where the robot measures next and when a search stops: the planner interface.

* :mod:`~dgse.planning.paths`: the free-space move graph (shortest obstacle-free paths);
* :mod:`~dgse.planning.planners`: the :class:`~dgse.planning.planners.Planner` protocol,
  :class:`~dgse.planning.planners.SearchHistory` (what a planner may know), the paper's
  utility planner, the deadline stop (:class:`~dgse.planning.planners.Deadline`) and the
  planner registry;
* :mod:`~dgse.planning.information`: the information planner (``"info"``): what a reading
  would teach about the source, per second of travel and dwell.

The search loop (:mod:`dgse.search`) drives a planner; the planners of the baselines
live with their estimators in :mod:`dgse.localization`.
"""

from dgse.planning.paths import Cell, FreeSpaceGraph, graph_for
from dgse.planning.planners import (
    Planner,
    SearchHistory,
    UtilityPlanner,
    get_planner,
    planner_names,
    register_planner,
)

__all__ = [
    "Cell",
    "FreeSpaceGraph",
    "Planner",
    "SearchHistory",
    "UtilityPlanner",
    "get_planner",
    "graph_for",
    "planner_names",
    "register_planner",
]
