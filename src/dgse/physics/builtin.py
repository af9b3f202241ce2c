"""The built-in engine: SIMPLEC k-epsilon flow + factorized linear-upwind transport.

Registered as engine ``"builtin"`` (the default).  For the adjoint of a flow
field (one solve per sensor), use :func:`flow_and_transport`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from dgse.errors import ConvergenceError, InputDataError
from dgse.physics.constants import DEFAULT_PHYSICS, Physics
from dgse.physics.engines import FlowField, Solution, Source, check_mass_balance
from dgse.physics.fv import Mesh, build_mesh
from dgse.physics.rans import FlowSettings, FlowState, face_fluxes, scale_state, solve_flow
from dgse.physics.transport import TransportSolver, check_release_cells
from dgse.world.layout import Layout


def check_inlet_velocity(v: float) -> float:
    v = float(v)
    if not (np.isfinite(v) and v > 0):
        raise InputDataError(f"inlet velocity must be a positive number of m/s, got {v}")
    return v


def flow_and_transport(
    layout: Layout,
    inlet_velocity: float,
    physics: Physics = DEFAULT_PHYSICS,
    settings: FlowSettings | None = None,
    progress: Callable[[int, dict], None] | None = None,
    warm_start: FlowField | None = None,
) -> tuple[FlowField, TransportSolver]:
    """Solve the flow and build the (lazily factorized) transport operator on it.

    ``warm_start``: a flow of the same layout solved by this function at any
    inlet speed (its ``info["inlet_velocity"]``); the iteration starts from it,
    scaled to ``inlet_velocity`` (:func:`dgse.physics.rans.scale_state`), and
    converges to the same residual criteria as a cold start.
    """
    v = check_inlet_velocity(inlet_velocity)
    mesh = build_mesh(layout)
    initial = None if warm_start is None else _warm_state(mesh, warm_start, v)
    st, info = solve_flow(layout, mesh, v, physics, settings, progress, initial=initial)
    info.pop("history", None)
    flow = FlowField(
        wind=mesh.field(np.stack([st.ux, st.uy])),
        k=mesh.field(st.k),
        epsilon=mesh.field(st.eps),
        nut=mesh.field(st.nut),
        pressure=mesh.field(st.p),
        info=info,
    )
    return flow, TransportSolver.build(mesh, st.F, st.nut, physics)


def _warm_state(mesh: Mesh, flow: FlowField, inlet_velocity: float) -> FlowState:
    """The :class:`FlowState` of a solved ``flow`` on ``mesh``, scaled to ``inlet_velocity`` m/s."""
    v0 = flow.info.get("inlet_velocity")
    if v0 is None or not v0 > 0:
        raise InputDataError("warm_start needs a flow solved by the built-in solver (info['inlet_velocity'])")
    if flow.wind.shape[1:] != mesh.shape or np.any(flow.wind[:, ~mesh.free] != 0):
        raise InputDataError(f"warm_start flow of shape {flow.wind.shape[1:]} is not on this layout")
    ux, uy = mesh.values(flow.wind[0]), mesh.values(flow.wind[1])
    state = FlowState(
        ux=ux, uy=uy, p=mesh.values(flow.pressure), k=mesh.values(flow.k), eps=mesh.values(flow.epsilon),
        nut=mesh.values(flow.nut), F=face_fluxes(mesh, ux, uy, float(v0)),
    )  # fmt: skip
    return scale_state(state, inlet_velocity / float(v0))


@dataclass
class BuiltinEngine:
    """Engine ``builtin``: a fast solver of spec section 4 (see :mod:`dgse.physics.rans`).

    Args:
        settings: SIMPLEC iteration controls (tolerance, iteration cap, ...).
        allow_unconverged: return a flow that missed its tolerance instead of
            raising :class:`~dgse.errors.ConvergenceError`.
    """

    settings: FlowSettings | None = None
    allow_unconverged: bool = False
    physics: Physics = DEFAULT_PHYSICS
    name: str = "builtin"

    @classmethod
    def unavailable(cls) -> str | None:
        """None: the built-in solver runs wherever DGSE is installed."""
        return None

    def solve(self, layout: Layout, inlet_velocity: float, sources: Sequence[Source]) -> Solution:
        # check the sources before spending time on the flow
        grid = layout.grid
        cells = [grid.cell_of(*s.position) for s in sources]
        for s, (i, j) in zip(sources, cells, strict=True):
            if layout.occupancy[i, j]:
                x, y = s.position
                raise InputDataError(f"source at ({x:g}, {y:g}) m lies in a solid cell")
            if not s.release_rate > 0:
                raise InputDataError(f"release rate must be positive, got {s.release_rate}")
        check_release_cells(build_mesh(layout), cells)
        t0 = time.perf_counter()
        flow, ts = flow_and_transport(layout, inlet_velocity, self.physics, self.settings)
        t_flow = time.perf_counter() - t0
        if not self.allow_unconverged:
            require_converged(flow.info)
        t1 = time.perf_counter()
        conc = ts.solve_cells(cells, [s.release_rate for s in sources]) if sources else []
        ratios = []
        for c, s in zip(conc, sources, strict=True):
            out, _ = ts.outflow(c)
            ratios.append(out * self.physics.slab_depth / s.release_rate)
        t_gas = time.perf_counter() - t1
        ppm = [np.maximum(c, 0.0) * self.physics.ppm_per_gm3 for c in conc]
        info = {
            "engine": self.name,
            "flow_iterations": flow.info["iterations"],
            "flow_converged": flow.info["converged"],
            "residuals": flow.info["residuals"],
            "wall_clock_s": {
                "flow": t_flow,
                "gas": t_gas,
                "gas_per_source": t_gas / max(len(sources), 1),
                "gas_outer_iterations": ts.info.get("outer_iterations"),
                "layout_total": time.perf_counter() - t0,
            },
        }
        return check_mass_balance(Solution(flow, list(sources), ppm, ratios, info))


def require_converged(
    info: Mapping, what: str = "flow", advice: str = "", names: Mapping[str, str] | None = None
) -> None:
    """Raise :class:`ConvergenceError` saying why unless the :func:`~dgse.physics.rans.solve_flow`
    ``info`` of a flow says it converged.

    Args:
        info: the flow's ``info`` (``converged``, ``diverged``, ``stalled``, ``iterations``,
            ``residuals``).
        what: what did not converge, the message's subject.
        advice: appended to the message (what to do instead), if given.
        names: the arguments ``advice`` names as ``{name}`` (:class:`~dgse.errors.DGSEError`).
    """
    if info.get("converged"):
        return
    why = (
        "diverged"
        if info.get("diverged")
        else "stalled (residuals stopped falling)"
        if info.get("stalled")
        else "hit its iteration or time limit"
    )
    message = (
        f"{what} did not converge in {info.get('iterations', '?')} iterations: {why} "
        f"(residuals {_fmt(info.get('residuals') or {})})"
    )
    raise ConvergenceError(f"{message}; {advice}" if advice else message, dict(info), names=names)


def _fmt(res: Mapping) -> str:
    return ", ".join(f"{k} {v:.1e}" for k, v in res.items())
