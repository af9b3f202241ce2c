"""Steady 2-D RANS (standard k-epsilon, standard wall functions) by SIMPLEC.

A collocated finite-volume solver on the layout's Cartesian grid that
follows OpenFOAM's ``simpleFoam`` (v1912) discretization of spec section 4:
Rhie-Chow face fluxes from the SIMPLEC pressure equation, bounded
linear-upwind convection with cell-limited Gauss gradients (deferred
correction), ``nutkWallFunction`` / ``epsilonWallFunction`` /
``kqRWallFunction`` at walls, inlet turbulence from intensity and mixing
length, and a fixed-pressure outlet.  Everything here is a pure function of
arrays; the entry point is :func:`solve_flow`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse.linalg as spla

from dgse.physics.constants import DEFAULT_PHYSICS, Physics
from dgse.physics.fv import (
    _AXIS,
    _SIGN,
    BC,
    DIRS,
    INLET,
    INTERNAL,
    OUTLET,
    WALL,
    Mesh,
    StencilMatrix,
    face_types,
    gauss_gradient,
    ho_correction,
    inlet_fluxes,
    neighbour,
    outward,
)
from dgse.world.layout import Layout


@dataclass
class Equation:
    """Coefficients of ``aP phi_P - sum_d a[d] phi_d = b`` on the grid (``(H, W)`` each)."""

    aP: np.ndarray
    a: dict[str, np.ndarray]
    b: np.ndarray

    def matrix(self, stencil: StencilMatrix):
        return stencil.assemble(self.aP, self.a["E"], self.a["W"], self.a["N"], self.a["S"])

    def residual_norm(self, phi: np.ndarray, mesh: Mesh) -> float:
        """OpenFOAM's normalised residual of ``phi`` in this equation."""
        f = mesh.free
        Ax = self.aP * phi
        Aavg = self.aP * phi[f].mean()
        for d in DIRS:
            Ax = Ax - self.a[d] * neighbour(phi, d)
            Aavg = Aavg - self.a[d] * phi[f].mean()
        r = np.abs(self.b - Ax)[f].sum()
        norm = (np.abs(Ax - Aavg) + np.abs(self.b - Aavg))[f].sum() + 1e-20
        return float(r / norm)


def assemble_transport(
    mesh: Mesh,
    t: dict,
    F: dict[str, np.ndarray],
    gamma_cell: np.ndarray,
    bc: BC,
    *,
    bounded: bool = True,
) -> Equation:
    """Upwind convection + central diffusion of ``div(F phi) - div(gamma grad phi)``.

    ``F`` are outward face fluxes (m^2/s per m depth); ``gamma_cell`` the cell
    diffusivity, linearly interpolated to internal faces.  With ``bounded``
    the continuity error ``sum F`` is taken off the diagonal (OpenFOAM's
    ``bounded Gauss``).
    """
    aP = np.zeros(mesh.shape)
    b = np.zeros(mesh.shape)
    a = {}
    net = np.zeros(mesh.shape)
    for d in DIRS:
        Fd = F[d]
        internal = t[d] == INTERNAL
        bnd = t[d] >= WALL
        g_face = 0.5 * (gamma_cell + neighbour(gamma_cell, d))
        a[d] = np.where(internal, g_face + np.maximum(-Fd, 0.0), 0.0)
        aP += np.where(internal, g_face + np.maximum(Fd, 0.0), 0.0)
        fixed = bnd & bc.fixed[d]
        zero_grad = bnd & ~bc.fixed[d]
        g_b = bc.gamma.get(d, gamma_cell)
        aP += np.where(fixed, 2.0 * g_b, 0.0) + np.where(zero_grad, Fd, 0.0)
        b += np.where(fixed, (2.0 * g_b - Fd) * bc.value[d], 0.0)
        net += np.where(internal | bnd, Fd, 0.0)
    if bounded:
        aP -= net
    return Equation(aP, a, b)


