r"""Adjoint Bayesian source localization: the exact posterior of the discretized physics.

Model
-----
The steady transport of spec section 4, discretized as the built-in solver
does, is linear in the source: ``A c = b`` with ``b`` nonzero only in the
source cell ``s`` (``q / (dx dy h)``).  The reading of sensor ``i`` for a
source of ``q`` g/s in cell ``s`` is therefore ``q a_i(s)`` with

``a_i = ppm_per_gm3 * A^{-T} e_i / h``   (ppm per g/s, for every candidate ``s`` at once),

one transposed solve per sensor with the one LU factorization of ``A``
(:meth:`dgse.physics.transport.TransportSolver.adjoint`; the discrete
operator is transposed, the continuous adjoint is never discretized).  The
operator is the solver's linear ``linearUpwind`` one; the forward cases are
solved with the bounded ``limitedLinearUpwind`` scheme (deferred correction),
so even the oracle sees a small model error near the source (a few per cent
of the field; the posterior still peaks within a cell or two of the source).

Readings ``z_i = q a_i(s) + e_i``.  Noise (Table I: ``sigma_i = alpha_g c_i +
sigma_env``, parameters unknown to the robot): ``e_i ~ N(0, sigma^2 r_i^2)``
with ``r_i = 1 + kappa * chat_i / mean(chat)``: ``sigma`` is the unknown noise
floor (``sigma_env``), ``kappa`` the unknown relative weight of the
proportional part, ``chat_i`` a plug-in estimate of the true concentration at
the sensor (the posterior-predictive mean of a first, homoscedastic pass,
``kappa = 0``; using the reading itself would down-weight readings that
happen to be high).  ``kappa`` is averaged over the grid ``kappas`` (default
``0, 0.5, 2, 8, 32``: Table I gives ``alpha_g c / sigma_env`` around
``alpha_g / u`` with ``alpha_g ~ U[0, 1]``, ``u ~ U[0, 0.5]``) with equal prior
weights (a Bayesian model average: the evidence of each ``kappa`` includes
its ``-sum log r_i`` normalization).

Priors: source uniform over the free cells; release rate ``q ~ U[0, q_max]``
(default ``q_max = 5`` g/s, the top of the training range; ``q_max=None``
gives the improper flat prior on ``q >= 0``, see below); noise precision
``tau = 1 / sigma^2 ~ Gamma(alpha0, beta0)`` with ``alpha0 = 1`` (weak: two
pseudo-readings) and ``beta0 = alpha0 s0^2``, ``s0 = 0.25 * mean(z)`` (Table
I's mean ``sigma_env`` when the sensors are spread over the free cells: an
empirical-Bayes scale).  With the weighted sums ``aa = sum w a_i^2``,
``az = sum w a_i z_i``, ``zz = sum w z_i^2`` (``w = 1 / r^2``), the
least-squares rate ``qhat = az / aa`` and the residual ``S = zz - az^2 / aa``,
integrating ``q`` and then ``tau`` analytically gives

``log p(z | s, kappa) = -sum log r_i - 1/2 log aa - alpha_n log beta_n
+ log[T_nu((q_max - qhat) / t) - T_nu(-qhat / t)] + const``

with ``alpha_n = alpha0 + (m - 1) / 2``, ``beta_n = beta0 + S / 2``,
``nu = 2 alpha_n``, ``t^2 = beta_n / (alpha_n aa)`` and ``T_nu`` the Student-t
CDF: the posterior of ``q`` given ``s`` is a Student-t around ``qhat``, and
the last term is its mass inside the prior's support (the truncation term;
with a known ``sigma`` it is the ``Phi``/erfc term ``Phi(qhat sqrt(aa) /
sigma)``).  In the limit ``alpha0, beta0 -> 0``, ``q_max -> inf`` this is the
textbook ``-[zz - az^2/aa] / (2 sigma^2) - 1/2 log aa`` with ``sigma``
integrated out: ``-(m-1)/2 log S - 1/2 log aa + log T_{m-1}(qhat sqrt((m-1)
aa / S))``.  Why ``q_max`` matters: with the flat prior on ``[0, inf)`` the
``-1/2 log aa`` Occam factor favours cells that hardly reach any sensor
(``aa -> 0``: any reading pattern explained by an enormous ``q``); the
proper prior's truncation term cancels that factor (``T(q_max / t) - T(0)
~ q_max sqrt(aa)``).

Zero readings
-------------
The sensor clips negative readings to 0 (spec, Table I), so a reading of 0
says only that the noisy concentration was at most 0: its likelihood is
``Phi(-q a_i(s) / (sigma r_i))``, not a Gaussian density at 0 (``censored``,
the default).  Read as exact zeros, clipped noise in clean air (0, 8, 33, 74
ppm where the truth is 0) has a positive mean and looks like a weak source
nearby, and searches stop confidently on it.  The positive readings keep the
closed form above; the zeros multiply it by ``E[prod Phi(...)]`` under the
posterior of ``(q, tau)`` given the positive readings
(:func:`censored_correction`: an adaptive Gauss-Hermite rule over ``log tau``
around the integrand's mode, composite Gauss-Legendre over ``q``'s
conditional CDF, the zeros' sum interpolated in ``q sqrt(tau)`` through
Chebyshev points; within a few hundredths of a nat of brute-force
integration in the tests).  Where the zeros pull the rate far from the positive
readings' estimate (a noise floor far above the plume reads half zeros and half
noise, and the positive readings alone then put the rate many of its spreads too
high), the rate's nodes follow a normal fitted to the product and carry importance
weights (``censored_kernel._rate_nodes``): nodes at the positive readings' rate alone
can miss the true source's factor by tens of nats.  Candidates whose positive-readings evidence
leaves less than ``CENSORED_TAIL`` of the mass are left at the factor's
plug-in value, and so are those the zero sensors cannot see (``q sqrt(tau)
sum_i a_i / (sigma r_i)`` below ``CENSORED_FAINT`` even at the rate prior's
end and the precision's 1 - 1e-12 quantile: each factor is 1/2 to within
that many nats).  No candidate's factor exceeds ``(1/2)`` per zero.  With
several ``kappas`` the zeros' factor uses the most probable ``kappa``'s
noise weights.

Responses are clipped at 0 (:meth:`FlowModel.responses`): the second-order
upwind operator's rows dip below zero just downstream of the sensor (down to
minus 0.18 of their peak: ``python benchmarks/phys.py diagnostics``), and a zero
reading then favoured exactly those candidates.

Wind
----
``wind="oracle"`` (registry ``adjoint-oracle``): the true flow.  It works at
knowledge level ``wind`` (:mod:`dgse.belief.knowledge`: the user's CFD,
with the openings and the inlet speed it was run with):
``get_estimator("adjoint-oracle", knowledge=Knowledge.from_case(case, "wind"))``,
or a precomputed ``transport=`` (+ ``flow=``).  The flow is re-solved with
the built-in solver from the openings and the inlet speed (cached per layout
and speed; the stored wind alone does not give the face fluxes and eddy
viscosity the transport needs).  With the built-in solver's own cases
this is the exact generating model up to the convection-scheme difference;
with OpenFOAM or GADEN cases it is the built-in physics of that scenario.

``wind="estimated"`` (registry ``adjoint``): the robot knows the map *and
its openings* (knowledge level ``openings``:
``get_estimator("adjoint", knowledge=Knowledge.from_case(case, "openings"))``),
but not the inlet speed.  RANS is not
linear in ``v_in``, but the flow's shape changes slowly with it, so: solve
the layout for the ``candidate_speeds`` (default 0.5, 1, 2, 3.5, 5 m/s;
cached), fit each candidate's wind at the reading cells to the wind readings
by least squares with a free scale ``lambda`` (``w_obs ~ lambda u_k``), take
the candidate with the smallest residual and the speed ``lambda v_k``,
snapped to a log grid of ``speed_step`` (10 %) so repeated estimates reuse
solves, and solve the layout once more at that speed (``refine_speed``).
That flow's adjoint gives the posterior as above.

Belief
------
``source_probs``: the posterior over free cells.  ``log_conc_mean`` /
``log_conc_var``: the posterior predictive of the concentration, a mixture
over the most probable source cells (up to ``conc_components``, covering
99 % of the mass) of the forward field at rate ``clip(qhat, 0, q_max)``,
moment-matched to a lognormal ``1 + c`` (release-rate spread within a cell
is not included).  ``wind_mean``: the flow used (no variance).
``info["response_model"]`` gives planners (Infotaxis) the predicted reading
at any cell for a source in every cell.

Cost: the flow solves (seconds to tens of seconds per speed on a 100 x 100
map, once per layout and speed), then per estimate one transposed solve per
new sensor cell and a few dense ``(m, N)`` products.
"""

