"""Scenario sets and variants the benchmark scripts of ``benchmarks/`` share.

* :func:`parse_seeds`: ``"2000-2019"`` or ``"900-911,2005"`` as a list of seeds;
* :data:`SEARCH_SETS` and :func:`search_cases`: the generated validation and test scenarios
  of the ``dgse-phys`` searches and diagnostics, as case files made once;
* :func:`office_floor_cases`: generated office floors (20-30 m, building scale), as case files
  made once;
* :func:`gaden_cases`: generated scenarios written as GADEN scenario folders and imported
  back through ``dgse import-gaden-scenario``'s library function, as case files made once;
* :func:`walled_case`: a scenario with walls drawn at the map's edge and its openings dropped,
  a closed slice as an imported GADEN scenario is;
* :data:`VARIANTS`, :func:`perturbed_wind`, :func:`variant_case` and :class:`ToldWind`: the
  physics made wrong in one way at a time (filament readings; a wind told at knowledge
  ``wind`` rotated, smoothed or too fast) for the robustness measurements.

Seed ranges: 900-963 are kept for validation (tuning), 2000-2019 for testing (never tuned
on), 3000 on for the office floors, 4000 on for the GADEN-format scenarios.
"""

from __future__ import annotations

import math
import os
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from dgse.errors import ConvergenceError, InputDataError
from dgse.files import write_text
from dgse.world.case import Case

__all__ = [
    "FLOOR_FIRST_SEED",
    "GADEN_FIRST_SEED",
    "SEARCH_SETS",
    "VARIANTS",
    "WIND_VARIANTS",
    "ToldWind",
    "gaden_cases",
    "office_floor_cases",
    "parse_seeds",
    "perturbed_wind",
    "search_cases",
    "variant_case",
    "walled_case",
]

#: The generated scenario sets of the searches, by seed: ``validation`` (the range the
#: dgse-phys parameters were tuned on), ``validation2`` and ``validation3`` (more validation
#: scenarios, for rare failures), ``test`` (never used for tuning).
SEARCH_SETS: dict[str, range] = {
    "validation": range(900, 908),
    "validation2": range(908, 924),
    "validation3": range(924, 964),
    "test": range(2000, 2020),
}
#: The seed of the first office floor.
FLOOR_FIRST_SEED = 3000
#: The seed of the first generated scenario written in GADEN's format and imported back.
GADEN_FIRST_SEED = 4000
#: The robustness variants: the scenario as generated, filament readings, and the wind told
#: at knowledge ``wind`` rotated by 20 degrees, smoothed over 3 cells or twice too fast.
VARIANTS = ("steady", "filament", "wind_rotated", "wind_smoothed", "wind_x2")
#: The variants that change only the wind told at knowledge ``wind``.
WIND_VARIANTS = tuple(v for v in VARIANTS if v.startswith("wind_"))


def parse_seeds(text: str) -> list[int]:
    """``"2000-2019"``, ``"2000,2003"`` or ``"900-911,2005"`` -> the seeds, in order.

    Raises:
        InputDataError: the text is no list of seeds or ranges.
    """
    seeds: list[int] = []
    try:
        for part in text.split(","):
            lo, _, hi = part.strip().partition("-")
            first, last = int(lo), int(hi or lo)
            if last < first:
                raise ValueError(part)
            seeds += list(range(first, last + 1))
    except ValueError:
        raise InputDataError(f"seeds must look like 2000-2019 or 2000,2003, got {text!r}") from None
    return seeds


def search_cases(out: str | os.PathLike[str], name: str, limit: int | None = None) -> Path:
    """The scenarios of set ``name`` (:data:`SEARCH_SETS`; the first ``limit``) as case files in
    ``out/_cases_<name>/`` (``_cases_<name>_<n>/`` with a limit), made once: one random
    training-distribution layout and source per seed, solved with the built-in solver.  A seed
    whose flow does not converge is left out with a ``.unconverged`` note beside the cases, as
    the dataset generator leaves such layouts out.  Files are named ``<set><seed>_src0.npz``
    with the set's name without its digits (``validation924_src0.npz``, ``test2005_src0.npz``)."""
    from dgse.physics.scenario import random_cases

    if name not in SEARCH_SETS:
        raise InputDataError(f"unknown scenario set {name!r}; the sets are {', '.join(SEARCH_SETS)}")
    seeds = list(SEARCH_SETS[name])[:limit]
    d = Path(out) / (f"_cases_{name}" if limit is None else f"_cases_{name}_{len(seeds)}")
    d.mkdir(parents=True, exist_ok=True)
    for seed in seeds:
        path = d / f"{name.rstrip('0123456789')}{seed}_src0.npz"
        skip = path.with_suffix(".unconverged")
        if path.exists() or skip.exists():
            continue
        try:
            random_cases(seed, n_sources=1)[0].save(path)
        except ConvergenceError as e:
            write_text(skip, f"{e}\n")
    return d


