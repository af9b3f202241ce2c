"""Registry entries of the GDM baselines: ``kdmv``, ``kdmvw``, ``ggmrf``, ``gwgmrf``, ``gabp``.

Each name maps to a lazy ``"module:Class"`` factory (the Estimator class
itself), so registering imports nothing heavy (numba and SciPy load when an
estimator is first built).  Importing this module registers them
(:func:`register`); factories take the class's keyword arguments, e.g.
``get_estimator("ggmrf", tuning="benchmarks/results/gdm_tuning.json", sigma_r=2.0)``.
"""

from __future__ import annotations

from dgse.estimators.registry import estimator_names, register_estimator

__all__ = ["GDM_ESTIMATORS", "register"]

#: Registry name -> lazy factory of every GDM baseline.
GDM_ESTIMATORS: dict[str, str] = {
    "kdmv": "dgse.mapping.kernel:KernelDMV",
    "kdmvw": "dgse.mapping.kernel:KernelDMVW",
    "ggmrf": "dgse.mapping.gmrf:GGMRF",
    "gwgmrf": "dgse.mapping.gwgmrf:GWGMRF",
    "gabp": "dgse.mapping.gabp:GaBPPlus",
}


def register(replace: bool = False) -> list[str]:
    """Register the GDM baselines; returns the names registered by this call.

    A name that is already registered (e.g. listed in the registry's built-ins,
    or registered by an earlier call) is left as it is unless ``replace``.
    """
    done = []
    taken = set(estimator_names())
    for name, factory in GDM_ESTIMATORS.items():
        if name in taken and not replace:
            continue
        register_estimator(name, factory, replace=replace)
        done.append(name)
    return done


register()
