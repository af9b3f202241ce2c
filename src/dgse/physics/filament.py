"""Filament dispersion on a steady wind field: GADEN's model (Farrell et al. 2002) in 2-D.

Gas leaves the source as *filaments*, ``filaments_per_second`` of them, each
carrying the fixed mass ``Q_f = q / filaments_per_second`` (g).  A filament is
a 2-D Gaussian puff whose width grows as ``sigma^2 = sigma0^2 + gamma * age``
(up to ``sigma_max``); its centre moves as
``x += h (w(x) + grad D(x)) + sqrt(2 D(x) h) xi`` with ``xi ~ N(0, I)``.
A snapshot of the concentration is the sum of the puffs (each spread over the
slab depth ``h``), so snapshots are *intermittent*: a sensor sees the passing
filaments, not the time mean.  The time mean approaches the steady
advection-diffusion solution with diffusivity ``D + gamma / 2``.

Design choices (parameters in :class:`FilamentSettings`):

* **Wind**: the case's cell-centred wind, turned into normal velocities on the
  cell faces (mean of the two cells; the boundary cell's at openings; 0 on wall
  faces and closed edges), projected to be exactly divergence-free in every
  free cell (:func:`face_velocities`), and interpolated across a cell
  linearly, each component along its own axis (Pollock's scheme).  Unlike
  bilinear interpolation of the cell-centred wind (0 in walls), this field
  conserves volume, so well-mixed gas stays well mixed, and it carries no
  filament into a wall.  The drift is integrated with the midpoint rule
  (explicit Euler spirals out of every eddy: in a 1 rad/s vortex it piled the
  gas against the walls).
* **Turbulent noise** (``noise="turbulent"``, the default): the random walk has
  the RANS eddy diffusivity of spec section 4, ``D = D_m + nu_t / Sc_t``, less
  ``gamma / 2`` (floored at 0) while a filament still widens, because its
  growth already diffuses that much: the mean filament field solves the
  steady model's equation.  ``D`` is bilinear between cell centres (solid
  cells take their free neighbours' mean: zero normal gradient at walls) and
  the Ito drift ``grad D`` is added to the wind, so that gas does not gather
  where ``D`` is small.  ``nu_t`` comes from the built-in solver's flow
  (:func:`dgse.physics.builtin.flow_and_transport`).
* **Constant noise** (``noise="constant"``, GADEN's model): velocity noise of
  standard deviation ``noise_std`` m/s per axis, applied per step ``dt``:
  the uniform diffusivity ``D = noise_std^2 dt / 2`` (GADEN's 0.1 m/s at
  ``dt = 0.1 s`` gives ``5e-4 m^2/s``, far below indoor eddy diffusivities of
  ``1e-3`` to ``0.5 m^2/s``).
* **Time step**: ``dt`` (0.1 s; the step used is ``frame_dt / ceil(frame_dt /
  dt)`` so that frames fall on steps) is split per filament into sub-steps
  in which the drift moves a filament at most ``max_cfl`` (0.5) of a cell and
  the noise's standard deviation is at most ``max_noise_std`` (1) cell: a
  9 m/s jet at 0.1 m cells takes 18 sub-steps per 0.1 s, still air one.  So
  ``dt`` sets only the release and bookkeeping granularity, not stability.
* **Walls**: every sub-step is traced cell by cell (Amanatides-Woo) from the
  old to the new position.  A step that would enter a solid cell or cross a
  closed edge is rejected and the filament *slides*: it tries the move along
  the axis of the larger displacement alone, then along the other, and stays
  where it is if both are blocked.  At a straight wall this keeps the walk
  symmetric (uniform gas stays uniform) while the tangential wind still
  carries filaments along.  Filaments never enter solid cells or leave
  through closed boundaries.
* **Openings**: a filament whose step crosses the domain edge at an opening
  (outlet, or inlet: ``c = 0`` there, as in the steady model) is removed.
  With a boolean mask of open boundary cells, a masked cell is open on every
  domain side it touches (matters only for corner cells).
* **Release**: the ``q dt`` worth of filaments of one step are born at
  uniformly random times within the step and moved for the rest of it (no
  beading at high wind), at the source plus ``N(0, sigma0^2)`` per axis (at
  the source itself if that point is across a wall).
* **Start**: with a steady concentration field (``prefill``; a case's own),
  the domain starts with the filaments of that field, aged the mean residence
  time (capped), instead of empty: poorly ventilated rooms would otherwise
  need several residence times (many minutes) of warm-up.
* **Concentration**: a filament adds its Gaussian *integrated over each cell*
  (erf differences: exact mass even when ``sigma0 = 1.5 cm << 0.1 m``) within
  ``kernel_sigmas`` (3) widths, as a product of two axis weights, each folded
  back at the wall or domain edge that bounds the free run of cells through
  the filament along that axis (an image filament: exact zero-flux straight
  walls), over the cells in line of sight of the filament's cell, and
  renormalized so that every filament puts exactly ``Q_f / h`` into the free
  cells (what corners and shadows would lose).  Line of sight is a grid test:
  a cell is visible if it is free and its parent (the cell one ring closer to
  the filament's cell on the digital straight line) is visible, with no
  corner-cutting between two diagonal solid cells; one visibility map serves
  all filaments of a cell, and windows without a solid cell (summed-area
  table) skip it.  Values are ppm (``c[g/m^3] * ppm_per_gm3``), 0 in solid
  cells.
* **Randomness**: a SplitMix64 stream inside the compiled kernels, seeded from
  the numpy Generator: the frames are a deterministic function of the seed.

The particle loop and the splatting are numba kernels, pure functions of
arrays (``numba.njit(cache=True, nogil=True)``, as in :mod:`dgse.physics.fv`).
Cost grows with the filaments in the air, ``filaments_per_second`` times the
mean residence time: about 1 000 for a well ventilated 10 x 10 m case (300 s
in a few seconds), 50 000 for a poorly ventilated one (about a minute), and
hundreds of thousands in rooms the inlet hardly reaches; ``max_filaments``
bounds it by releasing fewer, heavier filaments.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field, fields, replace
from typing import TYPE_CHECKING, Any

import numba
import numpy as np

from dgse.errors import ConvergenceError, InputDataError
from dgse.files import json_safe
from dgse.physics.constants import DEFAULT_PHYSICS, RECOMMENDED_MAX_FILAMENTS, Physics
from dgse.world.case import Case
from dgse.world.generate import RngLike, as_generator
from dgse.world.grid import DEFAULT_RESOLUTION, cell_index

if TYPE_CHECKING:
    from dgse.physics.rans import FlowSettings

__all__ = [
    "NOISE_MODELS",
    "RECOMMENDED_MAX_FILAMENTS",
    "FilamentRun",
    "FilamentSettings",
    "face_velocities",
    "make_filament_case",
    "run_filaments",
    "simulate_filaments",
    "walk_diffusivity",
]

_jit = numba.njit(cache=True, nogil=True)
#: small helpers of the particle loop, inlined into it (twice as fast as calls)
_jit_inline = numba.njit(cache=True, nogil=True, inline="always")

#: ``"turbulent"``: diffusivity from the RANS ``nu_t``; ``"constant"``: GADEN's velocity noise.
NOISE_MODELS = ("turbulent", "constant")

# move outcomes
_OK, _BLOCKED, _EXITED = 0, 1, 2


@dataclass(frozen=True)
class FilamentSettings:
    """Parameters of a filament simulation (SI units; defaults after GADEN, see the module doc).

    Attributes:
        release_rate: source strength ``q`` in g/s; ``None`` takes the case's
            ``meta["release_rate_gps"]`` (:func:`make_filament_case`).
        filaments_per_second: filaments released per second (GADEN: 100);
            each carries ``release_rate / filaments_per_second`` g.
        dt: longest time step in s (default 0.1); the step used is
            ``frame_dt / ceil(frame_dt / dt)``.  Sub-steps keep moves under
            ``max_cfl`` / ``max_noise_std`` cells, so any ``dt`` is stable.
        max_cfl: largest drift displacement of one sub-step, in cells.
        max_noise_std: largest standard deviation of the noise displacement
            of one sub-step, in cells.
        sigma0: initial filament width in m (GADEN: 1.5 cm).
        gamma: filament growth ``d(sigma^2)/dt`` in m^2/s (GADEN: 10 cm^2/s).
        sigma_max: filaments stop growing at this width in m (default 0.3 m,
            reached at an age of about 90 s); it bounds the cost of old
            filaments (a window of ``(2 kernel_sigmas sigma / res)^2`` cells
            each).  ``None``: unbounded growth, as GADEN.
        noise: ``"turbulent"`` (diffusivity from the RANS eddy viscosity) or
            ``"constant"`` (GADEN's constant velocity noise).
        noise_std: standard deviation per axis of the velocity noise in m/s
            (``noise="constant"`` only; GADEN: 0.1).
        prefill: start from the steady state rather than from an empty
            domain: ``M / Q_f`` filaments (``M`` the gas mass of the steady
            concentration field) drawn from that field, aged ``M / q`` (the
            mean residence time) or ``prefill_max_age`` if less.  Used when a
            steady field is given (:func:`make_filament_case` gives the
            case's); without it, filling rooms that are poorly ventilated takes
            several residence times (minutes to hours of simulated time).
        prefill_max_age: cap of the prefilled filaments' age, s.
        warmup: simulated seconds before the first frame: the release must
            establish the plume (at least the source-to-outlet travel time;
            without ``prefill``, a few mean residence times).
        frame_dt: seconds between frames.
        duration: recorded seconds; ``round(duration / frame_dt)`` frames.
        kernel_sigmas: a filament is evaluated within this many widths.
        max_filaments: cap of the filaments that stand for the steady field
            at the start (``prefill``).  Where ``M / Q_f`` exceeds it (rooms
            the inlet hardly reaches hold millions), that many heavier
            filaments carry the same mass ``M``; the release keeps its
            ``Q_f``, so the fresh plume is as fine as without the cap, and
            only the old, wide, well mixed background gets grainier.  It
            bounds the cost of a run, with ``duration``.  Default
            :data:`RECOMMENDED_MAX_FILAMENTS`; ``None``: no cap (a quiet room of
            test scenario 2005 then held over 14 GB of filaments before it was
            stopped).
        project_wind: make the face velocities divergence-free
            (:func:`face_velocities`); off, they are plain means of the cells.
    """

    release_rate: float | None = None
    filaments_per_second: float = 100.0
    dt: float = 0.1
    max_cfl: float = 0.5
    max_noise_std: float = 1.0
    sigma0: float = 0.015
    gamma: float = 1.0e-3
    sigma_max: float | None = 0.3
    noise: str = "turbulent"
    noise_std: float = 0.1
    prefill: bool = True
    prefill_max_age: float = 120.0
    warmup: float = 60.0
    frame_dt: float = 0.5
    duration: float = 120.0
    kernel_sigmas: float = 3.0
    max_filaments: int | None = RECOMMENDED_MAX_FILAMENTS
    project_wind: bool = True

    def __post_init__(self) -> None:
        problems = []

        def check(name: str, allow_zero: bool = False) -> None:
            v = getattr(self, name)
            ok = isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
            if not ok or v < 0 or (v == 0 and not allow_zero):
                what = "non-negative" if allow_zero else "positive"
                problems.append(f"{name} must be a {what} number, got {v!r}")

        for name in ("filaments_per_second", "dt", "max_cfl", "max_noise_std", "sigma0"):
            check(name)
        for name in ("frame_dt", "duration", "kernel_sigmas"):
            check(name)
        for name in ("gamma", "noise_std", "warmup", "prefill_max_age"):
            check(name, allow_zero=True)
        for name in ("release_rate", "sigma_max"):
            if getattr(self, name) is not None:
                check(name)
        mf = self.max_filaments
        if mf is not None and (not isinstance(mf, int) or isinstance(mf, bool) or mf < 1):
            problems.append(f"max_filaments must be a positive integer or None, got {mf!r}")
        if not isinstance(self.prefill, bool):
            problems.append(f"prefill must be True or False, got {self.prefill!r}")
        if self.noise not in NOISE_MODELS:
            problems.append(f"noise must be one of {', '.join(NOISE_MODELS)}, got {self.noise!r}")
        if not problems and self.sigma_max is not None and self.sigma_max < self.sigma0:
            problems.append(f"sigma_max {self.sigma_max} m is less than sigma0 {self.sigma0} m")
        if not problems and self.max_cfl > 1.0:
            problems.append(f"max_cfl must be at most 1 cell, got {self.max_cfl}")
        if not problems and round(self.duration / self.frame_dt) < 1:
            problems.append(f"duration {self.duration} s is shorter than one frame ({self.frame_dt} s)")
        if not problems and self.filaments_per_second * self.step > 1e6:
            problems.append(f"{self.filaments_per_second:g} filaments per second is too many")
        if problems:
            raise InputDataError("bad filament settings: " + "; ".join(problems))

    @property
    def n_frames(self) -> int:
        """Number of frames, ``round(duration / frame_dt)``."""
        return max(1, round(self.duration / self.frame_dt))

    @property
    def step(self) -> float:
        """The time step used: ``frame_dt / ceil(frame_dt / dt)`` s."""
        return self.frame_dt / math.ceil(self.frame_dt / self.dt - 1e-9)

    def with_(self, **changes) -> FilamentSettings:
        """A copy with ``changes`` (validated)."""
        return replace(self, **changes)

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> FilamentSettings:
        """Settings from :meth:`to_dict` output; unknown keys are an error."""
        names = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - names)
        if unknown:
            raise InputDataError(f"unknown filament setting(s): {', '.join(unknown)}")
        return cls(**d)


@dataclass
class FilamentRun:
    """A filament simulation's frames and bookkeeping.

    Attributes:
        frames: ``float32 (T, H, W)`` instantaneous concentration in ppm,
            ``frame_dt`` apart, the first ``warmup`` s after the release began.
        times: ``(T,)`` time of each frame since the release began, s.
        n_alive: ``(T,)`` filaments in the domain at each frame.
        n_released: ``(T,)`` filaments released up to each frame (cumulative).
        n_exited: ``(T,)`` filaments removed through openings up to each frame.
        positions: ``(n, 2)`` ``(x, y)`` in m of the filaments alive at the end.
        ages: ``(n,)`` their ages in s.
        weights: ``(n,)`` their masses in units of ``filament_mass`` (1, more
            for prefilled filaments over ``max_filaments``).
        filament_mass: grams per filament.
        step: time step used, s.
        info: settings, wall-clock seconds and counts (JSON-able).
    """

    frames: np.ndarray
    times: np.ndarray
    n_alive: np.ndarray
    n_released: np.ndarray
    n_exited: np.ndarray
    positions: np.ndarray
    ages: np.ndarray
    weights: np.ndarray
    filament_mass: float
    step: float
    info: dict = field(default_factory=dict)

    def exit_rate(self) -> float:
        """Filaments removed per second through openings while the frames were taken."""
        if len(self.times) < 2:
            return float("nan")
        return float((self.n_exited[-1] - self.n_exited[0]) / (self.times[-1] - self.times[0]))


# -- compiled kernels ------------------------------------------------------------------------
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)


@_jit_inline
def _uniform(state: np.ndarray) -> float:
    """SplitMix64: a uniform double in ``[0, 1)``; advances ``state[0]``."""
    state[0] = state[0] + _GOLDEN
    z = state[0]
    z = (z ^ (z >> _S30)) * _MIX1
    z = (z ^ (z >> _S27)) * _MIX2
    z = z ^ (z >> _S31)
    return float(z >> _S11) * (1.0 / 9007199254740992.0)


@_jit_inline
def _normal2(state: np.ndarray) -> tuple[float, float]:
    """Two independent standard normals (Marsaglia's polar method)."""
    while True:
        u = 2.0 * _uniform(state) - 1.0
        v = 2.0 * _uniform(state) - 1.0
        q = u * u + v * v
        if 0.0 < q < 1.0:
            break
    m = math.sqrt(-2.0 * math.log(q) / q)
    return u * m, v * m


@_jit_inline
def _sample(x, y, inv_res, ufx, ufy, dp):
    """Wind ``(u_x, u_y)``, diffusivity ``D`` and ``grad D`` at ``(x, y)``.

    The wind is interpolated from the face velocities (``ufx (H, W + 1)``,
    ``ufy (H + 1, W)``) linearly across the cell holding the point, each
    component along its own axis (Pollock's scheme: divergence-free within a
    cell, no flow through wall faces).  ``D`` is bilinear between cell centres
    of the padded ``dp`` (padded index ``(i + 1, j + 1)`` is cell ``(i, j)``),
    ``grad D`` the gradient of that interpolant.
    """
    H = ufx.shape[0]
    W = ufy.shape[1]
    gx_ = x * inv_res
    gy_ = y * inv_res
    j = min(max(math.floor(gx_), 0), W - 1)
    i = min(max(math.floor(gy_), 0), H - 1)
    tx = min(max(gx_ - j, 0.0), 1.0)
    ty = min(max(gy_ - i, 0.0), 1.0)
    ux = (1.0 - tx) * ufx[i, j] + tx * ufx[i, j + 1]
    uy = (1.0 - ty) * ufy[i, j] + ty * ufy[i + 1, j]
    fx = gx_ + 0.5
    fy = gy_ + 0.5
    fx = min(max(fx, 0.0), W + 1 - 1e-9)
    fy = min(max(fy, 0.0), H + 1 - 1e-9)
    jd = math.floor(fx)
    id_ = math.floor(fy)
    sx = fx - jd
    sy = fy - id_
    d00, d01, d10, d11 = dp[id_, jd], dp[id_, jd + 1], dp[id_ + 1, jd], dp[id_ + 1, jd + 1]
    D = (1.0 - sx) * (1.0 - sy) * d00 + sx * (1.0 - sy) * d01 + (1.0 - sx) * sy * d10 + sx * sy * d11
    gx = ((1.0 - sy) * (d01 - d00) + sy * (d11 - d10)) * inv_res
    gy = ((1.0 - sx) * (d10 - d00) + sx * (d11 - d01)) * inv_res
    return ux, uy, D, gx, gy


@_jit_inline
def _drift(x, y, comp, inv_res, ufx, ufy, dp):
    """Drift velocity ``w + grad D'`` and diffusivity ``D' = max(D - comp, 0)`` at ``(x, y)``."""
    ux, uy, D, gx, gy = _sample(x, y, inv_res, ufx, ufy, dp)
    if comp > 0.0:
        D -= comp
        if D <= 0.0:
            return ux, uy, 0.0
    return ux + gx, uy + gy, D


@_jit_inline
def _first_crossing(p, d, cell, res):
    """Along one axis, a trace from ``p`` (m, in cell ``cell``) by ``d`` (m): the cell step
    (-1, 0 or 1), the fraction of ``d`` at its first cell edge and the fraction per cell."""
    if d > 0.0:
        return 1, ((cell + 1) * res - p) / d, res / d
    if d < 0.0:
        return -1, (cell * res - p) / d, -res / d
    return 0, math.inf, math.inf


@_jit_inline
def _leaving(i, j, H, W, open_w, open_e, open_s, open_n):
    """How a trace ends that reaches cell ``(i, j)`` outside the ``(H, W)`` domain:
    ``_EXITED`` across an open boundary cell beside a side, else ``_BLOCKED`` (corners too)."""
    if 0 <= i < H:
        return _EXITED if (open_w[i] if j < 0 else open_e[i]) else _BLOCKED
    if 0 <= j < W:
        return _EXITED if (open_s[j] if i < 0 else open_n[j]) else _BLOCKED
    return _BLOCKED


@_jit_inline
def _move(x, y, dx, dy, res, inv_res, occ, open_w, open_e, open_s, open_n):
    """Trace the segment ``(x, y) -> (x + dx, y + dy)`` through the grid.

    Returns ``_OK`` if every cell it crosses is free and inside the domain,
    ``_EXITED`` if it first leaves the domain through an open edge, else
    ``_BLOCKED`` (a solid cell or a closed edge).
    """
    H, W = occ.shape
    i = min(max(math.floor(y * inv_res), 0), H - 1)
    j = min(max(math.floor(x * inv_res), 0), W - 1)
    ie = math.floor((y + dy) * inv_res)
    je = math.floor((x + dx) * inv_res)
    if ie == i and je == j:
        return _OK
    sx, tmx, tdx = _first_crossing(x, dx, j, res)
    sy, tmy, tdy = _first_crossing(y, dy, i, res)
    n_cross = abs(ie - i) + abs(je - j)
    for _ in range(n_cross):
        if tmx < tmy:
            j += sx
            tmx += tdx
        else:
            i += sy
            tmy += tdy
        if i < 0 or i >= H or j < 0 or j >= W:
            return _leaving(i, j, H, W, open_w, open_e, open_s, open_n)
        if occ[i, j]:
            return _BLOCKED
    # rounding may leave the trace a cell short or long of the end: check the end cell itself
    if ie < 0 or ie >= H or je < 0 or je >= W:
        return _leaving(ie, je, H, W, open_w, open_e, open_s, open_n)
    if occ[ie, je]:
        return _BLOCKED
    return _OK


@_jit
def _transport(
    px, py, f, tau, comp, res, lims, occ, open_w, open_e, open_s, open_n, ufx, ufy, dp, state, counts
):
    """Move filament ``f`` for ``tau`` s in sub-steps; returns False if it left through an opening.

    The walk's diffusivity is ``max(D - comp, 0)`` (``D`` from ``dp``).
    ``lims = (drift, noise)``: the largest drift displacement and noise
    standard deviation of one sub-step, in m.
    """
    H, W = occ.shape
    inv_res = 1.0 / res
    lim = lims[0]
    lim_noise2 = lims[1] * lims[1]
    rem = tau
    x = px[f]
    y = py[f]
    while rem > 1e-12:
        counts[2] += 1
        vx, vy, D = _drift(x, y, comp, inv_res, ufx, ufy, dp)
        speed = math.sqrt(vx * vx + vy * vy)
        h = rem
        if speed * h > lim:
            h = lim / speed
        if 2.0 * D * h > lim_noise2:
            h = lim_noise2 / (2.0 * D)
        if h < 1e-9 * tau:
            h = 1e-9 * tau
        # midpoint rule for the drift (explicit Euler would spiral out of every eddy)
        xm = x + 0.5 * h * vx
        ym = y + 0.5 * h * vy
        im = math.floor(ym * inv_res)
        jm = math.floor(xm * inv_res)
        if 0 <= im < H and 0 <= jm < W and occ[im, jm] == 0:
            vx, vy, _ = _drift(xm, ym, comp, inv_res, ufx, ufy, dp)
        dx = vx * h
        dy = vy * h
        if D > 0.0:
            amp = math.sqrt(2.0 * D * h)
            n1, n2 = _normal2(state)
            dx += amp * n1
            dy += amp * n2
        rem -= h
        status = _move(x, y, dx, dy, res, inv_res, occ, open_w, open_e, open_s, open_n)
        if status == _BLOCKED:
            # slide: the larger component alone, then the smaller one, else stay
            if abs(dx) >= abs(dy):
                a1x, a1y, a2x, a2y = dx, 0.0, 0.0, dy
            else:
                a1x, a1y, a2x, a2y = 0.0, dy, dx, 0.0
            status = _move(x, y, a1x, a1y, res, inv_res, occ, open_w, open_e, open_s, open_n)
            if status == _OK or status == _EXITED:
                dx, dy = a1x, a1y
            else:
                status = _move(x, y, a2x, a2y, res, inv_res, occ, open_w, open_e, open_s, open_n)
                if status == _OK or status == _EXITED:
                    dx, dy = a2x, a2y
                else:
                    dx, dy = 0.0, 0.0
                    status = _OK
        if status == _EXITED:
            return False
        x += dx
        y += dy
    px[f] = x
    py[f] = y
    return True


@_jit
def _advance(
    px, py, birth, weight, n, t, n_steps, dt, rate, carry, sx, sy, sigma0, comp, t_grow,
    res, lims, occ, open_w, open_e, open_s, open_n, ufx, ufy, dp, state, counts,
):  # fmt: skip
    """Advance the ``n`` live filaments by ``n_steps`` steps of ``dt`` from time ``t``, releasing new ones.

    ``px, py, birth, weight`` hold the filaments (capacity ``len(px)``); a
    removed filament is replaced by the last live one.  ``rate`` filaments per second
    are released at ``(sx, sy)`` plus ``N(0, sigma0^2)`` per axis; ``carry`` is
    the fraction of a filament owed from earlier steps.  Filaments younger
    than ``t_grow`` (still widening) walk with ``D - comp``, older ones with
    ``D``.  ``counts`` accumulates ``[released, removed through openings,
    sub-steps]``.  Returns the new ``(n, carry)``.
    """
    inv_res = 1.0 / res
    cap = px.shape[0]
    for step in range(n_steps):
        t0 = t + step * dt
        f = 0
        while f < n:
            c_f = comp if t0 - birth[f] < t_grow else 0.0
            if _transport(px, py, f, dt, c_f, res, lims, occ, open_w, open_e, open_s, open_n,
                          ufx, ufy, dp, state, counts):  # fmt: skip
                f += 1
            else:
                n -= 1
                px[f] = px[n]
                py[f] = py[n]
                birth[f] = birth[n]
                weight[f] = weight[n]
                counts[1] += 1
        owed = carry + rate * dt
        n_new = math.floor(owed + 1e-9)
        carry = max(owed - n_new, 0.0)
        for k in range(n_new):
            if n >= cap:
                break
            frac = (k + _uniform(state)) / n_new
            z1, z2 = _normal2(state)
            x = sx + sigma0 * z1
            y = sy + sigma0 * z2
            if _move(sx, sy, x - sx, y - sy, res, inv_res, occ, open_w, open_e, open_s, open_n) != _OK:
                x = sx
                y = sy
            px[n] = x
            py[n] = y
            birth[n] = t0 + frac * dt
            weight[n] = 1.0
            counts[0] += 1
            if _transport(px, py, n, (1.0 - frac) * dt, comp, res, lims, occ, open_w, open_e, open_s,
                          open_n, ufx, ufy, dp, state, counts):  # fmt: skip
                n += 1
            else:
                counts[1] += 1
    return n, carry


@_jit
def _window(x, y, s, ksig, inv_res, H, W):
    """Cells ``(ic, jc, i0, i1, j0, j1)``: the filament's cell and its ``ksig``-sigma window (clipped)."""
    jc = min(max(math.floor(x * inv_res), 0), W - 1)
    ic = min(max(math.floor(y * inv_res), 0), H - 1)
    r = ksig * s * inv_res
    j0 = min(max(math.floor(x * inv_res - r), 0), jc)
    j1 = max(min(math.floor(x * inv_res + r), W - 1), jc)
    i0 = min(max(math.floor(y * inv_res - r), 0), ic)
    i1 = max(min(math.floor(y * inv_res + r), H - 1), ic)
    return ic, jc, i0, i1, j0, j1


#: erf tabulated on [-_ERF_MAX, _ERF_MAX] every 1 / _ERF_PER_UNIT (linear interpolation error < 5e-7)
_ERF_MAX, _ERF_PER_UNIT = 6.0, 512


def _erf_table() -> np.ndarray:
    from scipy.special import erf

    return erf(np.arange(-_ERF_MAX * _ERF_PER_UNIT, _ERF_MAX * _ERF_PER_UNIT + 2) / _ERF_PER_UNIT)


@_jit_inline
def _erf(tab, z):
    """``erf(z)`` by linear interpolation in ``tab`` (:func:`_erf_table`)."""
    if z <= -_ERF_MAX:
        return -1.0
    if z >= _ERF_MAX:
        return 1.0
    u = (z + _ERF_MAX) * _ERF_PER_UNIT
    k = int(u)
    f = u - k
    return tab[k] + f * (tab[k + 1] - tab[k])


@_jit
def _axis_weights(w, k0, k1, kc, pos, c, res, line, erf_tab):
    """One axis of a filament's kernel: cell integrals of ``N(pos, sigma^2)`` over cells ``k0 .. k1``.

    ``c = 1 / (sqrt(2) sigma)``; ``line`` is the occupancy along the axis
    through the filament's cell ``kc``.  Only the free run of cells through
    ``kc`` gets weight; where a wall or the domain edge bounds the run within
    the window the Gaussian is folded back (an image filament mirrored at that
    face), exact zero-flux walls for straight walls.  Returns the sum of the
    weights.  ``erf`` comes from the table ``erf_tab`` (:func:`_erf`).
    """
    n_line = line.shape[0]
    lo = kc
    while lo > k0 and line[lo - 1] == 0:
        lo -= 1
    hi = kc
    while hi < k1 and line[hi + 1] == 0:
        hi += 1
    for k in range(k0, k1 + 1):
        w[k] = 0.0
    total = 0.0
    for m in range(3):
        if m == 0:
            p = pos
        elif m == 1:
            if not (lo == 0 or line[lo - 1] != 0):
                continue
            p = 2.0 * lo * res - pos
        else:
            if not (hi == n_line - 1 or line[hi + 1] != 0):
                continue
            p = 2.0 * (hi + 1) * res - pos
        e_prev = _erf(erf_tab, (lo * res - p) * c)
        for k in range(lo, hi + 1):
            e_next = _erf(erf_tab, ((k + 1) * res - p) * c)
            v = 0.5 * (e_next - e_prev)
            w[k] += v
            total += v
            e_prev = e_next
    return total


@_jit
def _splat(
    px, py, birth, weight, n, t, sigma0, gamma, sigma_max, ksig, res, occ, sat, los, erf_tab, amp, out
):  # fmt: skip
    """Add the ``n`` filaments' concentration at time ``t`` to ``out`` (``(H, W)``).

    Each filament adds its Gaussian (width ``min(sqrt(sigma0^2 + gamma age), sigma_max)``)
    integrated over each cell of its ``ksig``-sigma window, as the product of
    two axis weights folded at the walls in the filament's row and column
    (:func:`_axis_weights`), over the free cells in line of sight of its cell,
    renormalized to sum to ``amp * weight``.  ``sat`` is
    the summed-area table ``(H + 1, W + 1)`` of ``occ``; ``los`` the offsets
    ``(a, b, parent_a, parent_b)`` in ring order (:func:`_los_table`),
    ``erf_tab`` :func:`_erf_table`.
    Filaments are grouped by cell so that one visibility map serves a group.
    """
    H, W = occ.shape
    inv_res = 1.0 / res
    wx = np.empty(W)
    wy = np.empty(H)
    vis = np.zeros((H, W), dtype=np.uint8)
    cell = np.empty(n, dtype=np.int64)
    sig = np.empty(n)
    for f in range(n):
        jc = min(max(math.floor(px[f] * inv_res), 0), W - 1)
        ic = min(max(math.floor(py[f] * inv_res), 0), H - 1)
        cell[f] = ic * W + jc
        sig[f] = min(math.sqrt(sigma0 * sigma0 + gamma * max(t - birth[f], 0.0)), sigma_max)
    order = np.argsort(cell)
    inv_sqrt2 = 1.0 / math.sqrt(2.0)
    g = 0
    while g < n:
        e = g + 1
        while e < n and cell[order[e]] == cell[order[g]]:
            e += 1
        # the union of the windows that hold a solid cell: one visibility map for the group
        ui0, ui1, uj0, uj1 = H, -1, W, -1
        ic, jc = 0, 0
        for k in range(g, e):
            f = order[k]
            ic, jc, i0, i1, j0, j1 = _window(px[f], py[f], sig[f], ksig, inv_res, H, W)
            if sat[i1 + 1, j1 + 1] - sat[i0, j1 + 1] - sat[i1 + 1, j0] + sat[i0, j0] > 0:
                ui0, ui1, uj0, uj1 = min(ui0, i0), max(ui1, i1), min(uj0, j0), max(uj1, j1)
        if ui1 >= 0:
            R = max(ic - ui0, ui1 - ic, jc - uj0, uj1 - jc)
            vis[ic, jc] = 1
            for m in range(1, min((2 * R + 1) * (2 * R + 1), los.shape[0])):
                i = ic + los[m, 0]
                j = jc + los[m, 1]
                if i < ui0 or i > ui1 or j < uj0 or j > uj1 or occ[i, j]:
                    continue
                pi = ic + los[m, 2]
                pj = jc + los[m, 3]
                if vis[pi, pj] and (pi == i or pj == j or occ[pi, j] == 0 or occ[i, pj] == 0):
                    vis[i, j] = 1
        for k in range(g, e):
            f = order[k]
            x = px[f]
            y = py[f]
            s = sig[f]
            ic, jc, i0, i1, j0, j1 = _window(x, y, s, ksig, inv_res, H, W)
            c = inv_sqrt2 / s
            sx = _axis_weights(wx, j0, j1, jc, x, c, res, occ[ic, :], erf_tab)
            sy = _axis_weights(wy, i0, i1, ic, y, c, res, occ[:, jc], erf_tab)
            if sat[i1 + 1, j1 + 1] - sat[i0, j1 + 1] - sat[i1 + 1, j0] + sat[i0, j0] == 0:
                if sx > 0.0 and sy > 0.0:
                    scale = amp * weight[f] / (sx * sy)
                    for i in range(i0, i1 + 1):
                        a = scale * wy[i]
                        for j in range(j0, j1 + 1):
                            out[i, j] += a * wx[j]
                continue
            total = 0.0
            for i in range(i0, i1 + 1):
                row = 0.0
                for j in range(j0, j1 + 1):
                    if vis[i, j]:
                        row += wx[j]
                total += wy[i] * row
            if total > 0.0:
                scale = amp * weight[f] / total
                for i in range(i0, i1 + 1):
                    a = scale * wy[i]
                    for j in range(j0, j1 + 1):
                        if vis[i, j]:
                            out[i, j] += a * wx[j]
        if ui1 >= 0:
            vis[ui0 : ui1 + 1, uj0 : uj1 + 1] = 0
        g = e


def _los_table(R: int) -> np.ndarray:
    """Offsets ``(a, b, pa, pb)`` (rows, columns) within Chebyshev radius ``R`` in ring order.

    ``(pa, pb)`` is the parent of ``(a, b)``: the cell one ring closer to
    ``(0, 0)`` on the digital straight line to it (the major axis steps by one,
    the minor one is rounded), so a ring-ordered sweep sees every parent first.
    """
    grid_a, grid_b = np.meshgrid(np.arange(-R, R + 1), np.arange(-R, R + 1), indexing="ij")
    a, b = grid_a.ravel(), grid_b.ravel()
    d = np.maximum(np.abs(a), np.abs(b))
    order = np.lexsort((b, a, d))
    a, b, d = a[order], b[order], d[order]
    major_a = np.abs(a) >= np.abs(b)
    dd = np.maximum(d, 1)
    pa = np.where(major_a, a - np.sign(a), np.sign(a) * np.floor(np.abs(a) * (dd - 1) / dd + 0.5))
    pb = np.where(major_a, np.sign(b) * np.floor(np.abs(b) * (dd - 1) / dd + 0.5), b - np.sign(b))
    pa[0] = pb[0] = 0
    return np.ascontiguousarray(np.stack([a, b, pa, pb], axis=1).astype(np.int64))


# -- fields the kernels read -----------------------------------------------------------------
def walk_diffusivity(
    occupancy: np.ndarray,
    settings: FilamentSettings,
    nut: np.ndarray | None = None,
    physics: Physics = DEFAULT_PHYSICS,
) -> np.ndarray:
    """Diffusivity ``(H, W)`` in m^2/s of the filaments' random walk (see the module doc).

    ``"turbulent"``: ``D_m + nu_t / Sc_t`` in free cells (the kernels take
    ``gamma / 2`` off while a filament still widens); ``"constant"``:
    ``noise_std^2 * step / 2`` everywhere.  Solid cells hold the mean of their
    free neighbours (zero normal gradient at walls).
    """
    occ = np.asarray(occupancy) != 0
    if settings.noise == "constant":
        return np.full(occ.shape, 0.5 * settings.noise_std**2 * settings.step)
    if nut is None:
        raise InputDataError('noise="turbulent" needs the turbulent viscosity nut (H, W)')
    nut = np.asarray(nut, dtype=np.float64)
    if nut.shape != occ.shape:
        raise InputDataError(f"nut has shape {nut.shape}, expected {occ.shape}")
    if not np.isfinite(nut[~occ]).all() or (nut[~occ] < 0).any():
        raise InputDataError("nut must be finite and non-negative in free cells")
    return _fill_solid(physics.D_m + np.maximum(nut, 0.0) / physics.Sc_t, occ)


def _fill_solid(values: np.ndarray, solid: np.ndarray) -> np.ndarray:
    """Solid cells take the mean of their known 8-neighbours, layer by layer from the free cells."""
    v = np.where(solid, 0.0, values).astype(np.float64)
    known = ~solid
    H, W = v.shape
    for _ in range(max(H, W)):
        if known.all():
            break
        vp = np.pad(v * known, 1)
        kp = np.pad(known.astype(np.float64), 1)
        s = np.zeros_like(v)
        cnt = np.zeros_like(v)
        for di in (-1, 0, 1):
            for dj in (-1, 0, 1):
                if di or dj:
                    s += vp[1 + di : 1 + di + H, 1 + dj : 1 + dj + W]
                    cnt += kp[1 + di : 1 + di + H, 1 + dj : 1 + dj + W]
        new = (~known) & (cnt > 0)
        if not new.any():
            break
        v[new] = s[new] / cnt[new]
        known = known | new
    return v


def _edge_masks(open_mask: np.ndarray) -> tuple[np.ndarray, ...]:
    """Open rows of the west/east edges and columns of the south/north edges."""
    m = np.asarray(open_mask, dtype=bool)
    return (
        np.ascontiguousarray(m[:, 0]),
        np.ascontiguousarray(m[:, -1]),
        np.ascontiguousarray(m[0, :]),
        np.ascontiguousarray(m[-1, :]),
    )


def face_velocities(
    occupancy: np.ndarray, wind: np.ndarray, open_mask: np.ndarray | None = None, project: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """Normal velocities on the cell faces, ``(H, W + 1)`` (x) and ``(H + 1, W)`` (y), in m/s.

    A face between two free cells gets the mean of their wind; a face on an
    opening of the domain edge the boundary cell's; wall faces and closed
    edges 0.  With ``project`` the faces are then corrected by the gradient of
    a potential (``phi = 0`` beyond openings) so that every free cell's net
    outflow is 0 to round-off: filaments then neither gather nor thin out
    where the interpolated wind would compress.
    """
    occ = np.asarray(occupancy) != 0
    free = ~occ
    H, W = occ.shape
    if open_mask is None:
        open_mask = np.zeros((H, W), dtype=bool)
    u = np.where(free, wind[0], 0.0).astype(np.float64)
    v = np.where(free, wind[1], 0.0).astype(np.float64)
    open_w, open_e, open_s, open_n = _edge_masks(open_mask)
    ufx = np.zeros((H, W + 1))
    ufy = np.zeros((H + 1, W))
    ufx[:, 1:-1] = np.where(free[:, 1:] & free[:, :-1], 0.5 * (u[:, 1:] + u[:, :-1]), 0.0)
    ufy[1:-1, :] = np.where(free[1:, :] & free[:-1, :], 0.5 * (v[1:, :] + v[:-1, :]), 0.0)
    ufx[:, 0] = np.where(open_w & free[:, 0], u[:, 0], 0.0)
    ufx[:, -1] = np.where(open_e & free[:, -1], u[:, -1], 0.0)
    ufy[0, :] = np.where(open_s & free[0, :], v[0, :], 0.0)
    ufy[-1, :] = np.where(open_n & free[-1, :], v[-1, :], 0.0)
    if project:
        _project(ufx, ufy, free, (open_w, open_e, open_s, open_n))
    return np.ascontiguousarray(ufx), np.ascontiguousarray(ufy)


def _project(ufx: np.ndarray, ufy: np.ndarray, free: np.ndarray, edges: tuple[np.ndarray, ...]) -> None:
    """Make the face velocities divergence-free in every free cell (in place)."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla
    from scipy import ndimage

    H, W = free.shape
    open_w, open_e, open_s, open_n = edges
    idx = np.full((H, W), -1, dtype=np.int64)
    n = int(free.sum())
    idx[free] = np.arange(n)
    div = (ufx[:, 1:] - ufx[:, :-1]) + (ufy[1:, :] - ufy[:-1, :])  # net outflow per cell / res
    rows, cols, vals = [], [], []
    diag = np.zeros(n)
    # internal faces: outflow' = outflow - (phi_nb - phi_c)
    for a, b in ((idx[:, :-1], idx[:, 1:]), (idx[:-1, :], idx[1:, :])):
        m = (a >= 0) & (b >= 0)
        a, b = a[m], b[m]
        rows += [a, b]
        cols += [b, a]
        vals += [-np.ones(a.size), -np.ones(a.size)]
        np.add.at(diag, a, 1.0)
        np.add.at(diag, b, 1.0)
    # open faces: phi = 0 beyond them
    dirichlet = np.zeros((H, W))
    dirichlet[:, 0] += open_w
    dirichlet[:, -1] += open_e
    dirichlet[0, :] += open_s
    dirichlet[-1, :] += open_n
    diag += dirichlet[free]
    # a closed room (no opening in its connected part) fixes its potential at one cell
    labels, n_parts = ndimage.label(free)
    open_parts = set(np.unique(labels[free & (dirichlet > 0)]).tolist())
    for part in range(1, n_parts + 1):
        if part not in open_parts:
            first = np.flatnonzero(labels[free] == part)[0]
            diag[first] += 1.0
    A = sp.csr_matrix(
        (
            np.concatenate([*vals, diag]),
            (np.concatenate([*rows, np.arange(n)]), np.concatenate([*cols, np.arange(n)])),
        ),
        shape=(n, n),
    )
    phi_free = spla.spsolve(A.tocsc(), -div[free])
    phi = np.zeros((H, W))
    phi[free] = phi_free
    fx = free[:, 1:] & free[:, :-1]
    ufx[:, 1:-1] -= np.where(fx, phi[:, 1:] - phi[:, :-1], 0.0)
    fy = free[1:, :] & free[:-1, :]
    ufy[1:-1, :] -= np.where(fy, phi[1:, :] - phi[:-1, :], 0.0)
    ufx[:, 0] -= np.where(open_w & free[:, 0], phi[:, 0], 0.0)
    ufx[:, -1] += np.where(open_e & free[:, -1], phi[:, -1], 0.0)
    ufy[0, :] -= np.where(open_s & free[0, :], phi[0, :], 0.0)
    ufy[-1, :] += np.where(open_n & free[-1, :], phi[-1, :], 0.0)


def _check_inputs(
    occupancy: np.ndarray, wind: np.ndarray, source_xy, outlet_mask: np.ndarray | None, resolution: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Validated ``(occupancy uint8, wind float64 0 in solid, source (2,), open mask)``."""
    occ = np.asarray(occupancy)
    if occ.ndim != 2 or min(occ.shape) < 2:
        raise InputDataError(f"occupancy must be a 2-D map, got shape {occ.shape}")
    if not np.isin(occ, (0, 1)).all():
        raise InputDataError("occupancy must contain only 0 (free) and 1 (solid)")
    occ = occ.astype(np.uint8)
    H, W = occ.shape
    if not (isinstance(resolution, int | float) and math.isfinite(resolution) and resolution > 0):
        raise InputDataError(f"resolution must be a positive number of m, got {resolution!r}")
    wind = np.asarray(wind, dtype=np.float64)
    if wind.shape != (2, H, W):
        raise InputDataError(f"wind has shape {wind.shape}, expected (2, {H}, {W})")
    if not np.isfinite(wind).all():
        raise InputDataError("wind has non-finite values")
    wind = np.where(occ == 1, 0.0, wind)
    src = np.asarray(source_xy, dtype=np.float64).reshape(-1)
    if src.shape != (2,) or not np.isfinite(src).all():
        raise InputDataError(f"source must be a finite (x, y) in m, got {source_xy!r}")
    i, j = cell_index(src[1], resolution), cell_index(src[0], resolution)
    if not (0 <= i < H and 0 <= j < W):
        raise InputDataError(f"source ({src[0]:.3f}, {src[1]:.3f}) m lies outside the map")
    if occ[i, j]:
        raise InputDataError(f"source ({src[0]:.3f}, {src[1]:.3f}) m lies in a wall (a solid cell)")
    if outlet_mask is None:
        mask = np.zeros((H, W), dtype=bool)
    else:
        mask = np.asarray(outlet_mask, dtype=bool)
        if mask.shape != (H, W):
            raise InputDataError(f"outlet_mask has shape {mask.shape}, expected ({H}, {W})")
        mask = mask & (occ == 0)
    return occ, wind, src, mask


# -- the simulation ----------------------------------------------------------------------------
def run_filaments(
    occupancy: np.ndarray,
    wind: np.ndarray,
    source_xy,
    settings: FilamentSettings,
    rng: RngLike = None,
    outlet_mask: np.ndarray | None = None,
    *,
    resolution: float = DEFAULT_RESOLUTION,
    nut: np.ndarray | None = None,
    steady: np.ndarray | None = None,
    physics: Physics = DEFAULT_PHYSICS,
) -> FilamentRun:
    """Simulate filaments from ``source_xy`` in a steady ``wind`` and record concentration frames.

    Args:
        occupancy: ``(H, W)`` 1 solid, 0 free.
        wind: ``(2, H, W)`` cell-centred ``[u_x, u_y]`` in m/s (taken as 0 in solid cells).
        source_xy (tuple[float, float]): source ``(x, y)`` in m, in a free cell.
        settings: the simulation's parameters; ``settings.release_rate`` must be set.
        rng: seed or numpy Generator; the result is a deterministic function of it.
        outlet_mask: ``(H, W)`` bool, free boundary cells whose outer edge is
            open (outlets and inlets: filaments crossing it are removed);
            ``None``: a closed domain.
        resolution: cell size in m.
        nut: ``(H, W)`` turbulent viscosity in m^2/s (``noise="turbulent"``).
        steady: ``(H, W)`` steady concentration in ppm to start from
            (``settings.prefill``); ``None`` starts from an empty domain.
        physics: ``D_m``, ``Sc_t``, the slab depth and the ppm conversion.

    Returns:
        A :class:`FilamentRun`; ``frames`` is ``(round(duration / frame_dt), H, W)`` ppm.

    Raises:
        InputDataError: bad shapes or values, a source outside the map or in a
            wall, no release rate, ``noise="turbulent"`` without ``nut``.
    """
    t_start = time.perf_counter()
    if not isinstance(settings, FilamentSettings):
        raise InputDataError(f"settings must be FilamentSettings, got {type(settings).__name__}")
    if settings.release_rate is None:
        raise InputDataError("settings.release_rate (g/s) is not set")
    occ, wind, src, mask = _check_inputs(occupancy, wind, source_xy, outlet_mask, resolution)
    res = float(resolution)
    H, W = occ.shape
    gen = as_generator(rng)
    state = np.array([gen.integers(0, 2**63 - 1, dtype=np.int64)], dtype=np.int64).view(np.uint64)
    D = walk_diffusivity(occ, settings, nut, physics)
    dp = np.ascontiguousarray(np.pad(D, 1, mode="edge"))
    edges = _edge_masks(mask)
    ufx, ufy = face_velocities(occ, wind, mask, project=settings.project_wind)
    sat = np.zeros((H + 1, W + 1), dtype=np.int64)
    sat[1:, 1:] = occ.astype(np.int64).cumsum(0).cumsum(1)

    dt = settings.step
    steps_per_frame = round(settings.frame_dt / dt)
    warm_steps = round(settings.warmup / dt)
    T = settings.n_frames
    rate = float(settings.filaments_per_second)
    mass = settings.release_rate / rate
    ppm_per_filament = mass / (physics.slab_depth * res * res) * physics.ppm_per_gm3
    pre_x, pre_y, pre_age, pre_weight = _prefill(occ, steady, settings, ppm_per_filament, res, gen)
    t_end = (warm_steps + (T - 1) * steps_per_frame) * dt
    cap = math.ceil(rate * (t_end + dt)) + pre_x.size + 2
    px = np.zeros(cap)
    py = np.zeros(cap)
    birth = np.zeros(cap)
    weight = np.ones(cap)  # mass in units of Q_f: 1, or more for capped prefilled filaments
    n = pre_x.size
    px[:n], py[:n], birth[:n], weight[:n] = pre_x, pre_y, -pre_age, pre_weight
    counts = np.zeros(3, dtype=np.int64)
    sigma_max = math.inf if settings.sigma_max is None else float(settings.sigma_max)
    s_top = min(sigma_max, math.sqrt(settings.sigma0**2 + settings.gamma * (t_end + pre_age.max(initial=0))))
    los = _los_table(min(math.ceil(settings.kernel_sigmas * s_top / res) + 1, max(H, W)))
    lims = np.array([settings.max_cfl * res, settings.max_noise_std * res])
    erf_tab = _erf_table()

    frames = np.zeros((T, H, W), dtype=np.float32)
    times = np.zeros(T)
    n_alive = np.zeros(T, dtype=np.int64)
    n_released = np.zeros(T, dtype=np.int64)
    n_exited = np.zeros(T, dtype=np.int64)
    buf = np.zeros((H, W))
    carry, step_no, t_splat = 0.0, 0, 0.0
    walk = (res, lims, occ, *edges, ufx, ufy, dp, state, counts)
    kernel = (float(settings.sigma0), float(settings.gamma), sigma_max, float(settings.kernel_sigmas))
    # while a filament widens, its growth diffuses gamma / 2: the turbulent walk supplies the rest
    comp = 0.5 * settings.gamma if settings.noise == "turbulent" else 0.0
    t_grow = (sigma_max**2 - settings.sigma0**2) / settings.gamma if settings.gamma > 0 else math.inf
    for k in range(T):
        todo = warm_steps if k == 0 else steps_per_frame
        t0 = step_no * dt
        n, carry = _advance(
            px, py, birth, weight, n, t0, todo, dt, rate, carry, src[0], src[1], kernel[0], comp, t_grow,
            *walk,
        )  # fmt: skip
        step_no += todo
        t = step_no * dt
        t1 = time.perf_counter()
        buf[:] = 0.0
        _splat(px, py, birth, weight, n, t, *kernel, res, occ, sat, los, erf_tab, ppm_per_filament, buf)
        t_splat += time.perf_counter() - t1
        frames[k] = np.where(occ == 1, 0.0, buf)
        times[k] = t
        n_alive[k] = n
        n_released[k] = counts[0]
        n_exited[k] = counts[1]
    wall = time.perf_counter() - t_start
    free = occ == 0
    info = {
        "settings": settings.to_dict(),
        "step_s": dt,
        "prefill_filament_weight": pre_weight,
        "filament_mass_g": mass,
        "n_prefilled": int(pre_x.size),
        "prefill_age_s": float(pre_age.max(initial=0.0)),
        "n_released": int(counts[0]),
        "n_exited": int(counts[1]),
        "n_alive_end": int(n),
        "mean_alive": float(n_alive.mean()),
        "substeps_per_filament_step": float(counts[2] / max(1, n_alive.mean() * step_no)),
        "walk_diffusivity_m2s": {
            "min": float(D[free].min()),
            "median": float(np.median(D[free])),
            "max": float(D[free].max()),
        },
        "wall_clock_s": {"total": wall, "splat": t_splat, "particles": wall - t_splat},
    }
    return FilamentRun(
        frames=frames,
        times=times,
        n_alive=n_alive,
        n_released=n_released,
        n_exited=n_exited,
        positions=np.stack([px[:n], py[:n]], axis=1),
        ages=step_no * dt - birth[:n],
        weights=weight[:n].copy(),
        filament_mass=mass,
        step=dt,
        info=info,
    )


def _prefill(
    occ: np.ndarray,
    steady: np.ndarray | None,
    settings: FilamentSettings,
    ppm_per_filament: float,
    res: float,
    gen: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Positions, ages and weight (mass in ``Q_f``) of the filaments that stand for the steady field.

    Empty without one.  ``M / Q_f`` filaments of weight 1, or ``max_filaments``
    of the weight that carries the same mass.
    """
    empty = np.zeros(0)
    if steady is None or not settings.prefill:
        return empty, empty, empty, 1.0
    c = np.asarray(steady, dtype=np.float64)
    if c.shape != occ.shape:
        raise InputDataError(f"steady concentration has shape {c.shape}, expected {occ.shape}")
    c = np.where(occ == 0, c, 0.0)
    if not np.isfinite(c).all() or (c < 0).any():
        raise InputDataError("steady concentration must be finite and non-negative")
    total = c.sum()  # in filaments: ppm per filament spread over one cell
    n_mass = total / ppm_per_filament
    n = round(n_mass)
    if n == 0:
        return empty, empty, empty, 1.0
    weight = 1.0
    if settings.max_filaments is not None and n > settings.max_filaments:
        n = settings.max_filaments
        weight = n_mass / n
    # the mean residence time M / q (capped)
    age = min(n_mass / settings.filaments_per_second, settings.prefill_max_age)
    cells = gen.choice(c.size, size=n, p=(c / total).ravel())
    i, j = np.divmod(cells, occ.shape[1])
    x = (j + gen.random(n)) * res
    y = (i + gen.random(n)) * res
    return x, y, np.full(n, age), weight


def simulate_filaments(*args: Any, **kwargs: Any) -> np.ndarray:
    """The frames ``float32 (T, H, W)`` in ppm of :func:`run_filaments` (same arguments)."""
    return run_filaments(*args, **kwargs).frames


def make_filament_case(
    case: Case,
    settings: FilamentSettings | None = None,
    seed: RngLike = 0,
    *,
    nut: np.ndarray | None = None,
    physics: Physics = DEFAULT_PHYSICS,
    flow_settings: FlowSettings | None = None,
) -> Case:
    """The case with ``frames`` from a filament simulation on its wind, from its source.

    The release rate defaults to the case's; inlets and outlets (from the
    case's ``meta``) remove filaments.  With ``noise="turbulent"`` and no
    ``nut`` given, the case's flow is solved again with the built-in solver
    (a few seconds for 100 x 100 cells) for its turbulent viscosity; the
    advecting wind is always the case's own.  With ``settings.prefill`` the
    simulation starts from the case's steady concentration.  The steady
    ``concentration`` is kept; ``meta["frame_dt"]`` and ``meta["filament"]``
    (settings, seed, counts, timings, where ``nu_t`` came from) are added.
    ``flow_settings``: the iteration controls of that flow solve.

    Raises:
        InputDataError: bad settings; a case whose meta lacks its openings, its
            release rate (unless ``settings.release_rate`` is set) or, to solve
            the flow for ``nu_t``, its inlet velocity.
        ConvergenceError: a case whose meta says its flow did not converge
            (``flow_converged`` false), or a flow solved for ``nu_t`` that did not.
    """
    settings = FilamentSettings() if settings is None else settings
    if not isinstance(case, Case):
        raise InputDataError(f"make_filament_case needs a Case, got {type(case).__name__}")
    if case.meta.get("flow_converged") is False:
        raise ConvergenceError(
            f"case {case.name!r} was solved on a flow that did not converge (meta flow_converged "
            "false): its wind is not a steady flow to carry filaments; solve the case again"
        )
    if settings.release_rate is None:
        if "release_rate_gps" not in case.meta:
            raise InputDataError(
                f"case {case.name!r} has no meta release_rate_gps: set settings.release_rate"
            )
        settings = settings.with_(release_rate=case.release_rate)
    layout = case.layout
    mask = layout.opening_mask("inlet") | layout.opening_mask("outlet")
    nut_source = "none"
    t_flow = 0.0
    if settings.noise == "turbulent":
        if nut is None:
            from dgse.physics.builtin import flow_and_transport, require_converged

            if "inlet_velocity" not in case.meta:
                raise InputDataError(
                    f"case {case.name!r} has no meta inlet_velocity to solve its flow for nu_t: "
                    'use {noise}="constant" (or, from Python, pass nut=)',
                    names={"noise": "noise"},
                )
            t0 = time.perf_counter()
            flow, _ = flow_and_transport(layout, case.inlet_velocity, physics, flow_settings)
            t_flow = time.perf_counter() - t0
            # an unconverged flow's nu_t is far from the converged one (often orders of magnitude
            # too large), and its random walk spreads the plume to nothing
            require_converged(
                flow.info,
                f"the flow of case {case.name!r} solved for nu_t",
                'use {noise}="constant" (or, from Python, pass nut=)',
                names={"noise": "noise"},
            )
            nut = flow.nut
            nut_source = "builtin flow (converged)"
        else:
            nut_source = "given"
    seed_value = seed if isinstance(seed, int) and not isinstance(seed, bool) else None
    run = run_filaments(
        case.occupancy,
        case.wind,
        case.source,
        settings,
        seed,
        mask,
        resolution=case.resolution,
        nut=nut,
        steady=case.concentration,
        physics=physics,
    )
    info = {
        **run.info,
        "model": "filament (GADEN, Farrell 2002), 2-D",
        "seed": seed_value,
        "nut_source": nut_source,
        "warmup_s": settings.warmup,
        "exit_rate_per_s": run.exit_rate(),
        "release_per_s": settings.filaments_per_second,
    }
    info["wall_clock_s"] = {**info["wall_clock_s"], "nut_flow": t_flow}
    meta = {**case.meta, "frame_dt": float(settings.frame_dt), "filament": json_safe(info)}
    return replace(case, frames=run.frames, meta=meta)
