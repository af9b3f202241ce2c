"""The solver interface every physics engine implements, and their registry.

An engine takes a :class:`~dgse.world.layout.Layout`, an inlet velocity and
a list of sources, and returns a :class:`Solution`: one steady flow field
and one steady concentration field per source.  ``builtin`` is always
there; an optional one (``openfoam``) says why it cannot run here
(``Engine.unavailable``), and :func:`get_engine` passes that on.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from dgse.errors import MassBalanceError, UnsupportedError
from dgse.registry import Entry, Registry
from dgse.world.layout import Layout


@dataclass(frozen=True)
class Source:
    """A point release at ``position = (x, y)`` m of ``release_rate`` g/s."""

    position: tuple[float, float]
    release_rate: float


@dataclass
class FlowField:
    """Steady flow on the layout's grid, cell-centred, 0 in solid cells.

    Attributes:
        wind: ``(2, H, W)`` velocity ``[u_x, u_y]`` in m/s.
        k: ``(H, W)`` turbulent kinetic energy, m^2/s^2.
        epsilon: ``(H, W)`` dissipation rate, m^2/s^3.
        nut: ``(H, W)`` turbulent viscosity, m^2/s.
        pressure: ``(H, W)`` kinematic pressure, m^2/s^2.
        info: iterations, convergence flag, residuals, seconds.
    """

    wind: np.ndarray
    k: np.ndarray
    epsilon: np.ndarray
    nut: np.ndarray
    pressure: np.ndarray
    info: dict = field(default_factory=dict)


@dataclass
class Solution:
    """What an engine returns for one layout and several sources.

    ``concentrations[n]`` is the ``(H, W)`` steady field (ppm) of ``sources[n]``;
    ``outlet_flux_ratio[n]`` is the scalar flux out of the outlets over the
    release rate (1 at steady state); ``info`` carries timings and solver facts,
    at least ``engine``, ``flow_iterations``, ``flow_converged`` and
    ``wall_clock_s`` (``flow``, ``gas``, ``gas_per_source``, ``layout_total``
    seconds), which :func:`dgse.physics.scenario.solution_to_cases` records in
    every case file.
    """

    flow: FlowField
    sources: list[Source]
    concentrations: list[np.ndarray]
    outlet_flux_ratio: list[float]
    info: dict = field(default_factory=dict)


#: The largest ``|outlet flux / release rate - 1|`` of a gas field an engine returns
#: (:func:`check_mass_balance`; its value: ``docs/decisions.md``).
MASS_BALANCE_TOLERANCE = 0.05


def check_mass_balance(solution: Solution, tolerance: float = MASS_BALANCE_TOLERANCE) -> Solution:
    """``solution`` when every gas field is finite and carries its release rate out of the outlets.

    Spec section 4: at steady state the scalar flux out of the outlets equals the release
    rate.  Every engine calls this on its solution before returning it, so no case file
    holds a field that fails its own balance.

    Raises:
        MassBalanceError: a field with non-finite values, or an ``outlet_flux_ratio`` off 1 by
            more than ``tolerance``; the message names the source and the numbers.
    """
    engine = solution.info.get("engine", "the")
    for n, (src, conc, ratio) in enumerate(
        zip(solution.sources, solution.concentrations, solution.outlet_flux_ratio, strict=True)
    ):
        x, y = src.position
        where = f"{engine} engine's gas field of source {n} at ({x:g}, {y:g}) m"
        if not np.isfinite(conc).all():
            raise MassBalanceError(f"the {where} has non-finite values")
        if not (math.isfinite(ratio) and abs(ratio - 1.0) <= tolerance):
            raise MassBalanceError(
                f"the {where} fails its mass balance: outlet flux / release rate = {ratio:.4g} "
                f"({ratio * src.release_rate:.4g} of {src.release_rate:g} g/s), more than "
                f"{tolerance:g} off 1"
            )
    return solution


class Engine(Protocol):
    """A physics engine: ``solve(layout, inlet_velocity, sources) -> Solution``.

    ``unavailable()``, asked of the class before one is made, is None where the engine
    can run and otherwise says why not (missing software, with the fix).
    """

    name: str

    @classmethod
    def unavailable(cls) -> str | None: ...

    def solve(self, layout: Layout, inlet_velocity: float, sources: Sequence[Source]) -> Solution: ...


#: Every engine; packages add theirs through the ``dgse.engines`` entry-point group
#: (:mod:`dgse.registry`).  Each module is imported only when its engine is asked for, so a
#: process that solves with OpenFOAM never imports numba or the built-in solver.
ENGINES: Registry[Engine] = Registry(
    "engine",
    [
        Entry("builtin", "dgse.physics.builtin:BuiltinEngine", description="default"),
        Entry("openfoam", "dgse.physics.openfoam:OpenFOAMEngine", description="OpenFOAM v1912"),
    ],
    group="dgse.engines",
)


def unavailable_engines() -> dict[str, str]:
    """Registered engines that cannot be used here, with the reason for each."""
    out = {}
    for name in ENGINES.names():
        try:
            reason = ENGINES.factory(name).unavailable()
        except UnsupportedError as e:  # a plugin whose module cannot be imported
            reason = str(e)
        if reason:
            out[name] = reason
    return out


def engine_names() -> list[str]:
    """Names of the engines usable on this machine."""
    missing = unavailable_engines()
    return [n for n in ENGINES.names() if n not in missing]


def get_engine(name: str = "builtin", **options) -> Engine:
    """The engine ``name``; raises :class:`UnsupportedError` saying why when unusable."""
    factory = ENGINES.factory(name)
    reason = factory.unavailable()
    if reason:
        raise UnsupportedError(f"engine {name!r} is not available: {reason}")
    return factory(**options)