def office_floor_cases(
    out: str | os.PathLike[str],
    n: int,
    resolution: float = 0.2,
    size: tuple[float, float] = (20.0, 30.0),
) -> Path:
    """The first ``n`` office-floor scenarios as case files in ``out/_cases_<resolution>m/``,
    made once: per seed from :data:`FLOOR_FIRST_SEED`, a random office floor
    (:func:`dgse.world.building.random_office_floor`, sides drawn from ``size`` m, cells of
    ``resolution`` m), a random inlet speed of the training range and one random source,
    solved with the built-in solver.  Files are named ``building<seed>_src0.npz``."""
    from dgse.physics.scenario import solve_cases
    from dgse.world.building import random_office_floor
    from dgse.world.generate import as_generator, random_inlet_velocity, random_sources

    d = Path(out) / f"_cases_{resolution:g}m"
    d.mkdir(parents=True, exist_ok=True)
    for seed in range(FLOOR_FIRST_SEED, FLOOR_FIRST_SEED + n):
        path = d / f"building{seed}_src0.npz"
        if path.exists():
            continue
        rng = as_generator(seed)
        layout = random_office_floor(rng, resolution=resolution, width_range=size, height_range=size)
        v = random_inlet_velocity(rng)
        src = random_sources(layout, rng, n=1)
        solve_cases(layout, v, src, name=path.stem)[0].save(path)
    return d


def gaden_cases(out: str | os.PathLike[str], n: int) -> Path:
    """The first ``n`` GADEN-format scenarios as case files in ``out/_cases_gaden/``, made once:
    per seed from :data:`GADEN_FIRST_SEED`, a random training-distribution layout and source
    solved with the built-in solver (as :func:`search_cases` makes them), written as a GADEN
    scenario folder ``out/_gaden/gaden<seed>/`` (:func:`dgse.data.gaden_scenario.export_gaden_scenario`:
    ROS map, one outlet model per opening, the simulation with the source, the wind as a CSV)
    and imported back with :func:`dgse.data.gaden_scenario.import_gaden_scenario`, solved again
    with the built-in solver (inlets and outlets and the inlet speed from the wind file; the
    generated release rate).  A seed whose flow does not converge (generated or imported) is
    left out with a ``.unconverged`` note, as :func:`search_cases` does.  Files are named
    ``gaden<seed>_src0.npz``."""
    from dgse.data.gaden_scenario import export_gaden_scenario, import_gaden_scenario
    from dgse.physics.scenario import random_cases

    d = Path(out) / "_cases_gaden"
    d.mkdir(parents=True, exist_ok=True)
    for seed in range(GADEN_FIRST_SEED, GADEN_FIRST_SEED + n):
        path = d / f"gaden{seed}_src0.npz"
        skip = path.with_suffix(".unconverged")
        if path.exists() or skip.exists():
            continue
        folder = Path(out) / "_gaden" / f"gaden{seed}"
        try:
            case = random_cases(seed, n_sources=1)[0]
            export_gaden_scenario(case, folder)
            import_gaden_scenario(
                folder, path, solve=True, release_rate=case.release_rate, resolution=case.resolution
            )
        except ConvergenceError as e:
            write_text(skip, f"{e}\n")
    return d