def bound(phi: np.ndarray, free: np.ndarray, t: dict, minimum: float) -> np.ndarray:
    """OpenFOAM's ``bound``: values below ``minimum`` become the local face average."""
    pos = np.maximum(phi, minimum)
    acc = np.zeros_like(phi)
    cnt = np.zeros_like(phi)
    for d in DIRS:
        internal = t[d] == INTERNAL
        acc += np.where(internal, 0.5 * (pos + neighbour(pos, d)), pos)
        cnt += 1.0
    avg = acc / cnt
    out = np.where(phi < minimum, np.maximum(avg, minimum), phi)
    return np.where(free, out, 0.0)


def relax(eq: Equation, phi: np.ndarray, alpha: float) -> Equation:
    """OpenFOAM's implicit under-relaxation (with diagonal dominance enforced first)."""
    sum_off = sum(np.abs(eq.a[d]) for d in DIRS)
    D = np.maximum(np.abs(eq.aP), sum_off)
    aP = D / alpha
    b = eq.b + (aP - eq.aP) * phi
    return Equation(aP, eq.a, b)


class LinearSolvers:
    """Inexact linear solves of the SIMPLEC loop (relative tolerances, as OpenFOAM).

    Each equation's matrix changes slowly from one iteration to the next, so
    a sparse LU factorization (SuperLU) made at some iteration is an almost
    exact preconditioner for many later ones: Krylov solves (CG for the
    symmetric pressure equation, BiCGStab otherwise) preconditioned by the
    stale factors take one or two iterations, and the factorization is only
    redone when they stop doing so.
    """

    def __init__(self, settings: FlowSettings) -> None:
        self.s = settings
        self._lu: dict[str, object] = {}
        self.factorizations = 0

    def solve(self, key: str, A, b: np.ndarray, x0: np.ndarray, rel_tol: float) -> np.ndarray:
        if self.s.direct:
            return spla.spsolve(A.tocsc(), b)
        r0 = float(np.linalg.norm(b - A @ x0))
        if r0 == 0.0:
            return x0.copy()
        krylov = spla.cg if key == "p" else spla.bicgstab
        for attempt in range(2):
            if key not in self._lu or attempt == 1:
                self._lu[key] = spla.splu(A.tocsc())
                self.factorizations += 1
            lu = self._lu[key]
            M = spla.LinearOperator(A.shape, matvec=lu.solve)
            with np.errstate(all="ignore"):
                x, info = krylov(
                    A, b, x0=x0, rtol=0.0, atol=rel_tol * r0, maxiter=self.s.max_krylov, M=M
                )
            if info == 0 and np.isfinite(x).all():
                return x
        return spla.spsolve(A.tocsc(), b)


@dataclass
class FlowState:
    """Cell fields ``(H, W)`` and face fluxes of the SIMPLEC iteration."""

    ux: np.ndarray
    uy: np.ndarray
    p: np.ndarray
    k: np.ndarray
    eps: np.ndarray
    nut: np.ndarray
    phi_x: np.ndarray
    phi_y: np.ndarray


@dataclass
class FlowSettings:
    """Iteration controls of :func:`solve_flow`."""

    max_iterations: int = 2000
    tolerance: float = 1e-4  #: on every normalised initial residual (as OpenFOAM's residualControl)
    alpha_u: float = 0.9
    alpha_turb: float = 0.8
    alpha_p: float = 1.0
    high_order: bool = True
    consistent: bool = True
    direct: bool = False  #: exact sparse LU solves instead of the iterative ones
    rel_tol: float = 0.1  #: relative tolerance of the transport-equation solves
    p_rel_tol: float = 0.05  #: relative tolerance of the pressure solve
    max_krylov: int = 4  #: Krylov iterations on stale factors before refactorizing


