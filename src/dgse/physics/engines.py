"""The solver interface every physics engine implements, and their registry.

An engine takes a :class:`~dgse.world.layout.Layout`, an inlet velocity and
a list of sources, and returns a :class:`Solution`: one steady flow field
and one steady concentration field per source.  ``builtin`` is always
there; optional engines (``openfoam``) register themselves when importable
and usable, and :func:`get_engine` says clearly why one is missing.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from dgse.errors import UnsupportedError
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


class Engine(Protocol):
    """A physics engine: ``solve(layout, inlet_velocity, sources) -> Solution``."""

    name: str

    def solve(self, layout: Layout, inlet_velocity: float, sources: Sequence[Source]) -> Solution: ...


_FACTORIES: dict[str, Callable[[], Engine]] = {}
_UNAVAILABLE: dict[str, str] = {}


def register_engine(name: str, factory: Callable[[], Engine]) -> None:
    """Make ``factory`` available as engine ``name``."""
    _FACTORIES[name] = factory
    _UNAVAILABLE.pop(name, None)


def mark_unavailable(name: str, reason: str) -> None:
    """Record why a known engine cannot be used here (shown by :func:`get_engine`);
    drops a registration made earlier (e.g. before the software went missing)."""
    _FACTORIES.pop(name, None)
    _UNAVAILABLE[name] = reason


def unavailable_engines() -> dict[str, str]:
    """Known engines that cannot be used here, with the reason for each."""
    _load_optional()
    return dict(_UNAVAILABLE)


#: the module that registers each built-in engine (imported on first use: a process that
#: solves with one engine does not import the others)
_MODULES = {"builtin": "dgse.physics.builtin", "openfoam": "dgse.physics.openfoam"}


def _load_optional(name: str | None = None) -> None:
    # Engines register themselves on import; optional ones mark themselves
    # unavailable (with the reason) when their software is missing.
    import importlib

    for engine, module in _MODULES.items():
        if name is None or name == engine:
            importlib.import_module(module)


def engine_names() -> list[str]:
    """Names of the engines usable on this machine."""
    _load_optional()
    return sorted(_FACTORIES)


def get_engine(name: str = "builtin", **options) -> Engine:
    """The engine ``name``; raises :class:`UnsupportedError` saying why when unusable."""
    if name not in _FACTORIES:
        _load_optional(name if name in _MODULES else None)
    if name in _FACTORIES:
        return _FACTORIES[name](**options)
    if name in _UNAVAILABLE:
        raise UnsupportedError(f"engine {name!r} is not available: {_UNAVAILABLE[name]}")
    raise UnsupportedError(
        f"unknown engine {name!r}; known engines: {', '.join(sorted(_FACTORIES) + sorted(_UNAVAILABLE))}"
    )
