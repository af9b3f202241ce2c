"""Figure of an estimator's belief, next to the truth when it is known.

:func:`plot_belief` returns a :class:`matplotlib.figure.Figure` on the Agg
canvas (no display needed, pyplot untouched).  Maps are drawn with
``origin="lower"`` and their extent in metres (spec section 1); solid cells
are light grey in the field panels.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.animation import PillowWriter
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from dgse.belief.belief import Belief
from dgse.errors import InputDataError
from dgse.files import atomic_path
from dgse.sensing.sensors import Observations
from dgse.viz.case import SOURCE_STYLE as _CASE_SOURCE_STYLE
from dgse.viz.case import _style_map_axes, field_image, log_ppm_ticks, wind_arrows
from dgse.world.case import Case

__all__ = ["animate_beliefs", "plot_belief"]

ESTIMATE_STYLE: dict[str, Any] = {"marker": "X", "ms": 11, "mfc": "white", "mec": "black", "mew": 1.0}
SOURCE_STYLE: dict[str, Any] = dict(_CASE_SOURCE_STYLE)
SENSOR_COLOR = "#7dff5c"
#: Arrows along the longer side of a wind panel.
_ARROWS_ALONG = 20

Panel = Callable[[Figure, Axes], None]


def _imshow(
    fig: Figure,
    ax: Axes,
    field: np.ndarray,
    solid: np.ndarray,
    extent: tuple[float, float, float, float],
    cmap: str,
    label: str,
    vmin: float = 0.0,
    vmax: float | None = None,
    log_ppm: bool = False,
) -> None:
    finite = field[~solid]
    top = float(finite.max()) if finite.size else 1.0
    vmax = max(top if vmax is None else vmax, vmin + 1e-9)
    im = field_image(ax, field, solid, extent, cmap, vmin, vmax)
    cb = fig.colorbar(im, ax=ax, shrink=0.85, pad=0.02)
    if log_ppm:
        ticks, labels = log_ppm_ticks(vmax)
        cb.set_ticks(ticks, labels=labels)
    cb.set_label(label, fontsize=8)
    cb.ax.tick_params(labelsize=7)


def _sensor_sizes(gas: np.ndarray) -> np.ndarray:
    """Marker areas (points^2) growing with the gas reading: 6 at 0, 90 at the largest."""
    g = np.log1p(np.maximum(np.asarray(gas, dtype=np.float64), 0.0))
    top = float(g.max()) if g.size else 0.0
    return 6.0 + 84.0 * (g / top if top > 0 else np.zeros_like(g))


def _sensors(ax: Axes, obs: Observations, res: float, wind: bool = False) -> None:
    if len(obs) == 0:
        return
    xy = obs.positions(res)
    ax.scatter(
        xy[:, 0],
        xy[:, 1],
        s=_sensor_sizes(obs.gas),
        facecolor=SENSOR_COLOR,
        edgecolor="black",
        linewidth=0.5,
        alpha=0.9,
        zorder=7,
    )
    if wind:
        speed = np.hypot(obs.wind[:, 0], obs.wind[:, 1])
        keep = speed > 0
        if keep.any():
            ax.quiver(
                xy[keep, 0],
                xy[keep, 1],
                obs.wind[keep, 0] / speed[keep],
                obs.wind[keep, 1] / speed[keep],
                angles="xy",
                scale_units="xy",
                scale=1.0 / (3 * res),
                color=SENSOR_COLOR,
                width=0.004,
                zorder=8,
            )


def _source_markers(ax: Axes, belief: Belief, case: Case | None) -> None:
    ex, ey = belief.source_estimate()
    ax.plot(ex, ey, ls="none", zorder=9, **ESTIMATE_STYLE)
    if case is not None:
        ax.plot(float(case.source[0]), float(case.source[1]), ls="none", zorder=9, **SOURCE_STYLE)


def _check(belief: Belief, case: Case | None, observations: Observations | None) -> None:
    if not isinstance(belief, Belief):
        raise InputDataError(f"plot_belief needs a Belief, got {type(belief).__name__}")
    if case is not None:
        if tuple(case.occupancy.shape) != belief.shape:
            raise InputDataError(
                f"the case's map {tuple(case.occupancy.shape)} and the belief's map {belief.shape} differ"
            )
    if observations is not None and len(observations):
        c = observations.cells
        H, W = belief.shape
        if c[:, 0].min() < 0 or c[:, 1].min() < 0 or c[:, 0].max() >= H or c[:, 1].max() >= W:
            raise InputDataError("observation cells lie outside the belief's map")


def plot_belief(belief: Belief, case: Case | None = None, observations: Observations | None = None) -> Figure:
    """The belief's panels, with the truth and the errors when ``case`` is given.

    Panels (those the belief has data for):

    1. source posterior ``pi_s`` with the probability-weighted estimate (white
       X), the true source (star, with ``case``) and the sensors;
    2. wind mean: speed with direction arrows, the sensors' wind readings as
       cyan arrows; 3. wind standard deviation ``sqrt(var_x + var_y)``;
       4. (with ``case``) the true wind;
    5. log-concentration mean ``E[log(1 + c)]`` (ticks in ppm) with the
       sensors, marker area growing with the gas reading; 6. its standard
       deviation; 7. (with ``case``) the true ``log(1 + c)``; 8. (with
       ``case``) the error ``|mean - log(1 + c_true)|``.

    Args:
        belief: the estimate.
        case: the true scenario on the same map (optional).
        observations: the readings the estimate used (optional).

    Returns:
        The figure (map panels plus one colorbar axes per field panel).

    Raises:
        InputDataError: ``case`` or ``observations`` that do not fit the belief's map.
    """
    _check(belief, case, observations)
    H, W = belief.shape
    res = belief.resolution
    W_m, H_m = W * res, H * res
    extent = (0.0, W_m, 0.0, H_m)
    solid = belief.occupancy != 0
    obs = observations if observations is not None and len(observations) else None

    def posterior(fig: Figure, ax: Axes) -> None:
        _imshow(fig, ax, belief.source_probs, solid, extent, "magma", "source probability")
        if obs is not None:
            _sensors(ax, obs, res)
        _source_markers(ax, belief, case)
        title = f"Source posterior (H / log N = {belief.normalized_entropy():.2f})"
        if case is not None:
            title += (
                f"\nerror {belief.localization_error((float(case.source[0]), float(case.source[1]))):.2f} m"
            )
        _style_map_axes(ax, title, W_m, H_m)

    panels: list[Panel] = [posterior]
    wm, wv = belief.wind_mean, belief.wind_var
    speed_max = None
    if case is not None:
        speed_max = float(np.hypot(case.wind[0], case.wind[1])[~solid].max(initial=0.0))
    if wm is not None:
        speed = np.hypot(wm[0], wm[1])
        top = max(float(speed[~solid].max(initial=0.0)), speed_max or 0.0)

        def wind_mean(fig: Figure, ax: Axes) -> None:
            _imshow(fig, ax, speed, solid, extent, "viridis", "speed [m/s]", vmax=top)
            wind_arrows(ax, wm, solid, res, _ARROWS_ALONG, width=0.004)
            if obs is not None:
                _sensors(ax, obs, res, wind=True)
            _style_map_axes(ax, "Wind mean", W_m, H_m)

        panels.append(wind_mean)
        if wv is not None:
            std = np.sqrt(wv[0] + wv[1])

            def wind_std(fig: Figure, ax: Axes) -> None:
                _imshow(fig, ax, std, solid, extent, "cividis", "std [m/s]")
                _style_map_axes(ax, "Wind std", W_m, H_m)

            panels.append(wind_std)
        if case is not None:
            true_wind = case.wind.astype(np.float64)

            def wind_truth(fig: Figure, ax: Axes) -> None:
                _imshow(
                    fig,
                    ax,
                    np.hypot(true_wind[0], true_wind[1]),
                    solid,
                    extent,
                    "viridis",
                    "speed [m/s]",
                    vmax=top,
                )
                wind_arrows(ax, true_wind, solid, res, _ARROWS_ALONG, width=0.004)
                _style_map_axes(ax, "Wind (truth)", W_m, H_m)

            panels.append(wind_truth)
    lm, lv = belief.log_conc_mean, belief.log_conc_var
    if lm is not None:
        truth = None if case is None else np.log1p(np.maximum(case.concentration.astype(np.float64), 0.0))
        cmax = max(float(lm[~solid].max(initial=0.0)), 0.0 if truth is None else float(truth.max()), 1.0)

        def conc_mean(fig: Figure, ax: Axes) -> None:
            _imshow(fig, ax, lm, solid, extent, "inferno", "ppm, log(1 + c) scale", vmax=cmax, log_ppm=True)
            if obs is not None:
                _sensors(ax, obs, res)
            _source_markers(ax, belief, case)
            _style_map_axes(ax, "Concentration mean", W_m, H_m)

        panels.append(conc_mean)
        if lv is not None:

            def conc_std(fig: Figure, ax: Axes) -> None:
                _imshow(fig, ax, np.sqrt(lv), solid, extent, "cividis", "std of log(1 + c)")
                _style_map_axes(ax, "Concentration std", W_m, H_m)

            panels.append(conc_std)
        if truth is not None:
            t = truth

            def conc_truth(fig: Figure, ax: Axes) -> None:
                _imshow(
                    fig, ax, t, solid, extent, "inferno", "ppm, log(1 + c) scale", vmax=cmax, log_ppm=True
                )
                if case is not None:
                    ax.plot(float(case.source[0]), float(case.source[1]), ls="none", zorder=9, **SOURCE_STYLE)
                _style_map_axes(ax, "Concentration (truth)", W_m, H_m)

            def conc_error(fig: Figure, ax: Axes) -> None:
                _imshow(fig, ax, np.abs(lm - t), solid, extent, "Reds", "|error| of log(1 + c)")
                _style_map_axes(ax, "Concentration error", W_m, H_m)

            panels += [conc_truth, conc_error]

    ncols = min(len(panels), 4 if case is not None else 3)
    nrows = math.ceil(len(panels) / ncols)
    map_w = 3.4
    map_h = min(max(map_w * H_m / W_m, 1.8), 6.0)
    fig = Figure(figsize=(ncols * (map_w + 1.1), nrows * (map_h + 0.9) + 0.8), layout="constrained")
    FigureCanvasAgg(fig)
    axes = np.atleast_1d(fig.subplots(nrows, ncols, squeeze=False)).ravel()
    for ax, draw in zip(axes, panels, strict=False):
        draw(fig, ax)
        ax.tick_params(labelsize=7)
        ax.xaxis.label.set_size(8)
        ax.yaxis.label.set_size(8)
        ax.title.set_size(9)
    for ax in axes[len(panels) :]:
        fig.delaxes(ax)
    handles = [Line2D([], [], ls="none", label="estimate", **ESTIMATE_STYLE)]
    if case is not None:
        handles.append(Line2D([], [], ls="none", label="true source", **SOURCE_STYLE))
    if obs is not None:
        handles.append(
            Line2D([], [], ls="none", marker="o", mfc=SENSOR_COLOR, mec="black", label="sensors (size: gas)")
        )
    fig.legend(handles=handles, loc="outside lower center", ncol=len(handles), frameon=False, fontsize=8)
    parts = [belief.method]
    if obs is not None:
        parts.append(f"{len(obs)} observations")
    seconds = belief.info.get("seconds")
    if isinstance(seconds, (int, float)) and math.isfinite(seconds):
        parts.append(f"{seconds:.2f} s")
    if case is not None:
        parts.append(case.name)
    fig.suptitle(", ".join(parts), fontsize=11)
    return fig


def animate_beliefs(
    source_probs: np.ndarray,
    occupancy: np.ndarray,
    resolution: float,
    cells: np.ndarray,
    path: str | Path,
    *,
    fps: float = 2.0,
    dpi: int = 80,
) -> Path:
    """A GIF of a sequence of source posteriors: frame ``k`` shows ``source_probs[k]`` with the
    readings ``cells[:k + 1]`` (the newest ringed) and the belief's mean (white X).

    Args:
        source_probs: ``(n, H, W)`` one posterior per reading.
        occupancy: ``(H, W)`` the map, 1 solid.
        resolution: cell size, m.
        cells: ``(n, 2)`` the cell of each reading.
        path: the GIF to write (atomically, :func:`dgse.files.atomic_path`).

    Raises:
        InputDataError: shapes that do not agree, or no frame.
    """
    probs = np.asarray(source_probs, dtype=np.float64)
    occ = np.asarray(occupancy)
    cells = np.asarray(cells, dtype=np.int64).reshape(-1, 2)
    if probs.ndim != 3 or probs.shape[1:] != occ.shape or len(probs) != len(cells) or not len(probs):
        raise InputDataError(
            f"posteriors {probs.shape}, map {occ.shape} and {len(cells)} readings do not make an animation"
        )
    H, W = occ.shape
    extent = (0.0, W * resolution, 0.0, H * resolution)
    solid = occ != 0
    fig = Figure(figsize=(5.0, 5.0 * H / W + 0.6))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    top = float(probs[:, ~solid].max()) if (~solid).any() else 1.0
    im = field_image(ax, probs[0], solid, extent, "magma", 0.0, max(top, 1e-12))
    fig.colorbar(im, ax=ax, shrink=0.85, pad=0.02).set_label("source probability", fontsize=8)
    xy = (cells[:, ::-1] + 0.5) * resolution
    (trail,) = ax.plot([], [], "o-", color="cyan", ms=3, lw=0.8)
    (newest,) = ax.plot([], [], "o", mfc="none", mec="white", ms=9)
    (mean,) = ax.plot([], [], "x", color="white", ms=9, mew=2)
    _style_map_axes(ax, "", extent[1], extent[3])
    ii, jj = np.mgrid[0:H, 0:W]
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    writer = PillowWriter(fps=fps)
    with atomic_path(path) as tmp, writer.saving(fig, str(tmp), dpi):
        for k in range(len(probs)):
            p = probs[k]
            im.set_data(np.ma.masked_where(solid, p))
            trail.set_data(xy[: k + 1, 0], xy[: k + 1, 1])
            newest.set_data(xy[k : k + 1, 0], xy[k : k + 1, 1])
            total = p.sum() or 1.0
            mean.set_data([float(((jj + 0.5) * p).sum() / total * resolution)],
                          [float(((ii + 0.5) * p).sum() / total * resolution)])  # fmt: skip
            ax.set_title(f"source posterior after reading {k + 1} of {len(probs)}", fontsize=9)
            writer.grab_frame()
    return path
