"""Figures and GIF animations of a search episode (like the paper's fig:dgse_search_process).

Three map panels per search step ``k`` (one per measurement location):

1. the predicted wind field: speed (colour) and direction (unit arrows);
2. the predicted concentration, mean of ``log(1 + c)`` (colour bar in ppm, as the
   case figure's, :func:`dgse.viz.case.label_ppm_colorbar`);
3. the source posterior ``pi_s``.

Every panel shows the walls (grey), the inlets (green) and outlets (red) as
the case figure draws them (:func:`dgse.viz.case.draw_openings`), the robot's
start (a yellow triangle), its trajectory up to the step (black line), the
measurement locations so far (orange circles, area proportional to the gas
reading), the true source (star) and the current estimate (the
probability-weighted mean, a white cross).  The maps are the
ones recorded by :func:`~dgse.search.episode.run_episode` with
``record=True`` (possibly block-averaged); a method without a wind or
concentration estimate leaves that panel empty with a note.

:func:`plot_search_step` draws one step as a :class:`~matplotlib.figure.Figure`
(Agg canvas); :func:`animate_episode` writes a GIF with matplotlib's
:class:`~matplotlib.animation.PillowWriter` (no ffmpeg needed).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib import colormaps
from matplotlib.animation import PillowWriter
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import to_rgba
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from dgse.errors import InputDataError
from dgse.files import atomic_path
from dgse.search.episode import EpisodeResult
from dgse.viz.case import (
    SOLID_IN_FIELD,
    SOURCE_STYLE,
    draw_openings,
    label_ppm_colorbar,
    opening_handles,
    openings_of,
)
from dgse.world.case import Case

__all__ = ["START_STYLE", "animate_episode", "frame_steps", "plot_search_step"]

MEASUREMENT_COLOR = "#ff8c00"
TRAJECTORY_COLOR = "black"
#: The true source marker (the case figures' style, smaller).
_SOURCE: dict[str, Any] = {**SOURCE_STYLE, "ms": 12}
#: The robot's start.
START_STYLE: dict[str, Any] = {"marker": "^", "ms": 9, "mfc": "#ffd92f", "mec": "black", "mew": 0.9}
#: Arrows along the longer side of the wind panel.
_ARROWS_ALONG = 16
_MIN_MARKER, _MAX_MARKER = 12.0, 220.0


def _check(result: EpisodeResult, case: Case) -> None:
    if not result.steps:
        raise InputDataError(f"episode on {result.case_name!r} has no steps to draw")
    if not result.recorded:
        raise InputDataError("episode has no recorded belief maps: run it with record=True")
    if case.occupancy.shape[0] > 0 and result.steps[0].source_probs is not None:
        f = result.record_factor
        H, W = case.occupancy.shape
        h, w = result.steps[0].source_probs.shape
        if (h, w) != (-(-H // f), -(-W // f)):
            raise InputDataError(f"recorded maps {h} x {w} do not match case {case.name!r} ({H} x {W} cells)")


class _SearchFigure:
    """The three-panel figure; :meth:`draw` updates it to one step."""

    def __init__(self, result: EpisodeResult, case: Case, figsize_scale: float = 1.0) -> None:
        _check(result, case)
        self.result, self.case = result, case
        res = case.resolution
        H, W = case.occupancy.shape
        self.W_m, self.H_m = W * res, H * res
        f = result.record_factor
        h, w = result.steps[0].source_probs.shape  # type: ignore[union-attr]
        ext = (0.0, w * f * res, 0.0, h * f * res)
        panel_w = 3.4 * figsize_scale
        panel_h = min(max(panel_w * self.H_m / self.W_m, 1.8), 7.0)
        self.fig = Figure(figsize=(3 * panel_w + 2.4, panel_h + 1.3), layout="constrained")
        FigureCanvasAgg(self.fig)
        self.axes: list[Axes] = list(self.fig.subplots(1, 3))
        steps = result.steps

        winds = [s.wind_mean for s in steps if s.wind_mean is not None]
        concs = [s.log_conc_mean for s in steps if s.log_conc_mean is not None]
        wmax = max((float(np.nanmax(np.hypot(a[0], a[1]))) for a in winds), default=1.0)
        cmax = max(max((float(np.nanmax(a)) for a in concs), default=1.0), 1.0)  # as the case figure
        self.has_wind, self.has_conc = bool(winds), bool(concs)

        blank = np.zeros((h, w))
        a_w, a_c, a_p = self.axes
        self.im_wind = a_w.imshow(
            blank, origin="lower", extent=ext, cmap=colormaps["viridis"], vmin=0.0, vmax=max(wmax, 1e-6)
        )
        self.im_conc = a_c.imshow(
            blank, origin="lower", extent=ext, cmap=colormaps["inferno"], vmin=0.0, vmax=cmax
        )
        self.im_prob = a_p.imshow(blank, origin="lower", extent=ext, cmap=colormaps["magma"], vmin=0, vmax=1)
        self.fig.colorbar(self.im_wind, ax=a_w, shrink=0.85, pad=0.02, label="wind speed [m/s]")
        label_ppm_colorbar(self.fig.colorbar(self.im_conc, ax=a_c, shrink=0.85, pad=0.02), cmax)
        self.fig.colorbar(self.im_prob, ax=a_p, shrink=0.85, pad=0.02, label="source probability")
        for im in (self.im_wind, self.im_conc, self.im_prob):
            im.set_interpolation("nearest")

        # wind arrows on a sub-grid of the recorded map
        step = max(1, math.ceil(max(h, w) / _ARROWS_ALONG))
        rows, cols = np.arange(step // 2, h, step), np.arange(step // 2, w, step)
        self.q_ii, self.q_jj = np.meshgrid(rows, cols, indexing="ij")
        cell = f * res
        qx, qy = (self.q_jj + 0.5) * cell, (self.q_ii + 0.5) * cell
        zeros = np.zeros(self.q_ii.shape)
        self.quiver = a_w.quiver(
            qx, qy, zeros, zeros, color="white", scale_units="xy", angles="xy",
            scale=1.0 / (0.6 * step * cell), width=0.006, headwidth=4, zorder=4, alpha=0.9,
        )  # fmt: skip

        walls = np.zeros((H, W, 4))
        walls[case.occupancy != 0] = to_rgba(SOLID_IN_FIELD)
        gas_max = max((s.gas for s in steps), default=0.0)
        self.gas_scale = gas_max if gas_max > 0 else 1.0
        sx, sy = float(case.source[0]), float(case.source[1])
        start_x, start_y = case.grid.center_of(*result.start_cell)
        inlets, outlets = openings_of(case.meta)
        self.lines: list[Line2D] = []
        self.scatters = []
        self.estimates: list[Line2D] = []
        titles = ("Predicted wind", "Predicted concentration", "Source posterior")
        for ax, title in zip(self.axes, titles, strict=True):
            ax.imshow(walls, origin="lower", extent=(0.0, self.W_m, 0.0, self.H_m), zorder=3)
            draw_openings(ax, inlets, outlets, self.W_m, self.H_m, thick=False)
            ax.plot(start_x, start_y, ls="none", zorder=7, **START_STYLE)
            (line,) = ax.plot([], [], color=TRAJECTORY_COLOR, lw=1.4, zorder=5)
            self.lines.append(line)
            sc = ax.scatter(
                [], [], s=[], facecolors="none", edgecolors=MEASUREMENT_COLOR, linewidths=1.4, zorder=6
            )
            self.scatters.append(sc)
            ax.plot(sx, sy, ls="none", zorder=8, **_SOURCE)
            (est,) = ax.plot([], [], ls="none", marker="X", ms=9, mfc="white", mec="black", zorder=9)
            self.estimates.append(est)
            ax.set_xlim(0, self.W_m)
            ax.set_ylim(0, self.H_m)
            ax.set_aspect("equal")
            ax.set_xlabel("x [m]")
            ax.set_title(title, fontsize=10)
        self.axes[0].set_ylabel("y [m]")
        for ax, ok, what in ((a_w, self.has_wind, "wind"), (a_c, self.has_conc, "concentration")):
            if not ok:
                ax.text(0.5, 0.5, f"no {what} estimate", transform=ax.transAxes, ha="center", zorder=10)
        handles = [
            Line2D([], [], ls="none", label="start", **START_STYLE),
            Line2D([], [], color=TRAJECTORY_COLOR, lw=1.4, label="trajectory"),
            Line2D([], [], ls="none", marker="o", mfc="none", mec=MEASUREMENT_COLOR, label="measurements"),
            Line2D([], [], ls="none", label="true source", **{**_SOURCE, "ms": 10}),
            Line2D([], [], ls="none", marker="X", mfc="white", mec="black", label="estimate"),
            *opening_handles(),
        ]
        self.fig.legend(
            handles=handles, loc="outside lower center", ncol=len(handles), frameon=False, fontsize=8
        )
        res_xy = np.asarray(result.trajectory_cells, dtype=np.float64)
        self.traj_x = (res_xy[:, 1] + 0.5) * res
        self.traj_y = (res_xy[:, 0] + 0.5) * res

    def draw(self, k: int) -> Figure:
        """Show step ``k`` (0-based index into ``result.steps``)."""
        r = self.result
        s = r.steps[k]
        res = self.case.resolution
        if s.wind_mean is not None:
            speed = np.hypot(s.wind_mean[0], s.wind_mean[1])
            self.im_wind.set_data(speed)
            u = s.wind_mean[0][self.q_ii, self.q_jj]
            v = s.wind_mean[1][self.q_ii, self.q_jj]
            n = np.hypot(u, v)
            n = np.where(n > 1e-9, n, 1.0)
            self.quiver.set_UVC(u / n, v / n)
        if s.log_conc_mean is not None:
            self.im_conc.set_data(s.log_conc_mean)
        p = s.source_probs
        assert p is not None
        self.im_prob.set_data(p)
        self.im_prob.set_clim(0.0, max(float(np.nanmax(p)), 1e-12))

        upto = np.searchsorted(r.trajectory_times, s.time_s, side="right")
        cells = np.array([t.cell for t in r.steps[: k + 1]], dtype=np.float64)
        mx, my = (cells[:, 1] + 0.5) * res, (cells[:, 0] + 0.5) * res
        gas = np.array([t.gas for t in r.steps[: k + 1]])
        sizes = _MIN_MARKER + (_MAX_MARKER - _MIN_MARKER) * np.clip(gas / self.gas_scale, 0, 1)
        for line, sc, est in zip(self.lines, self.scatters, self.estimates, strict=True):
            line.set_data(self.traj_x[: max(upto, 1)], self.traj_y[: max(upto, 1)])
            sc.set_offsets(np.column_stack([mx, my]))
            sc.set_sizes(sizes)
            est.set_data([s.estimate_xy[0]], [s.estimate_xy[1]])
        self.fig.suptitle(
            f"{r.case_name}, {r.method} + {r.planner}:  k = {s.step},  t = {s.time_s:.0f} s,  "
            f"H / log N = {s.normalized_entropy:.2f},  error = {s.error_m:.2f} m",
            fontsize=10,
        )
        return self.fig


def plot_search_step(result: EpisodeResult, case: Case, step: int = -1) -> Figure:
    """The three panels at search step ``step`` (index into ``result.steps``; -1: the last).

    Raises:
        InputDataError: the episode has no steps or no recorded maps, or does
            not belong to ``case``'s map.
    """
    fig = _SearchFigure(result, case)
    n = len(result.steps)
    if not -n <= step < n:
        raise InputDataError(f"step {step} out of range for an episode of {n} steps")
    return fig.draw(step % n)


def frame_steps(n_steps: int, max_frames: int) -> list[int]:
    """Up to ``max_frames`` step indices spread evenly over ``n_steps``, the first and last included."""
    if n_steps <= max_frames:
        return list(range(n_steps))
    if max_frames < 2:
        return [n_steps - 1]
    return sorted({round(x) for x in np.linspace(0, n_steps - 1, max_frames)})


def animate_episode(
    result: EpisodeResult,
    case: Case,
    path: str | Path,
    *,
    fps: int = 2,
    dpi: int = 80,
    max_frames: int = 60,
    hold_last: int = 3,
) -> Path:
    """Write a GIF of the search, one frame per step (at most ``max_frames``, evenly spread).

    Args:
        result: an episode run with ``record=True`` on ``case``.
        case: the case it ran on.
        path: the GIF to write (parent directories are created).
        fps: frames per second.
        dpi: resolution.
        max_frames: at most this many steps are drawn.
        hold_last: the last frame is repeated this many extra times.

    Returns:
        The path written.
    """
    if not (fps > 0 and dpi > 0 and max_frames >= 1 and hold_last >= 0):
        raise InputDataError("fps, dpi and max_frames must be positive and hold_last >= 0")
    path = Path(path)
    if path.suffix.lower() != ".gif":
        raise InputDataError(f"animation {path.name!r} must be a .gif file")
    sf = _SearchFigure(result, case)
    path.parent.mkdir(parents=True, exist_ok=True)
    ks = frame_steps(len(result.steps), max_frames)
    writer = PillowWriter(fps=fps)
    with atomic_path(path) as tmp, writer.saving(sf.fig, str(tmp), dpi):
        for n, k in enumerate(ks):
            sf.draw(k)
            if n == 0:  # lay the figure out once (the frames differ only in data), then freeze it
                sf.fig.canvas.draw()
                sf.fig.set_layout_engine(None)
            writer.grab_frame()
        for _ in range(hold_last):
            writer.grab_frame()
    return path