from __future__ import annotations

import functools
import itertools
import json
import math
import threading
import time
from collections import OrderedDict
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from scipy import special

from dgse import threads
from dgse.belief.inputs import map_key
from dgse.errors import InputDataError
from dgse.physics.builtin import flow_and_transport
from dgse.physics.constants import DEFAULT_PHYSICS, Physics
from dgse.physics.engines import FlowField
from dgse.physics.rans import FlowSettings
from dgse.physics.transport import TransportSolver
from dgse.posterior import censored_kernel, evidence_kernel
from dgse.posterior.student_t import log_interval
from dgse.world.layout import Layout

__all__ = [
    "AdjointResponseModel",
    "FlowModel",
    "adjoint_log_evidence",
    "censored_correction",
    "check_noise_weights",
    "clear_flow_cache",
    "flow_model",
    "sigma_floor",
]

#: Flow models kept in memory (each holds an LU factorization of the transport operator).
FLOW_CACHE_SIZE = 16
#: Adjoint rows kept per flow model (one float per free cell each).
MAX_CACHED_ROWS = 1024
#: Forward fields per unit release kept per flow model (one float per free cell each).
MAX_CACHED_FIELDS = 256
#: Candidates this many nats below the best one skip the evidence's truncation term.
TRUNC_NATS = 60.0
#: The grid of the proportional noise's weight ``kappa`` (equal prior weights; module docstring).
DEFAULT_KAPPAS = (0.0, 0.5, 2.0, 8.0, 32.0)


