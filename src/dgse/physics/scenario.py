"""From a layout and sources to case files: the physics' edge to the rest of DGSE."""

from __future__ import annotations

import json
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from dgse.physics.constants import DEFAULT_PHYSICS
from dgse.physics.engines import Engine, Solution, Source, check_mass_balance, get_engine
from dgse.world.case import Case
from dgse.world.layout import Layout

if TYPE_CHECKING:
    from dgse.world.generate import RngLike


def solution_to_cases(
    layout: Layout, inlet_velocity: float, solution: Solution, name: str | None = None
) -> list[Case]:
    """One :class:`Case` per source of an engine's solution (fields as float32, 0 in solid)."""
    free = layout.free
    wind = np.where(free, solution.flow.wind, 0.0).astype(np.float32)
    base = name or layout.name
    cases = []
    for n, (src, ppm, ratio) in enumerate(
        zip(solution.sources, solution.concentrations, solution.outlet_flux_ratio, strict=True)
    ):
        meta = {
            "name": f"{base}_src{n}",
            "layout": base,
            "source_index": n,
            **layout.meta(),
            "inlet_velocity": float(inlet_velocity),
            "release_rate_gps": float(src.release_rate),
            "source_xy_m": [float(src.position[0]), float(src.position[1])],
            "solver": solution.info.get("engine", "unknown"),
            "physics": {**DEFAULT_PHYSICS.to_dict(), "ppm_per_gm3": DEFAULT_PHYSICS.ppm_per_gm3},
            "iterations": {"flow": solution.info.get("flow_iterations")},
            "flow_converged": solution.info.get("flow_converged"),
            "residuals": solution.info.get("residuals"),
            "mass_balance": {"outlet_flux_ratio": float(ratio)},
            "timings": solution.info.get("wall_clock_s", {}),
        }
        meta = json.loads(json.dumps(meta, default=float))  # plain JSON types only
        conc = np.where(free, ppm, 0.0).astype(np.float32)
        cases.append(Case(layout.occupancy, wind, conc, np.array(src.position), layout.resolution, meta))
    return cases


def solve_cases(
    layout: Layout,
    inlet_velocity: float,
    sources: Sequence[Source] | Sequence[tuple[tuple[float, float], float]],
    engine: str | Engine = "builtin",
    name: str | None = None,
) -> list[Case]:
    """Solve one layout for several sources and return one case per source."""
    eng = get_engine(engine) if isinstance(engine, str) else engine
    srcs = [s if isinstance(s, Source) else Source(tuple(s[0]), float(s[1])) for s in sources]
    # the engines check their own solutions; this covers an engine from a plugin too
    sol = check_mass_balance(eng.solve(layout, inlet_velocity, srcs))
    return solution_to_cases(layout, inlet_velocity, sol, name)


def resolve_case(case: Case, engine: str | Engine = "builtin") -> Case:
    """Solve a case file's scenario again (layout, openings, inlet speed, source, rate)."""
    src = Source((float(case.source[0]), float(case.source[1])), case.release_rate)
    out = solve_cases(case.layout, case.inlet_velocity, [src], engine, name=case.meta.get("layout"))[0]
    meta = {**out.meta, "name": case.name}
    return Case(out.occupancy, out.wind, out.concentration, out.source, out.resolution, meta)


def random_scenario(
    rng_or_seed: RngLike = None, n_sources: int = 4, **layout_kw: Any
) -> tuple[Layout, float, list[Source]]:
    """A random training-distribution scenario (spec section 3), unsolved: the layout, the inlet
    velocity (m/s) and ``n_sources`` sources, drawn in that order from one generator."""
    # imported here: the generators load scipy.ndimage, which solving a given case never needs
    from dgse.world.generate import as_generator, random_inlet_velocity, random_layout
    from dgse.world.generate import random_sources as _random_sources

    rng = as_generator(rng_or_seed)
    layout = random_layout(rng, **layout_kw)
    v = random_inlet_velocity(rng)
    return layout, v, list(_random_sources(layout, rng, n=n_sources))


def random_cases(
    rng_or_seed: RngLike = None, n_sources: int = 4, engine: str | Engine = "builtin", **layout_kw: Any
) -> list[Case]:
    """:func:`random_scenario` solved for its sources."""
    layout, v, sources = random_scenario(rng_or_seed, n_sources, **layout_kw)
    return solve_cases(layout, v, sources, engine)