def walled_case(case: Case) -> Case:
    """``case`` with every cell on the map's edge solid (wind and gas 0 there) and no openings
    or inlet speed in its ``meta``: a closed slice, as an imported GADEN scenario is.  The air
    that crossed the old openings now enters and leaves through the slice beside them (the
    wind's divergence there, :mod:`dgse.physics.projection`); the gas is the case's own.

    Raises:
        InputDataError: a source on the map's edge.
    """
    occ = case.occupancy.copy()
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = 1
    solid = occ != 0
    i, j = case.source_cell
    if solid[i, j]:
        raise InputDataError(f"the source of {case.name!r} lies on the map's edge: no walled case")
    frames = None if case.frames is None else np.where(solid[None], 0.0, case.frames)
    dropped = ("inlet", "inlets", "outlet", "outlets", "inlet_velocity", "walls", "layout")
    meta = {k: v for k, v in case.meta.items() if k not in dropped}
    meta["name"] = f"{case.name}_walled"
    return replace(
        case,
        occupancy=occ,
        wind=np.where(solid[None], 0.0, case.wind),
        concentration=np.where(solid, 0.0, case.concentration),
        frames=frames,
        meta=meta,
    )


def perturbed_wind(case: Any, variant: str) -> np.ndarray:
    """The wind told at knowledge ``wind`` in ``variant`` (:data:`VARIANTS`), ``(2, H, W)``, of a
    :class:`~dgse.world.case.Case` or a :class:`~dgse.belief.knowledge.Knowledge` with a wind:
    ``wind_rotated`` turns every vector by 20 degrees, ``wind_smoothed`` averages it with a
    Gaussian of 3 cells over the free cells, ``wind_x2`` doubles it; the others leave the
    wind as it is.  Solid cells stay at rest."""
    from scipy import ndimage

    u = np.asarray(case.wind, dtype=np.float64)
    free = case.occupancy == 0
    if variant == "wind_rotated":
        a = math.radians(20.0)
        out = np.stack([math.cos(a) * u[0] - math.sin(a) * u[1], math.sin(a) * u[0] + math.cos(a) * u[1]])
    elif variant == "wind_smoothed":
        w = ndimage.gaussian_filter(free.astype(float), 3.0)
        out = np.stack([ndimage.gaussian_filter(c * free, 3.0) / np.maximum(w, 1e-6) for c in u])
    elif variant == "wind_x2":
        out = 2.0 * u
    elif variant in VARIANTS:
        return u
    else:
        raise InputDataError(f"unknown variant {variant!r}; the variants are {', '.join(VARIANTS)}")
    return np.where(free[None], out, 0.0)


def variant_case(
    case: Case, variant: str, cache: str | os.PathLike[str], tag: str, settings: Any = None
) -> Case:
    """The scenario the readings of ``variant`` come from: ``case``, or for ``filament`` the
    case with the frames of a filament simulation (``dgse plume``'s simulator, seed 0, with
    ``settings``, a :class:`~dgse.physics.filament.FilamentSettings`; None: its defaults), made
    once into ``cache/<tag>_filament.npz`` (a tag names one setting: a file that exists is
    reused whatever the settings)."""
    if variant != "filament":
        return case
    path = Path(cache) / f"{tag}_filament.npz"
    if not path.exists():
        from dgse.physics.filament import FilamentSettings, make_filament_case

        make_filament_case(case, FilamentSettings() if settings is None else settings, seed=0).save(path)
    return Case.load(path)


class ToldWind:
    """An estimator told, at knowledge ``wind``, the case's wind perturbed as ``variant``
    (:func:`perturbed_wind`) while the readings stay the case's: a user's CFD that is off.
    Every other knowledge level and attribute is the wrapped estimator's."""

    def __init__(self, estimator: Any, variant: str) -> None:
        if variant not in WIND_VARIANTS:
            raise InputDataError(f"{variant!r} is no wind variant; choose from {', '.join(WIND_VARIANTS)}")
        self.estimator = estimator
        self.variant = variant

    @property
    def knowledge_levels(self) -> tuple[str, ...]:
        return tuple(self.estimator.knowledge_levels)

    def set_knowledge(self, knowledge: Any) -> None:
        if knowledge.wind is not None:
            knowledge = replace(knowledge, wind=perturbed_wind(knowledge, self.variant))
        self.estimator.set_knowledge(knowledge)

    def estimate(self, occupancy: np.ndarray, resolution: float, observations: Any) -> Any:
        return self.estimator.estimate(occupancy, resolution, observations)

    def __getattr__(self, name: str) -> Any:
        if name == "estimator":  # not set yet (copying, unpickling)
            raise AttributeError(name)
        return getattr(self.estimator, name)
