"""The estimators by name: :data:`ESTIMATORS`, one :class:`~dgse.registry.Registry`.

Every estimator implements :class:`~dgse.belief.estimator.Estimator`
(``set_knowledge(knowledge)``, then ``estimate(occupancy, resolution,
observations) -> Belief``).  Built-in entries name their factories lazily, so
listing names imports nothing heavy (PyTorch for the DGSE networks); a package
adds its own through the ``dgse.estimators`` entry-point group
(:mod:`dgse.registry`).  Each entry carries the label, colour and marker every
figure and table shows the method with.
"""

from __future__ import annotations

from typing import Any

from dgse.belief.estimator import Estimator, EstimatorFactory
from dgse.belief.knowledge import Knowledge
from dgse.errors import UnsupportedError
from dgse.registry import Entry, Registry

__all__ = ["ESTIMATORS", "estimator_names", "get_estimator", "register_estimator"]

#: Every estimator: DGSE's own, the gas distribution mapping baselines (paper Sec. V-B),
#: the source localization baselines and the physics oracle (Sec. V-C, V-D).  Tags the
#: benchmarks size runs by: ``"gdm"`` a mapping method, ``"slow"`` seconds per estimate
#: (fewer trials and shorter searches), ``"flow-solves"`` flow solves per scenario before
#: its first estimate (one scenario in a quick run).
ESTIMATORS: Registry[Estimator] = Registry(
    "estimator",
    [
        Entry("dgse-s", "dgse.estimators.dgse:make_dgse_s", "DGSE-S", "#d62728", "o"),
        Entry(
            "dgse-phys",
            "dgse.estimators.phys:make_dgse_phys",
            "DGSE-phys",
            "#000080",
            "p",
            tags=("flow-solves",),
        ),
        Entry("dgse-p", "dgse.estimators.dgse:make_dgse_p", "DGSE-P", "#1f77b4", "s"),
        Entry("dgse-o", "dgse.estimators.dgse:make_dgse_o", "DGSE-O", "#2ca02c", "^"),
        Entry("kdmvw", "dgse.mapping.kernel:KernelDMVW", "KDM+V/W", "#9467bd", "v", tags=("gdm",)),
        Entry("kdmv", "dgse.mapping.kernel:KernelDMV", "KDM+V", "#c5b0d5", "v", tags=("gdm",)),
        Entry("ggmrf", "dgse.mapping.gmrf:GGMRF", "G-GMRF", "#17a2b8", "s", tags=("gdm",)),
        Entry("gwgmrf", "dgse.mapping.gwgmrf:GWGMRF", "GW-GMRF", "#6b8e23", "^", tags=("gdm",)),
        Entry("gabp", "dgse.mapping.gabp:GaBPPlus", "GaBP+", "#ff7f0e", "D", tags=("gdm",)),
        Entry(
            "dualmode",
            "dgse.localization.particle_filter:ParticleFilterEstimator",
            "Dual-mode PF",
            "#8c564b",
            "P",
        ),
        Entry("pmfs", "dgse.localization.pmfs:make_pmfs", "PMFS", "#e377c2", "X", tags=("slow",)),
        Entry("grgsl", "dgse.localization.grgsl:GrGSLEstimator", "GrGSL", "#bcbd22", "h"),
        Entry(
            "adjoint",
            "dgse.localization.adjoint:make_adjoint",
            "Adjoint (est. wind)",
            "#17becf",
            "*",
            tags=("flow-solves",),
        ),
        Entry(
            "adjoint-oracle",
            "dgse.localization.adjoint:make_adjoint_oracle",
            "Adjoint oracle (true wind)",
            "#7f7f7f",
            "*",
        ),
    ],
    group="dgse.estimators",
)


def register_estimator(
    name: str, factory: EstimatorFactory | str, *, replace: bool = False, **meta: Any
) -> None:
    """Register ``factory`` (a callable or ``"module:function"``) under ``name``
    (:meth:`dgse.registry.Registry.register`; ``meta``: label, colour, marker)."""
    ESTIMATORS.register(name, factory, replace=replace, **meta)


def estimator_names() -> list[str]:
    """The registered estimator names, sorted (plugins included)."""
    return ESTIMATORS.names()


def get_estimator(name: str, knowledge: Knowledge | None = None, **kwargs: Any) -> Estimator:
    """A new estimator ``name`` built with ``kwargs``, told ``knowledge`` if given.

    Raises:
        UnsupportedError: an unknown name (the message lists the known ones), an
            estimator whose dependencies are missing here, or one that does not
            implement :class:`~dgse.belief.estimator.Estimator`.
        InputDataError: an option the estimator does not take, or a value of
            the wrong type (:func:`dgse.options.check_options`).
        UnsupportedError: ``knowledge`` of a level the estimator does not work at.
    """
    est = ESTIMATORS.create(name, **kwargs)
    if not isinstance(est, Estimator):
        raise UnsupportedError(
            f"estimator {name!r} does not implement the Estimator protocol "
            "(derive it from dgse.belief.knowledge.KnowledgeUser and give it estimate())"
        )
    if knowledge is not None:
        est.set_knowledge(knowledge)
    return est