def _openings_velocity(mesh: Mesh, v_in: float) -> tuple[dict, dict]:
    """Inlet boundary velocity components per direction."""
    t = face_types(mesh)
    vx, vy = {}, {}
    for d in DIRS:
        inl = t[d] == INLET
        # inflow velocity points against the outward normal
        if _AXIS[d] == 0:
            vx[d] = np.where(inl, -_SIGN[d] * v_in, 0.0)
            vy[d] = np.zeros(mesh.shape)
        else:
            vx[d] = np.zeros(mesh.shape)
            vy[d] = np.where(inl, -_SIGN[d] * v_in, 0.0)
    return vx, vy


def inlet_widths(layout: Layout) -> float:
    return max(o.width_m for o in layout.inlets)


def solve_flow(
    layout: Layout,
    mesh: Mesh,
    inlet_velocity: float,
    physics: Physics = DEFAULT_PHYSICS,
    settings: FlowSettings | None = None,
    progress=None,
) -> tuple[FlowState, dict]:
    """Solve the steady RANS flow; returns the final state and an info dict.

    ``info`` holds ``iterations``, ``converged``, the last normalised initial
    residuals per equation, and ``seconds``.
    """
    s = settings or FlowSettings()
    t0 = time.perf_counter()
    H, W = mesh.shape
    h = mesh.h
    V = h * h
    f = mesh.free
    t = face_types(mesh)
    stencil = StencilMatrix(mesh)
    solver = LinearSolvers(s)
    nu = physics.nu
    Cmu = physics.C_mu
    Cmu25, Cmu75 = Cmu**0.25, Cmu**0.75
    kappa, E = physics.kappa, physics.E
    ypl = physics.y_plus_lam
    y = 0.5 * h
    k_in, eps_in = physics.inlet_turbulence(inlet_velocity, inlet_widths(layout))
    max_length = max(mesh.shape) * h
    n_limited = 0
    nut_in = Cmu * k_in**2 / eps_in

    bnd = {d: t[d] >= WALL for d in DIRS}
    wall = {d: (t[d] == WALL) & f for d in DIRS}
    inlet = {d: (t[d] == INLET) & f for d in DIRS}
    outlet = {d: (t[d] == OUTLET) & f for d in DIRS}
    n_wall = sum(wall[d].astype(float) for d in DIRS)
    wall_cell = n_wall > 0
    vx_in, vy_in = _openings_velocity(mesh, inlet_velocity)
    zeros = np.zeros(mesh.shape)

    phi_x, phi_y = inlet_fluxes(mesh, layout, inlet_velocity)
    st = FlowState(
        ux=zeros.copy(), uy=zeros.copy(), p=zeros.copy(),
        k=np.where(f, k_in, 0.0), eps=np.where(f, eps_in, 0.0), nut=zeros.copy(),
        phi_x=phi_x, phi_y=phi_y,
    )
    st.nut = np.where(f, Cmu * st.k**2 / np.where(f, st.eps, 1.0), 0.0)

    # pressure matrix pieces that never change
    p_fixed = {d: outlet[d] for d in DIRS}

    def nut_wall(k: np.ndarray) -> np.ndarray:
        yplus = Cmu25 * y * np.sqrt(np.maximum(k, 0.0)) / nu
        with np.errstate(divide="ignore", invalid="ignore"):
            val = nu * (yplus * kappa / np.log(E * np.maximum(yplus, 1e-30)) - 1.0)
        return np.where(yplus > ypl, val, 0.0)

    residuals: dict[str, float] = {}
    history = []
    converged = False
    it = 0
    for it in range(1, s.max_iterations + 1):
        F = outward(st.phi_x, st.phi_y)
        nueff = np.where(f, nu + st.nut, 0.0)
        nutw = nut_wall(st.k)
        # ---- momentum predictor ------------------------------------------------------
        gam_b = {}
        for d in DIRS:
            gam_b[d] = np.where(wall[d], nu + nutw, np.where(inlet[d], nu + nut_in, nueff))
        bc_ux = BC({d: wall[d] | inlet[d] for d in DIRS}, vx_in, gam_b)
        bc_uy = BC({d: wall[d] | inlet[d] for d in DIRS}, vy_in, gam_b)
        eq = assemble_transport(mesh, t, F, nueff, bc_ux, bounded=True)
        # identical matrix for uy; only the boundary sources differ
        eq_y = assemble_transport(mesh, t, F, nueff, bc_uy, bounded=True)
        gux = gauss_gradient(st.ux, t, bc_ux, h, limited=False)
        guy = gauss_gradient(st.uy, t, bc_uy, h, limited=False)
        bx = eq.b.copy()
        by = eq_y.b.copy()
        # explicit part of the stress: div(nuEff dev2(T(grad U)))
        divu = gux[0] + guy[1]
        for d in DIRS:
            internal = t[d] == INTERNAL
            nu_f = np.where(internal, 0.5 * (nueff + neighbour(nueff, d)), nueff)

            def fint(a):
                return np.where(internal, 0.5 * (a + neighbour(a, d)), a)

            sgn = _SIGN[d]
            if _AXIS[d] == 0:
                tx = fint(gux[0] - (2.0 / 3.0) * divu)  # d ux/dx
                ty = fint(gux[1])  # d ux/dy  (T(gradU)_yx)
            else:
                tx = fint(guy[0])
                ty = fint(guy[1] - (2.0 / 3.0) * divu)
            active = internal | bnd[d]
            bx += np.where(active, sgn * nu_f * tx * h, 0.0)
            by += np.where(active, sgn * nu_f * ty * h, 0.0)
        if s.high_order:
            gxl = gauss_gradient(st.ux, t, bc_ux, h, limited=True)
            gyl = gauss_gradient(st.uy, t, bc_uy, h, limited=True)
            bx += ho_correction(st.ux, *gxl, t, F, h)
            by += ho_correction(st.uy, *gyl, t, F, h)
        eqx = relax(Equation(eq.aP, eq.a, bx), st.ux, s.alpha_u)
        eqy = relax(Equation(eq.aP, eq.a, by), st.uy, s.alpha_u)
        # pressure gradient (Gauss linear, p fixed 0 at outlets, zero gradient elsewhere)
        bc_p = BC(p_fixed, {d: zeros for d in DIRS})
        gpx, gpy = gauss_gradient(st.p, t, bc_p, h, limited=False)
        residuals["Ux"] = Equation(eqx.aP, eqx.a, eqx.b - gpx * V).residual_norm(st.ux, mesh)
        residuals["Uy"] = Equation(eqy.aP, eqy.a, eqy.b - gpy * V).residual_norm(st.uy, mesh)
        A = eqx.matrix(stencil)
        ux_star = np.zeros(mesh.shape)
        uy_star = np.zeros(mesh.shape)
        ux_star[f] = solver.solve("U", A, (eqx.b - gpx * V)[f], st.ux[f], s.rel_tol)
        uy_star[f] = solver.solve("U", A, (eqy.b - gpy * V)[f], st.uy[f], s.rel_tol)

        # ---- SIMPLEC pressure equation -----------------------------------------------
        aP = eqx.aP
        sum_a = sum(eqx.a[d] for d in DIRS)
        hx = eqx.b.copy()
        hy = eqy.b.copy()
        for d in DIRS:
            hx += eqx.a[d] * neighbour(ux_star, d)
            hy += eqy.a[d] * neighbour(uy_star, d)
        safe = np.where(f, aP, 1.0)
        hbyax = np.where(f, hx / safe, 0.0)
        hbyay = np.where(f, hy / safe, 0.0)
        rAU = np.where(f, V / safe, 0.0)
        if s.consistent:
            rAtU = np.where(f, V / np.where(f, aP - sum_a, 1.0), 0.0)
        else:
            rAtU = rAU
        phb = {}
        lap_a = {}
        lap_P = np.zeros(mesh.shape)
        for d in DIRS:
            internal = t[d] == INTERNAL
            hb = hbyax if _AXIS[d] == 0 else hbyay
            sgn = _SIGN[d]
            nb_hb = neighbour(hb, d)
            vb = (vx_in if _AXIS[d] == 0 else vy_in)[d]
            val = np.where(internal, 0.5 * (hb + nb_hb), np.where(outlet[d], hb, vb))
            flux = sgn * val * h
            diff = rAtU - rAU
            nb_p = neighbour(st.p, d)
            if s.consistent:
                flux = flux + np.where(internal, 0.5 * (diff + neighbour(diff, d)) * (nb_p - st.p), 0.0)
                flux = flux + np.where(outlet[d], diff * 2.0 * (0.0 - st.p), 0.0)
            phb[d] = np.where(internal | bnd[d], flux, 0.0)
            coef = np.where(internal, 0.5 * (rAtU + neighbour(rAtU, d)), 0.0)
            lap_a[d] = coef
            lap_P += coef + np.where(outlet[d], 2.0 * rAtU, 0.0)
        if s.consistent:
            hbyax = hbyax - (rAU - rAtU) * gpx
            hbyay = hbyay - (rAU - rAtU) * gpy
        div_phb = sum(phb[d] for d in DIRS)
        peq = Equation(lap_P, lap_a, -div_phb)
        residuals["p"] = peq.residual_norm(st.p, mesh)
        P = peq.matrix(stencil)
        p_new = np.zeros(mesh.shape)
        p_new[f] = solver.solve("p", P, peq.b[f], st.p[f], s.p_rel_tol)
        # corrected face fluxes
        Fn = {}
        for d in DIRS:
            nb_p = neighbour(p_new, d)
            Fn[d] = phb[d] - np.where(t[d] == INTERNAL, lap_a[d] * (nb_p - p_new), 0.0)
            Fn[d] = Fn[d] - np.where(outlet[d], 2.0 * rAtU * (0.0 - p_new), 0.0)
        st.phi_x, st.phi_y = _faces_from_outward(Fn, mesh)
        st.p = s.alpha_p * p_new + (1 - s.alpha_p) * st.p
        gpx, gpy = gauss_gradient(st.p, t, bc_p, h, limited=False)
        st.ux = np.where(f, hbyax - rAtU * gpx, 0.0)
        st.uy = np.where(f, hbyay - rAtU * gpy, 0.0)

        # ---- k-epsilon -----------------------------------------------------------------
        F = outward(st.phi_x, st.phi_y)
        bc_ux.fixed = {d: wall[d] | inlet[d] for d in DIRS}
        gux = gauss_gradient(st.ux, t, bc_ux, h, limited=False)
        guy = gauss_gradient(st.uy, t, bc_uy, h, limited=False)
        divu = gux[0] + guy[1]
        G = st.nut * (
            2.0 * gux[0] ** 2 + 2.0 * guy[1] ** 2 + (gux[1] + guy[0]) ** 2 - (2.0 / 3.0) * divu**2
        )
        k_old = np.where(f, st.k, 1.0)
        eps_old = np.where(f, st.eps, 1.0)
        yplus = Cmu25 * y * np.sqrt(k_old) / nu
        umag = np.hypot(st.ux, st.uy)
        log_region = yplus > ypl
        G0 = (nutw + nu) * (umag / y) * Cmu25 * np.sqrt(k_old) / (kappa * y)
        eps0 = np.where(log_region, Cmu75 * k_old**1.5 / (kappa * y), 2.0 * k_old * nu / y**2)
        G = np.where(wall_cell, np.where(log_region, G0, 0.0), G)

        turb_fixed_out = {d: outlet[d] & (F[d] < 0) for d in DIRS}
        # epsilon
        deff = np.where(f, nu + st.nut / physics.sigma_eps, 0.0)
        g_in = nu + nut_in / physics.sigma_eps
        bc_e = BC(
            {d: inlet[d] | turb_fixed_out[d] for d in DIRS},
            {d: np.full(mesh.shape, eps_in) for d in DIRS},
            {d: np.where(inlet[d], g_in, deff) for d in DIRS},
        )
        eq = assemble_transport(mesh, t, F, deff, bc_e, bounded=True)
        if s.high_order:
            eq.b += ho_correction(st.eps, *gauss_gradient(st.eps, t, bc_e, h), t, F, h)
        eq.b += physics.C_1 * G * eps_old / k_old * V
        eq.aP += physics.C_2 * eps_old / k_old * V
        eq = relax(eq, st.eps, s.alpha_turb)
        # wall cells take the wall-function value
        eq.aP = np.where(wall_cell, 1.0, eq.aP)
        eq.b = np.where(wall_cell, eps0, eq.b)
        for d in DIRS:
            eq.a[d] = np.where(wall_cell, 0.0, eq.a[d])
        residuals["epsilon"] = eq.residual_norm(st.eps, mesh)
        eps_new = np.zeros(mesh.shape)
        eps_new[f] = solver.solve("eps", eq.matrix(stencil), eq.b[f], st.eps[f], s.rel_tol)
        eps_new = bound(eps_new, f, t, 1e-15)
        # k
        dk = np.where(f, nu + st.nut / physics.sigma_k, 0.0)
        g_in = nu + nut_in / physics.sigma_k
        bc_k = BC(
            {d: inlet[d] | turb_fixed_out[d] for d in DIRS},
            {d: np.full(mesh.shape, k_in) for d in DIRS},
            {d: np.where(inlet[d], g_in, dk) for d in DIRS},
        )
        eq = assemble_transport(mesh, t, F, dk, bc_k, bounded=True)
        if s.high_order:
            eq.b += ho_correction(st.k, *gauss_gradient(st.k, t, bc_k, h), t, F, h)
        eq.b += G * V
        eq.aP += eps_new / k_old * V
        eq = relax(eq, st.k, s.alpha_turb)
        residuals["k"] = eq.residual_norm(st.k, mesh)
        k_new = np.zeros(mesh.shape)
        k_new[f] = solver.solve("k", eq.matrix(stencil), eq.b[f], st.k[f], s.rel_tol)
        st.k = bound(k_new, f, t, 1e-15)
        # realizability guard: the turbulence length scale Cmu^0.75 k^1.5 / eps
        # cannot exceed the domain; without it a transient dip of epsilon to
        # its lower bound gives an unbounded nu_t and the iteration blows up
        eps_floor = Cmu75 * st.k**1.5 / max_length
        limited = f & (eps_new < eps_floor)
        n_limited = int(limited.sum())
        st.eps = np.where(limited, eps_floor, eps_new)
        st.nut = np.where(f, Cmu * st.k**2 / np.where(f, st.eps, 1.0), 0.0)

        history.append(dict(residuals))
        if progress is not None:
            progress(it, residuals)
        if max(residuals.values()) < s.tolerance:
            converged = True
            break
        if not all(math.isfinite(v) for v in residuals.values()) or not np.isfinite(st.ux).all():
            break
    info = {
        "iterations": it,
        "converged": converged,
        "residuals": dict(residuals),
        "seconds": time.perf_counter() - t0,
        "length_scale_limited_cells": n_limited,
        "factorizations": solver.factorizations,
        "history": history,
    }
    return st, info


def _faces_from_outward(F: dict[str, np.ndarray], mesh: Mesh) -> tuple[np.ndarray, np.ndarray]:
    """Face flux arrays from per-cell outward fluxes (each face taken from one owner)."""
    H, W = mesh.shape
    fx = np.zeros((H, W + 1))
    fy = np.zeros((H + 1, W))
    f = mesh.free
    # east faces from their west cell, west boundary faces from the cell east of them
    fx[:, 1:] = np.where(f, F["E"], 0.0)
    west_only = (mesh.tW >= WALL) & f
    fx[:, :-1] = np.where(west_only, -F["W"], fx[:, :-1])
    fy[1:, :] = np.where(f, F["N"], 0.0)
    south_only = (mesh.tS >= WALL) & f
    fy[:-1, :] = np.where(south_only, -F["S"], fy[:-1, :])
    return fx, fy