# -- flows ---------------------------------------------------------------------------------
@dataclass(eq=False)
class FlowModel:
    """A flow field and its factorized transport operator, with the adjoint rows cached per sensor cell.

    Attributes:
        wind: ``float64 (2, H, W)`` the flow's wind, m/s (0 in solid cells).
        transport: the transport operator of the flow.
        inlet_velocity: the inlet speed it was solved for, m/s (nan when unknown).
        info: solver diagnostics (converged, iterations, seconds).
        physics: constants (``ppm_per_gm3``).
        solved: the built-in solver's full flow (for warm starts), when it made this model.
    """

    wind: np.ndarray
    transport: TransportSolver
    inlet_velocity: float = float("nan")
    info: dict[str, Any] = field(default_factory=dict)
    physics: Physics = DEFAULT_PHYSICS
    solved: FlowField | None = field(default=None, repr=False)
    _rows: dict[tuple[int, int], np.ndarray] = field(default_factory=dict, repr=False)
    _fields: dict[tuple[int, int], np.ndarray] = field(default_factory=dict, repr=False)
    _grown: tuple[list[tuple[int, int]], np.ndarray] | None = field(default=None, repr=False)

    @property
    def mesh(self):
        """The mesh (free-cell numbering) of the transport operator."""
        return self.transport.mesh

    @property
    def free(self) -> np.ndarray:
        """``bool (H, W)`` the free cells (candidate sources), numbered row-major."""
        return self.transport.mesh.free

    def responses(self, cells: np.ndarray, *, growing: bool = False) -> np.ndarray:
        """``float64 (k, n_free)``: reading (ppm) at each of ``cells`` per g/s released in every free cell.

        Adjoint rows of the linear (``linearUpwind``) operator, computed in
        one batch for the cells not seen before and cached (the last
        :data:`MAX_CACHED_ROWS` cells used), clipped at 0: a release cannot lower a
        reading, but the second-order upwind scheme undershoots next to a
        point source: a row dips below zero for sources a cell or two
        downstream of the sensor (to a fifth of its peak below zero).  Left
        in, such lobes made a zero reading *favour* the candidates just
        downstream of it (``Phi(-q a / sigma) > 1/2`` for ``a < 0``).

        ``growing``: the cells of a search's readings, which only grow.  The rows go into
        one buffer, and a call whose cells extend the last growing call's copies only the
        new rows (stacking every row afresh costs a few per cent of a search step); a call
        that does not extend it starts the buffer again.  The answer is then a read-only
        view of that buffer, valid until the next growing call.
        """
        c = np.asarray(cells, dtype=np.int64).reshape(-1, 2)
        keys = [(int(i), int(j)) for i, j in c]
        start = 0
        if growing and self._grown is not None:
            old = self._grown[0]
            if len(keys) >= len(old) and keys[: len(old)] == old:
                start = len(old)
        new = sorted({k for k in keys[start:] if k not in self._rows})
        if new:
            adj = self.transport.adjoint(np.array(new, dtype=np.int64))
            vals = np.maximum(self.mesh.values(adj) * self.physics.ppm_per_gm3, 0.0)
            for k, row in zip(new, vals, strict=True):
                self._rows[k] = row
        n = self.mesh.n
        if growing:
            buf = None if self._grown is None or not start else self._grown[1]
            if buf is None or buf.shape[0] < len(keys):
                grown = np.empty((len(keys) + max(64, len(keys) // 4), n))
                if start:
                    grown[:start] = buf[:start]
                buf = grown
            for i in range(start, len(keys)):
                buf[i] = self._rows[keys[i]]
            self._grown = (keys, buf)
            out = buf[: len(keys)].view()
            out.flags.writeable = False
        else:
            out = np.stack([self._rows[k] for k in keys]) if keys else np.zeros((0, n))
        for k in keys[start:]:  # the cells just used move to the end (start is 0 unless growing)
            self._rows[k] = self._rows.pop(k)
        while len(self._rows) > MAX_CACHED_ROWS:  # least recently used first
            del self._rows[next(iter(self._rows))]
        return out

    def forward(self, cells: np.ndarray, rates: np.ndarray) -> np.ndarray:
        """``float64 (k, n_free)`` concentration (ppm) of sources ``rates`` (g/s) in ``cells``.

        The operator is linear: the field per g/s of each source cell is solved
        once (in one batch for the cells not seen before) and cached, the last
        :data:`MAX_CACHED_FIELDS` cells used; clipped at 0 like :meth:`responses`.
        """
        m = self.mesh
        ts = self.transport
        c = np.asarray(cells, dtype=np.int64).reshape(-1, 2)
        keys = [(int(i), int(j)) for i, j in c]
        new = sorted({k for k in keys if k not in self._fields})
        if new:
            nc = np.array(new, dtype=np.int64)
            B = np.zeros((m.n, len(new)))
            B[m.index[nc[:, 0], nc[:, 1]], np.arange(len(new))] = 1.0 / ts.physics.slab_depth
            X = np.maximum(ts.factor(ts.adjoint_scheme).solve(B) * self.physics.ppm_per_gm3, 0.0)
            for k, col in zip(new, X.T, strict=True):
                self._fields[k] = col
        out = np.stack([self._fields[k] for k in keys]) if keys else np.zeros((0, m.n))
        for k in keys:
            self._fields[k] = self._fields.pop(k)
        while len(self._fields) > MAX_CACHED_FIELDS:  # least recently used first
            del self._fields[next(iter(self._fields))]
        return out * np.asarray(rates, dtype=np.float64).reshape(-1, 1)


_FLOWS: OrderedDict[tuple[str, float, float | None, str], FlowModel] = OrderedDict()
#: Guards :data:`_FLOWS`: flows of several hypotheses are solved on threads at once.
_FLOWS_LOCK = threading.Lock()


def _layout_key(layout: Layout) -> str:
    openings = json.dumps(
        [[o.to_dict() for o in layout.inlets], [o.to_dict() for o in layout.outlets]], sort_keys=True
    )
    return map_key(layout.occupancy, layout.resolution) + openings


def flow_model(
    layout: Layout,
    inlet_velocity: float,
    physics: Physics = DEFAULT_PHYSICS,
    settings: FlowSettings | None = None,
    warm_start: FlowModel | None = None,
) -> FlowModel:
    """The built-in solver's flow of ``layout`` at ``inlet_velocity`` (cached, the last 16 kept).

    ``warm_start``: a model of the same layout at another speed; its flow, scaled, starts
    the iteration (:func:`dgse.physics.builtin.flow_and_transport`), which converges to the
    same criteria in fewer iterations, though not to the same turbulence in quiet rooms
    (see :class:`dgse.estimators.phys.PhysicsGuidedEstimator`'s ``warm_start``), so
    warm- and cold-started flows are cached apart, as are flows of other settings.
    """
    v = float(inlet_velocity)
    start_v = None if warm_start is None else round(float(warm_start.inlet_velocity), 9)
    key = (_layout_key(layout), round(v, 9), start_v, repr(settings))
    with _FLOWS_LOCK:
        hit = _FLOWS.get(key)
        if hit is not None and hit.physics == physics:
            _FLOWS.move_to_end(key)
            return hit
    t0 = time.perf_counter()
    start = None if warm_start is None else warm_start.solved
    flow, ts = flow_and_transport(layout, v, physics, settings, warm_start=start)
    info = {
        "converged": bool(flow.info.get("converged", False)),
        "iterations": flow.info.get("iterations"),
        "seconds": time.perf_counter() - t0,
        "warm_start": None if start is None else float(warm_start.inlet_velocity),
    }
    fm = FlowModel(np.asarray(flow.wind, dtype=np.float64), ts, v, info, physics, flow)
    with _FLOWS_LOCK:
        _FLOWS[key] = fm
        while len(_FLOWS) > FLOW_CACHE_SIZE:
            _FLOWS.popitem(last=False)
    return fm


#: Where the proportional noise weights of :func:`adjoint_log_evidence` take their concentrations.
NOISE_WEIGHTS = ("plug-in", "candidate")


def check_noise_weights(mode: object, modes: tuple[str, ...] = NOISE_WEIGHTS) -> None:
    """Raise a clear :class:`InputDataError` unless ``mode`` is one of ``modes`` (by default
    :data:`NOISE_WEIGHTS`; an estimator may offer more, e.g. ``dgse-phys``'s mixture)."""
    if mode not in modes:
        raise InputDataError(f"noise_weights must be one of {modes}, got {mode!r}")


def clear_flow_cache() -> None:
    """Forget the cached flows."""
    with _FLOWS_LOCK:
        _FLOWS.clear()


# -- the posterior ----------------------------------------------------------------------------
def _weighted_sums(
    A: np.ndarray, A2: np.ndarray, z: np.ndarray, r: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray | float]:
    """``(aa, az, zz)``: ``sum_i w a_i^2``, ``sum_i w a_i z_i``, ``sum_i w z_i^2`` per column of ``A``.

    ``w = 1 / r^2``; ``r`` is ``(m,)`` (the same noise weights for every candidate) or
    ``(m, N)`` (each candidate's own); ``zz`` is then a float or ``(N,)``.
    """
    w = 1.0 / r**2
    if w.ndim == 1:
        return np.maximum(w @ A2, evidence_kernel.AA_FLOOR), (w * z) @ A, float(w @ z**2)
    return np.maximum((w * A2).sum(axis=0), evidence_kernel.AA_FLOOR), z @ (w * A), (z * z) @ w


def _evidence_from_sums(
    sums: tuple[np.ndarray, np.ndarray, np.ndarray | float, np.ndarray | float],
    m: int,
    q_max: float | None,
    alpha0: float,
    beta0: float,
) -> tuple[np.ndarray, np.ndarray, float]:
    """``(log p(z | s) per candidate up to an (s, r)-independent constant, qhat, alpha_n)`` of ``m``
    readings from their weighted sums ``(aa, az, zz, sum_i log r_i)``
    (:mod:`~dgse.posterior.evidence_kernel`, or :func:`_weighted_sums`)."""
    aa, az, zz, log_r = sums
    qhat = az / aa
    S = np.maximum(zz - az * qhat, 0.0)
    alpha_n = alpha0 + 0.5 * (m - 1)
    beta_n = beta0 + 0.5 * S
    nu = 2.0 * alpha_n
    with np.errstate(over="ignore"):  # a candidate no reading sees (aa at its floor): scale inf
        scale = np.sqrt(beta_n / (alpha_n * aa))
    logl = -log_r - 0.5 * np.log(aa) - alpha_n * np.log(beta_n)
    # the truncation term (<= 0) only where it can matter: candidates within TRUNC_NATS of
    # the best truncated one (:func:`~dgse.posterior.student_t.log_interval`); the
    # rest, TRUNC_NATS below, keep the untruncated value, an upper bound
    # where both ends lie beyond the t quantile of 1e-13 the term is 0 to double precision
    far = -float(special.stdtrit(nu, 1e-13))
    lo_all = -qhat / scale
    done = lo_all < -far
    if q_max is not None:
        done &= (q_max - qhat) / scale > far
    best = float(logl[done].max()) if done.any() else -np.inf
    while True:
        todo = ~done & (logl >= (best if np.isfinite(best) else logl.max()) - TRUNC_NATS)
        if not todo.any():
            break
        q_, s_ = qhat[todo], scale[todo]
        hi = np.full(q_.shape, np.inf) if q_max is None else (q_max - q_) / s_
        logl[todo] += log_interval(-q_ / s_, hi, nu)
        done |= todo
        best = float(logl[done].max())
    return logl, qhat, alpha_n


#: Gauss-Hermite nodes over the log noise precision in the censored correction.
CENSORED_TAU_NODES = 4
#: Newton steps to the mode of that integrand.
CENSORED_NEWTON_STEPS = 5
#: Gauss-Legendre nodes per piece over the release rate (pieces refine towards the low end).
CENSORED_Q_NODES = 4
#: Breakpoints of those pieces in the rate's CDF, closer near ``q = 0`` where the factor falls steeply.
CENSORED_Q_PIECES = (0.0, 1.0 / 512, 1.0 / 64, 1.0 / 8, 1.0)
#: The share of the posterior mass the candidates left at the zeros' plug-in factor may hold.
CENSORED_TAIL = 1e-4


@functools.cache
def _censored_nodes(
    q_nodes: int, q_pieces: tuple[float, ...], tau_nodes: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The censored correction's rules: ``(u, log w_u)`` composite Gauss-Legendre over the
    rate's CDF pieces, ``(x, w)`` Gauss-Hermite over ``log tau``."""
    xg, wg = np.polynomial.legendre.leggauss(q_nodes)
    us, ws = [], []
    for a, b in itertools.pairwise(q_pieces):
        us.append(a + (b - a) * 0.5 * (xg + 1.0))
        ws.append((b - a) * 0.5 * wg)
    xh, wh = special.roots_hermite(tau_nodes)
    return np.concatenate(us), np.log(np.concatenate(ws)), xh, wh


def _censored_log_factor(
    Bt: np.ndarray,
    qhat: np.ndarray,
    aa: np.ndarray,
    beta_n: np.ndarray,
    alpha_n: float,
    q_max: float | None,
    log_mass: np.ndarray,
    tilt_min: float = censored_kernel.TILT_MIN,
) -> np.ndarray:
    """``log E[prod_i Phi(-q B_i sqrt(tau))]`` under the posterior of ``(q, tau)`` from the positive readings.

    Args:
        Bt: ``(n, c)`` censored readings' responses over their noise weights (``a_i / r_i``),
            a row for each of ``n`` candidate sources.
        qhat, aa, beta_n: ``(n,)`` the uncensored readings' least-squares rate, weighted
            ``sum a^2`` and the noise posterior's rate.
        alpha_n: the noise posterior's shape.
        q_max: the rate prior's upper end (None: unbounded).
        log_mass: ``(n,)`` ``log P(0 <= q <= q_max)`` under the uncensored posterior (the
            Student-t mass of :func:`_evidence_from_sums`): the normalizer.
        tilt_min: where the rate's nodes follow the zeros
            (:data:`~dgse.posterior.censored_kernel.TILT_MIN`; ``inf``: never).

    Given ``tau``, ``q`` is ``N(qhat, 1 / (tau aa))`` truncated to ``[0, q_max]``; ``tau`` is
    ``Gamma(alpha_n, beta_n)`` weighted by that truncation's mass.  The zeros can move the
    noise floor far from where the positive readings put it (a zero where the plume should
    be says the noise is large), so the integral over ``log tau`` is adaptive: Newton steps
    find the mode of the integrand (rate at its conditional mean), then Gauss-Hermite nodes
    around it; at each node, composite Gauss-Legendre nodes over the rate's conditional CDF.
    Every node enters through ``lambda = q sqrt(tau)`` and ``G(lambda) = sum_i log Phi(-lambda
    B_i)``, one analytic function per candidate (linear at 0, quadratic far out): it is
    evaluated exactly at ``CENSORED_CHEBYSHEV_POINTS`` Chebyshev points of ``[0, max
    lambda]`` and interpolated to the nodes (Clenshaw's recurrence), far below the
    quadrature's error.  The loop over candidates is compiled
    (:func:`dgse.posterior.censored_kernel.censored_log_factor`).
    """
    u, log_wu, xh, wh = _censored_nodes(CENSORED_Q_NODES, CENSORED_Q_PIECES, CENSORED_TAU_NODES)
    return censored_kernel.censored_log_factor(
        np.ascontiguousarray(Bt, dtype=np.float64),
        np.ascontiguousarray(qhat, dtype=np.float64),
        np.ascontiguousarray(aa, dtype=np.float64),
        np.ascontiguousarray(beta_n, dtype=np.float64),
        float(alpha_n),
        math.inf if q_max is None else float(q_max),
        np.ascontiguousarray(log_mass, dtype=np.float64),
        u,
        log_wu,
        xh,
        wh,
        _chebyshev_coefficient_matrix(CENSORED_CHEBYSHEV_POINTS),
        CENSORED_NEWTON_STEPS,
        CENSORED_FLOOR,
        CENSORED_SCAN_MARGIN,
        np.zeros(len(qhat), dtype=np.uint8),
        tilt_min,
    )


#: The zeros' factor (nats) of a candidate whose integrand underflows everywhere.
CENSORED_FLOOR = -1e4
#: The miss (nats) of the Gauss-Hermite value, by a probe, above which a candidate is scanned instead.
CENSORED_SCAN_MARGIN = 0.5
#: Chebyshev points for the zeros' factor as a function of ``lambda = q sqrt(tau)``.
CENSORED_CHEBYSHEV_POINTS = 10


@functools.cache
def _chebyshev_coefficient_matrix(k: int) -> np.ndarray:
    """``(k, k)``: values at the ``k`` Chebyshev points ``y_j = -cos(pi j / (k - 1))`` to coefficients.

    The interpolant is ``sum_m c_m T_m(y)``; at these points the discrete cosine transform
    gives ``c_m = (2 / (k - 1)) sum_j'' f_j T_m(y_j)`` (ends halved, and ``c_0``, ``c_{k-1}`` halved).
    """
    j = np.arange(k)
    T = np.cos(np.outer(j, np.pi - np.pi * j / (k - 1)))  # T_m(y_j) = cos(m arccos y_j)
    w = np.full(k, 2.0 / (k - 1))
    w[[0, -1]] *= 0.5
    M = T * w[None, :]
    M[[0, -1]] *= 0.5
    return M


def _censored_setup(
    A: np.ndarray,
    z: np.ndarray,
    r: np.ndarray,
    q_max: float | None,
    alpha0: float,
    beta0: float,
    tilt: bool,
    sums: tuple[np.ndarray, np.ndarray, np.ndarray | float] | None,
) -> dict[str, Any]:
    """What :func:`censored_correction` computes from its inputs alone (not from ``logl``): the
    zeros' responses over their noise weights a row per candidate (``Bt``), the positive
    readings' rate estimate, sums and noise posterior, the candidates the zeros hardly see
    (``faint``, None without a rate bound), each zero's bound ``(1/2)`` summed (``ceiling``),
    and room for the plug-in and integrated factors (``plug``, ``exact``: nan until computed).
    ``sums``: the positive readings' weighted sums, where the caller has them."""
    cen = z <= 0.0
    pos = ~cen
    alpha_n = alpha0 + 0.5 * (int(pos.sum()) - 1)
    # the zeros' responses over their noise weights, a row per candidate
    rc = r if r.shape[0] != z.size else r[cen]  # the zeros' rows, or every reading's
    Bt = np.ascontiguousarray((A[cen] / (rc if rc.ndim == 2 else rc[:, None])).T)
    qmax = np.inf if q_max is None else q_max
    # the positive readings' rate and noise posterior, for the plug-in and integrated factors
    if sums is None:
        if r.shape[0] != z.size:
            raise InputDataError("noise weights of the zeros alone need the positive readings' sums")
        Ap = A[pos]
        sums = _weighted_sums(Ap, Ap * Ap, z[pos], r[pos])
    aa, az, zz = sums
    qh = az / aa
    beta_n = beta0 + 0.5 * np.maximum(zz - az * qh, 0.0)
    tilt_min = censored_kernel.TILT_MIN if tilt else math.inf
    faint = None
    if math.isfinite(qmax):
        tau_hi = special.gammainccinv(alpha_n, 1e-12) / beta_n
        faint = qmax * np.sqrt(tau_hi) * np.maximum(Bt, 0.0).sum(axis=1) < CENSORED_FAINT
    return {
        "Bt": Bt, "qh": qh, "aa": aa, "beta_n": beta_n, "alpha_n": alpha_n, "tilt_min": tilt_min,
        "faint": faint, "ceiling": -math.log(2.0) * (Bt >= 0.0).sum(axis=1),
        "plug": np.full(qh.shape, np.nan), "exact": np.full(qh.shape, np.nan),
    }  # fmt: skip


def censored_correction(
    A: np.ndarray,
    z: np.ndarray,
    r: np.ndarray,
    logl: np.ndarray,
    *,
    q_max: float | None,
    alpha0: float,
    beta0: float,
    tail: float = CENSORED_TAIL,
    tilt: bool = True,
    memo: dict[str, Any] | None = None,
    sums: tuple[np.ndarray, np.ndarray, np.ndarray | float] | None = None,
) -> np.ndarray:
    """``log p(z_censored | z_rest, s)`` per candidate ``s``: what the zero readings add.

    A reading clipped at zero says only that the noisy concentration was at most 0:
    ``P = Phi(-q a_i(s) / (sigma r_i))``.  Integrated over the posterior of the rate and the
    noise floor given the positive readings (:func:`_censored_log_factor`) for the candidates
    that hold the posterior mass: candidates are ranked, and the exact factor is computed
    down the ranking until the rest hold less than ``tail`` of the mass computed so far; the
    rest keep a plug-in value (the noise at its point estimate, the rate at the positive
    readings' estimate or, where the zeros move it, at the maximum of the two factors
    together: :func:`~dgse.posterior.censored_kernel.tilted_plug_in_log_factor`), and
    those whose bound (``1/2`` a zero) lies :data:`CENSORED_NEGLIGIBLE_NATS` below the best
    plug-in value keep that bound, no plug-in value computed.

    The ranking is by that plug-in value, an approximation: after few positive readings the
    noise posterior is broad and the plug-in factor of a candidate the zeros see well can sit
    far below the integrated one, so the cut can leave out mass.  It acts as a tighter noise
    prior, which the searches were measured with (``docs/decisions.md``).

    ``tilt`` (default True): where the zeros move the rate far from the positive readings'
    estimate, the rate's nodes and the plug-in value follow them (see the module doc's
    "Zero readings"); False: they stay at the positive readings' estimate.

    ``memo``: a dict shared by calls with the same ``A``, ``z``, ``r``, ``q_max``, ``alpha0``,
    ``beta0`` and ``tilt`` (the caller's promise; ``logl`` and ``tail`` may differ): every
    candidate's plug-in and integrated factors are computed once and reused (the same numbers
    as computed afresh).  The two noise-weight modes of
    :class:`~dgse.estimators.phys.PhysicsGuidedEstimator` share them where their most probable
    ``kappa`` gives the same weights.

    Args:
        A: ``(m, N)`` responses.
        z: ``(m,)`` readings (zeros are the censored ones).
        r: ``(m,)`` noise weights, or ``(m, N)``: each candidate's own; with ``sums``, the
            zeros' rows alone will do (``(n_zeros,)`` or ``(n_zeros, N)``).
        logl: ``(N,)`` the positive readings' log evidence.
        sums: the positive readings' weighted sums ``(sum w a^2, sum w a z, sum w z^2)`` with
            these weights (``w = 1 / r^2``), where the caller has them
            (:func:`adjoint_log_evidence` does; computed here otherwise).
    """
    cen = z <= 0.0
    if not cen.any():
        return np.zeros(logl.shape)
    if memo is None:
        memo = {}
    if "plug" not in memo:
        memo.update(_censored_setup(A, z, r, q_max, alpha0, beta0, tilt, sums))
    Bt, qh, aa, beta_n, alpha_n = memo["Bt"], memo["qh"], memo["aa"], memo["beta_n"], memo["alpha_n"]
    tilt_min, plug, exact, ceiling = memo["tilt_min"], memo["plug"], memo["exact"], memo["ceiling"]
    # a plug-in pass (rate and noise at their estimates) orders the candidates and stands in
    # for the exact factor where the mass is negligible: for every candidate whose bound (the
    # positive readings' evidence and 1/2 a zero) comes within CENSORED_NEGLIGIBLE_NATS of the
    # best plug-in value, best bound first; the others keep their bound (a mass below
    # exp(-CENSORED_NEGLIGIBLE_NATS) each either way)
    bound = logl + ceiling
    by_bound = np.argsort(bound)[::-1]
    qmax = np.inf if q_max is None else q_max
    best = -math.inf
    for k in range(0, by_bound.size, CENSORED_PLUG_BLOCK):
        blk = by_bound[k : k + CENSORED_PLUG_BLOCK]
        if bound[blk[0]] < best - CENSORED_NEGLIGIBLE_NATS:
            break
        new = blk[np.isnan(plug[blk])]
        if new.size:
            plug[new] = censored_kernel.tilted_plug_in_log_factor(
                np.ascontiguousarray(Bt[new]),
                qh[new],
                aa[new],
                np.log(alpha_n / beta_n[new]),
                float(qmax),
                tilt_min,
            )
        best = max(best, float(np.max(logl[blk] + plug[blk])))
    out = np.where(np.isnan(plug), ceiling, plug)
    key = logl + out
    # the ranking and the stop: the plug-in value (see above)
    rank_key = key
    order = np.argsort(rank_key)[::-1]
    # candidates the zero sensors hardly see: where even the largest plausible
    # lambda = q sqrt(tau) (q at its prior's end, tau at its 1 - 1e-12 quantile) gives
    # lambda sum_i B_i below CENSORED_FAINT, every factor Phi(-lambda B_i) is 1/2 to first
    # order, and the plug-in value is within that many nats of the integrated one
    top = float(rank_key[order[0]])
    got = 0.0
    if memo["faint"] is not None:
        faint = memo["faint"]
        got = float(np.exp(key[faint] - top).sum())
        order = order[~faint[order]]
    rest = np.cumsum(np.exp(rank_key[order] - top)[::-1])[::-1]  # ranked mass from position k on

    def factor(idx: np.ndarray) -> np.ndarray:
        with np.errstate(over="ignore"):  # a candidate no positive reading sees: scale inf
            scale = np.sqrt(beta_n[idx] / (alpha_n * aa[idx]))
        hi = np.full(idx.shape, np.inf) if q_max is None else (q_max - qh[idx]) / scale
        log_mass = log_interval(-qh[idx] / scale, hi, 2.0 * alpha_n)
        return _censored_log_factor(
            Bt[idx], qh[idx], aa[idx], beta_n[idx], alpha_n, q_max, log_mass, tilt_min
        )

    # chunks down the ranking, as many at once as there are worker threads (the compiled
    # kernel releases the GIL), until the rest of the ranking holds a negligible share;
    # candidates a call with the same memo integrated already are not integrated again
    done = 0
    chunk = CENSORED_CHUNK
    while done < order.size:
        idxs = [
            order[k : k + chunk] for k in range(done, min(done + chunk * threads.WORKERS, order.size), chunk)
        ]
        todo = [idx[np.isnan(exact[idx])] for idx in idxs]
        todo = [idx for idx in todo if idx.size]
        for idx, f in zip(todo, threads.map_threads(factor, todo), strict=True):
            exact[idx] = f
        for idx in idxs:
            out[idx] = exact[idx]
            got += float(np.exp(logl[idx] + exact[idx] - top).sum())
            done += idx.size
        if done < order.size and rest[done] < tail * got:
            break
    # each zero with a non-negative response has probability at most 1/2: a bound the
    # quadrature can overshoot by a few hundredths of a nat when the posterior is broad
    return np.minimum(out, ceiling)


#: The error (nats) of the plug-in factor that stands for a candidate the zero sensors hardly see.
CENSORED_FAINT = 1e-3
#: Candidates per chunk of the censored correction (chunks run on :func:`dgse.threads.map_threads`).
CENSORED_CHUNK = 256
#: Candidates whose bound lies this many nats below the best plug-in value keep their bound.
CENSORED_NEGLIGIBLE_NATS = 50.0
#: Candidates per block of the plug-in pass down the bounds.
CENSORED_PLUG_BLOCK = 512


class Details(dict):
    """The ``details`` of :func:`adjoint_log_evidence`: a dict in which some entries are computed
    when first read (:meth:`lazy`).  ``"r"`` is one: with each candidate's own noise weights it
    is an ``(m, N)`` array, a few milliseconds to build in every call of a search step, and
    only the step's best flow hypothesis reads it."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._lazy: dict[str, Callable[[], Any]] = {}

    def lazy(self, key: str, make: Callable[[], Any]) -> None:
        """Let ``self[key]`` be ``make()``, computed on the first read and kept."""
        self.pop(key, None)
        self._lazy[key] = make

    def __missing__(self, key: str) -> Any:
        make = self._lazy.pop(key, None)
        if make is None:
            raise KeyError(key)
        value = self[key] = make()
        return value

    def __contains__(self, key: object) -> bool:
        return super().__contains__(key) or key in self._lazy

    def get(self, key: str, default: Any = None) -> Any:
        return self[key] if key in self else default


def adjoint_log_evidence(
    A: np.ndarray,
    z: np.ndarray,
    *,
    q_max: float | None = 5.0,
    kappas: Sequence[float] = DEFAULT_KAPPAS,
    alpha0: float = 1.0,
    sigma0_fraction: float = 0.25,
    censored: bool | Literal["deferred"] = True,
    noise_weights: Literal["plug-in", "candidate"] = "plug-in",
) -> tuple[np.ndarray, dict[str, Any]]:
    """``log p(z | s)`` for every candidate source (columns of ``A``), release rate and noise integrated out.

    Args:
        A: ``(m, N)`` responses: reading ``i`` (ppm) per g/s released in candidate ``s``.
        z: ``(m,)`` readings, ppm (>= 0).
        q_max: upper end of the uniform release-rate prior, g/s (None: flat on ``q >= 0``).
        kappas: grid of the proportional-noise weight ``kappa`` (averaged, equal prior weights);
            ``(0,)`` gives a homoscedastic model.
        alpha0: shape of the Gamma prior on the noise precision.
        sigma0_fraction: prior noise scale ``s0 = sigma0_fraction * mean(z)`` (``beta0 = alpha0 s0^2``).
        censored: treat readings of 0 as censored (the sensor clips negatives: such a reading
            says only that the noisy concentration was at most 0, :func:`censored_correction`);
            False reads them as exact zeros; ``"deferred"`` returns the positive readings'
            evidence and leaves the zeros' factor to the caller (``details["censor"]``: the
            keyword arguments of :func:`censored_correction` besides ``logl``), for callers
            that skip it where it cannot matter.
        noise_weights: where the proportional noise ``r_i = 1 + kappa c_i / cbar`` takes its
            concentrations ``c_i`` (:data:`NOISE_WEIGHTS`): ``"plug-in"``, the posterior-predictive
            mean of a first, homoscedastic pass (the same weights for every candidate);
            ``"candidate"``, each candidate's own prediction ``clip(qhat, 0, q_max) a_i(s)``
            of that pass (Table I's noise given that source: a candidate that predicts high
            concentrations where the readings are low pays ``log r_i`` for each).

    Returns:
        ``(log_evidence (N,), details)`` with ``details`` (a :class:`Details`): ``qhat`` ``(N,)``
        (least-squares rate of the most probable ``kappa``, g/s), ``kappa_weights`` (posterior
        weights of ``kappas``), ``kappa`` (the most probable), ``chat`` ``(m,)`` (plug-in
        concentrations) and ``cbar`` (their mean), ``best`` (the most probable candidate),
        ``s0`` (the prior noise scale, ppm), ``censored`` (how many zeros), ``r`` (the most
        probable ``kappa``'s noise weights, ``(m,)`` or ``(m, N)``, built when first read) and,
        with ``censored="deferred"``, ``censor``.  The evidence is defined up to a constant
        independent of ``s`` (the same for every ``kappa``).
    """
    A = np.ascontiguousarray(A, dtype=np.float64)
    z = np.maximum(np.asarray(z, dtype=np.float64).reshape(-1), 0.0)
    if A.ndim != 2 or A.shape[0] != z.size or z.size == 0:
        raise InputDataError(f"responses {A.shape} do not match {z.size} readings")
    if q_max is not None and not (q_max > 0 and math.isfinite(q_max)):
        raise InputDataError(f"q_max must be a positive number of g/s or None, got {q_max}")
    ks = [float(k) for k in kappas]
    if not ks or any(not (k >= 0 and math.isfinite(k)) for k in ks):
        raise InputDataError(f"kappas must be finite and >= 0, got {kappas}")
    check_noise_weights(noise_weights)
    s0 = max(sigma0_fraction * float(z.mean()), 1e-9 * max(float(z.max()), 1.0), 1e-12)
    beta0 = alpha0 * s0**2
    ones = np.ones_like(z)
    # readings clipped at zero are censored: the Gaussian part takes the others, and the
    # zeros enter as P(reading <= 0) (censored_correction); the sums read the positive
    # readings' rows in place (evidence_kernel)
    cen = (z <= 0.0) if censored else np.zeros(z.shape, dtype=bool)
    pos = ~cen
    rows = np.flatnonzero(pos)
    zp = z[pos]
    m = int(rows.size)
    details = Details(s0=s0, censored=int(cen.sum()))

    def _censored(logl: np.ndarray, r: np.ndarray, sums: tuple[np.ndarray, ...]) -> np.ndarray:
        if not cen.any():
            return logl
        kw = {"A": A, "z": z, "r": r, "q_max": q_max, "alpha0": alpha0, "beta0": beta0, "sums": sums}
        if censored == "deferred":
            details["censor"] = kw
            return logl
        return logl + censored_correction(logl=logl, **kw)

    aa0, az0 = evidence_kernel.row_sums(A, rows, z, ones[None, :])
    sums0 = (aa0[0], az0[0], float(zp @ zp))
    logl0, qhat0, _ = _evidence_from_sums((*sums0, 0.0), m, q_max, alpha0, beta0)
    if ks == [0.0]:
        logl0 = _censored(logl0, ones[cen], sums0)
        best = int(np.argmax(logl0))
        details.update(qhat=qhat0, kappa_weights=np.ones(1), kappa=0.0, chat=None, best=best, r=ones)
        return logl0, details
    # plug-in concentrations at the sensors from the homoscedastic pass (positive readings)
    post0 = np.exp(logl0 - logl0.max())
    post0 /= post0.sum()
    qclip = np.clip(qhat0, 0.0, np.inf if q_max is None else q_max)
    chat = A @ (post0 * qclip)
    chat = np.maximum(chat, 0.0)
    cbar = float(chat.mean())
    if not cbar > 0:
        ks = [0.0]
    logls, qhats, totals = [], [], []

    # each candidate's own concentrations at the sensors (the kernels' max(a q, floor) with a
    # zero floor): its prediction ("candidate"); None: the plug-in for every candidate
    floor = np.zeros_like(z) if noise_weights == "candidate" else None

    def weights(k: float, which: np.ndarray | None = None) -> np.ndarray:
        """The noise weights of ``kappa = k``, of every reading or of the readings ``which``."""
        if k == 0.0:
            return ones if which is None else ones[which]
        if floor is not None:
            if which is None:
                return evidence_kernel.own_weights(A, qclip, floor, k / cbar)
            return evidence_kernel.own_weights(A[which], qclip, floor[which], k / cbar)
        r = 1.0 + k * chat / cbar
        return r if which is None else r[which]

    # the weighted sums of every kappa > 0 from one pass over the positive readings' rows
    heavy = [k for k in ks if k != 0.0]
    if not heavy:
        many: tuple[np.ndarray, ...] = ()
    elif floor is not None:
        cs = np.array([k / cbar for k in heavy])
        many = evidence_kernel.candidate_sums_many(A, rows, qclip, floor, z, cs)
    else:
        r_all = np.stack([weights(k)[pos] for k in heavy])  # (K, m_pos)
        w_pos = 1.0 / r_all**2
        w_all = np.zeros((len(heavy), z.size))
        w_all[:, pos] = w_pos
        aa_all, az_all = evidence_kernel.row_sums(A, rows, z, w_all)
        many = (aa_all, az_all, w_pos @ zp**2, np.log(r_all).sum(axis=1))
    all_sums = []
    for k in ks:
        # kappa = 0 is the homoscedastic pass above
        if k == 0.0:
            ll, qh = logl0, qhat0
            all_sums.append(sums0)
        else:
            j = heavy.index(k)
            sums = (many[0][j], many[1][j], many[2][j], many[3][j])
            ll, qh = _evidence_from_sums(sums, m, q_max, alpha0, beta0)[:2]
            all_sums.append(sums[:3])
        logls.append(ll)
        qhats.append(qh)
        top = ll.max()
        totals.append(top + math.log(np.exp(ll - top).sum()))
    L = np.stack(logls)
    top = L.max(axis=0)
    logl = top + np.log(np.exp(L - top).mean(axis=0))
    tot = np.array(totals)
    kw = np.exp(tot - tot.max())
    kw /= kw.sum()
    kbest = int(np.argmax(kw))
    # the zeros' factor with the most probable kappa's noise weights (one pass, not one per
    # kappa): the zeros' rows of them and the sums above; every reading's weights (an (m, N)
    # array with each candidate's own) only when a caller reads details["r"]
    k_best = ks[kbest]
    logl = _censored(logl, weights(k_best, cen), all_sums[kbest])
    details.update(
        qhat=qhats[kbest],
        kappa_weights=kw,
        kappa=k_best,
        chat=chat,
        cbar=cbar,
        best=int(np.argmax(logl)),
    )
    details.lazy("r", lambda: weights(k_best))
    return logl, details


def sigma_floor(A: np.ndarray, z: np.ndarray, r: np.ndarray, s: int, alpha0: float, beta0: float) -> float:
    """Posterior-mean noise floor ``E[sigma^2]^(1/2)`` given the source ``s`` (ppm).

    ``r``: the noise weights, ``(m,)`` or ``(m, N)`` (each candidate's own: column ``s``).
    """
    w = 1.0 / (r[:, s] if r.ndim == 2 else r) ** 2
    a = A[:, s]
    aa = max(float(w @ a**2), 1e-300)
    az = float((w * z) @ a)
    S = max(float(w @ z**2) - az * az / aa, 0.0)
    alpha_n = alpha0 + 0.5 * (z.size - 1)
    beta_n = beta0 + 0.5 * S
    return math.sqrt(beta_n / max(alpha_n - 1.0, 0.5))


# -- the planner-side response model ----------------------------------------------------------
@dataclass(eq=False)
class AdjointResponseModel:
    """Predicted readings for planners: ``E[z at x | source s] = qhat(s) a_x(s)`` (ppm).

    Attributes:
        flow: the flow model whose adjoint gives ``a_x``.
        q_map: ``(n_free,)`` release rate per candidate source (``clip(qhat, 0, q_max)``), g/s.
        sigma_floor: noise floor, ppm.
        kappa: proportional noise weight; ``sigma(mu) = sigma_floor (1 + kappa mu / cbar)``.
        cbar: the concentration scale of ``kappa`` (ppm).
    """

    flow: FlowModel
    q_map: np.ndarray
    sigma_floor: float
    kappa: float = 0.0
    cbar: float = 1.0
    kind: str = "ppm"

    def mean_readings(self, cells: np.ndarray) -> np.ndarray:
        """``(k, H, W)`` expected reading (ppm) at ``cells[k]`` per source in each free cell (0 on walls)."""
        rows = self.flow.responses(cells) * self.q_map[None, :]
        return self.flow.mesh.field(np.maximum(rows, 0.0))

    def reading_sigma(self, mean: np.ndarray) -> np.ndarray:
        """Noise standard deviation (ppm) of a reading with mean ``mean``."""
        return self.sigma_floor * (1.0 + self.kappa * np.asarray(mean) / max(self.cbar, 1e-12))

    def __repr__(self) -> str:
        return f"<AdjointResponseModel v_in={self.flow.inlet_velocity:.3g}>"
