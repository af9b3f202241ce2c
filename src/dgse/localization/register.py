"""Registry entries of the localization baselines (lazy ``"module:function"`` factories).

Importing this module registers them (names already taken are left alone, so
it is safe to import twice or after the registries learned the names some
other way).  Listing names never imports the heavy modules (numba kernels,
the flow solver): each factory is imported on first use.

Estimators (:func:`dgse.estimators.get_estimator`):

* ``adjoint``: adjoint Bayesian posterior with the wind fitted to the wind
  readings; knowledge ``openings`` or ``wind`` (it needs the openings):
  ``get_estimator("adjoint", knowledge=Knowledge.from_case(case, "openings"))``;
* ``adjoint-oracle``: the same with the true flow; knowledge ``wind`` (openings
  and inlet speed); the evaluation and search loops call ``set_knowledge``
  before each case's estimates;
* ``dualmode``: the dual-mode planner's particle filter (any level; map only);
* ``pmfs``: PMFS (any level; with the openings known, filaments leave only
  through them);
* ``grgsl``: GrGSL (any level; map only).

Planners (:func:`dgse.planning.planners.get_planner`): ``infotaxis``,
``entrotaxis``, ``dualmode``, ``pmfs``.
"""

from __future__ import annotations

from dgse.estimators.registry import estimator_names, register_estimator
from dgse.planning.planners import planner_names, register_planner

__all__ = ["ESTIMATORS", "PLANNERS", "register_all"]

#: Estimator name -> lazy factory.
ESTIMATORS: dict[str, str] = {
    "adjoint": "dgse.localization.adjoint:make_adjoint",
    "adjoint-oracle": "dgse.localization.adjoint:make_adjoint_oracle",
    "dualmode": "dgse.localization.particle_filter:ParticleFilterEstimator",
    "pmfs": "dgse.localization.pmfs:make_pmfs",
    "grgsl": "dgse.localization.grgsl:GrGSLEstimator",
}

#: Planner name -> lazy factory.
PLANNERS: dict[str, str] = {
    "infotaxis": "dgse.localization.infotaxis:make_infotaxis",
    "entrotaxis": "dgse.localization.infotaxis:make_entrotaxis",
    "dualmode": "dgse.localization.particle_filter:DualModePlanner",
    "pmfs": "dgse.localization.pmfs:PMFSPlanner",
}


def register_all() -> None:
    """Register every name of :data:`ESTIMATORS` and :data:`PLANNERS` not registered yet."""
    taken = set(estimator_names())
    for name, factory in ESTIMATORS.items():
        if name not in taken:
            register_estimator(name, factory)
    taken = set(planner_names())
    for name, factory in PLANNERS.items():
        if name not in taken:
            register_planner(name, factory)


register_all()
