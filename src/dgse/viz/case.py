"""Figures of a case and of a layout (what users see first).

Every function returns a :class:`matplotlib.figure.Figure` drawn on the Agg
canvas (no display needed, pyplot's global state untouched); the caller saves
it (``fig.savefig("case.png")``).  Maps are drawn with ``origin="lower"`` and
their extent in metres (spec section 1); solid cells are dark grey in the
layout panel and light grey in the field panels.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
from matplotlib import colormaps
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colorbar import Colorbar
from matplotlib.colors import Colormap, ListedColormap
from matplotlib.figure import Figure
from matplotlib.image import AxesImage
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from dgse.errors import InputDataError
from dgse.world.case import Case
from dgse.world.layout import INWARD_NORMAL, Layout, Opening

__all__ = [
    "CONCENTRATION_LABEL",
    "INLET_COLOR",
    "OUTLET_COLOR",
    "SOURCE_STYLE",
    "draw_openings",
    "field_image",
    "label_ppm_colorbar",
    "log_ppm_ticks",
    "opening_handles",
    "openings_of",
    "plot_case",
    "plot_layout",
    "wind_arrows",
]

INLET_COLOR = "#1a9641"
OUTLET_COLOR = "#d7191c"
SOLID_COLOR = "#4d4d4d"
SOLID_IN_FIELD = "#bdbdbd"
SOURCE_STYLE = {"marker": "*", "ms": 15, "mfc": "#00e5ff", "mec": "black", "mew": 0.9}
#: The colour bar of a concentration drawn on a ``log(1 + c)`` scale (:func:`label_ppm_colorbar`).
CONCENTRATION_LABEL = "concentration [ppm], log(1 + c) scale"
_OCC_CMAP = ListedColormap(["white", SOLID_COLOR])
#: Arrows along the longer side of the wind panel.
_ARROWS_ALONG = 24


# -- helpers -----------------------------------------------------------------------------
def _new_figure(n_panels: int, width_m: float, height_m: float) -> Figure:
    """A constrained-layout figure on the Agg canvas, sized for the map's aspect ratio."""
    map_w = 3.5 if n_panels > 1 else 5.5  # inches of one map panel
    map_h = min(max(map_w * height_m / width_m, 2.0), 8.0)
    colorbars = 1.1 * (n_panels - 1)
    fig = Figure(figsize=(n_panels * (map_w + 0.7) + colorbars, map_h + 1.7), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def openings_of(meta: Mapping) -> tuple[list[Opening], list[Opening]]:
    """Inlets and outlets named in a case's ``meta`` (empty when absent or malformed)."""

    def read(plural: str, single: str) -> list[Opening]:
        items = meta.get(plural, [meta[single]] if single in meta else [])
        try:
            return [Opening.from_dict(d) for d in items]
        except (InputDataError, TypeError):
            return []

    return read("inlets", "inlet"), read("outlets", "outlet")


def _segment(o: Opening, width_m: float, height_m: float) -> tuple[list[float], list[float]]:
    """``([x0, x1], [y0, y1])`` of an opening on the outer boundary."""
    if o.side == "west":
        return [0.0, 0.0], [o.start_m, o.end_m]
    if o.side == "east":
        return [width_m, width_m], [o.start_m, o.end_m]
    if o.side == "south":
        return [o.start_m, o.end_m], [0.0, 0.0]
    return [o.start_m, o.end_m], [height_m, height_m]


def draw_openings(
    ax: Axes,
    inlets: Sequence[Opening],
    outlets: Sequence[Opening],
    width_m: float,
    height_m: float,
    *,
    thick: bool = True,
) -> None:
    """Inlets (green) and outlets (red) as bars on the boundary with a flow-direction arrow."""
    lw = 6.0 if thick else 3.5
    arrow = 0.07 * max(width_m, height_m)
    for kind, group, color in (("inlet", inlets, INLET_COLOR), ("outlet", outlets, OUTLET_COLOR)):
        for o in group:
            xs, ys = _segment(o, width_m, height_m)
            ax.plot(xs, ys, color=color, lw=lw, solid_capstyle="butt", clip_on=False, zorder=6)
            nx, ny = INWARD_NORMAL[o.side]
            mx, my = 0.5 * (xs[0] + xs[1]), 0.5 * (ys[0] + ys[1])
            inner = (mx + nx * arrow, my + ny * arrow)
            tail, head = ((mx, my), inner) if kind == "inlet" else (inner, (mx, my))
            ax.annotate(
                "",
                xy=head,
                xytext=tail,
                zorder=7,
                arrowprops={"arrowstyle": "-|>", "color": color, "lw": 1.8, "mutation_scale": 12},
            )


def _style_map_axes(ax: Axes, title: str, width_m: float, height_m: float) -> None:
    ax.set_xlim(0, width_m)
    ax.set_ylim(0, height_m)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title, fontsize=11)
    for spine in ax.spines.values():
        spine.set_linewidth(0.8)


def _draw_occupancy(ax: Axes, occupancy: np.ndarray, extent: tuple[float, float, float, float]) -> None:
    ax.imshow(
        occupancy,
        cmap=_OCC_CMAP,
        vmin=0,
        vmax=1,
        origin="lower",
        extent=extent,
        interpolation="nearest",
    )


def _add_legend(fig: Figure, ax: Axes, handles: list, own: bool) -> None:
    """The key: below the panels on a figure of our own, else inside ``ax``."""
    if own:
        fig.legend(
            handles=handles,
            loc="outside lower center",
            ncol=len(handles),
            frameon=False,
            fontsize=9,
            handlelength=1.6,
            columnspacing=1.4,
        )
    else:
        ax.legend(handles=handles, loc="upper right", fontsize=7, framealpha=0.85)


def opening_handles() -> list[Line2D]:
    """Legend entries of the inlets and outlets :func:`draw_openings` draws."""
    return [
        Line2D([], [], color=INLET_COLOR, lw=4, label="inlet"),
        Line2D([], [], color=OUTLET_COLOR, lw=4, label="outlet"),
    ]


def _layout_handles(with_source: bool) -> list:
    handles: list = [Patch(facecolor=SOLID_COLOR, edgecolor="none", label="solid"), *opening_handles()]
    if with_source:
        handles.append(Line2D([], [], ls="none", label="source", **SOURCE_STYLE))
    return handles


def log_ppm_ticks(vmax: float) -> tuple[list[float], list[str]]:
    """Colorbar ticks at round ppm values on a ``log(1 + c)`` axis up to ``vmax``."""
    values = [0.0]
    for decade in range(0, 9):
        for m in (1, 3):
            v = m * 10.0**decade
            if math.log1p(v) <= vmax * 1.0001:
                values.append(v)
    if len(values) > 7:  # keep it readable: drop the 3s
        values = [v for v in values if v == 0 or str(int(v)).startswith("1")]
    return [math.log1p(v) for v in values], [f"{v:g}" for v in values]


def label_ppm_colorbar(colorbar: Colorbar, vmax: float) -> None:
    """Ticks at round ppm values and :data:`CONCENTRATION_LABEL` on a colour bar of ``log(1 + c)``."""
    ticks, labels = log_ppm_ticks(vmax)
    colorbar.set_ticks(ticks, labels=labels)
    colorbar.set_label(CONCENTRATION_LABEL)


def _as_axes(ax: Axes | Sequence[Axes] | None, n: int, what: str) -> list[Axes] | None:
    if ax is None:
        return None
    axes = [ax] if isinstance(ax, Axes) else list(np.ravel(np.asarray(ax, dtype=object)))
    if len(axes) != n or not all(isinstance(a, Axes) for a in axes):
        raise InputDataError(f"{what} needs {n} matplotlib Axes, got {len(axes)}")
    return axes


# -- public ------------------------------------------------------------------------------
def plot_case(case: Case, *, ax: Sequence[Axes] | None = None, arrows: bool = True) -> Figure:
    """Three panels of a case: layout, wind speed, log concentration.

    1. Layout: solid cells dark grey, inlets green and outlets red on the
       boundary (arrows show the flow direction), the source as a star.
    2. Wind speed ``|w|`` in m/s with direction arrows (unit length, one per
       ``~max(H, W) / 24`` cells) when ``arrows``.
    3. Concentration on a ``log(1 + c)`` colour scale, ticks in ppm, and the source.

    Args:
        case: the case to draw.
        ax: three Axes to draw into (their figure is returned, no suptitle is
            set); ``None`` makes a new figure.
        arrows: draw the wind direction arrows.

    Returns:
        The figure: 3 map panels plus 2 colorbar axes (5 axes on a new figure).
    """
    grid = case.grid
    W_m, H_m = grid.width_m, grid.height_m
    extent = (0.0, W_m, 0.0, H_m)
    axes = _as_axes(ax, 3, "plot_case")
    if axes is None:
        fig = _new_figure(3, W_m, H_m)
        axes = list(fig.subplots(1, 3))
        own = True
    else:
        fig = axes[0].get_figure()  # type: ignore[assignment]
        own = False
    a_occ, a_wind, a_gas = axes
    solid = case.occupancy == 1
    inlets, outlets = openings_of(case.meta)
    sx, sy = float(case.source[0]), float(case.source[1])

    # 1. layout
    _draw_occupancy(a_occ, case.occupancy, extent)
    draw_openings(a_occ, inlets, outlets, W_m, H_m)
    a_occ.plot(sx, sy, ls="none", zorder=8, **SOURCE_STYLE)
    _style_map_axes(a_occ, "Layout" if own else f"{case.name}: layout", W_m, H_m)
    _add_legend(fig, a_occ, _layout_handles(with_source=True), own)

    # 2. wind speed + direction
    speed = np.hypot(case.wind[0], case.wind[1])
    im = field_image(a_wind, speed, solid, extent, "viridis", 0.0, max(float(speed.max()), 1e-6))
    fig.colorbar(im, ax=a_wind, shrink=0.9, pad=0.02, label="wind speed [m/s]")
    if arrows:
        wind_arrows(a_wind, case.wind, solid, case.resolution)
    draw_openings(a_wind, inlets, outlets, W_m, H_m, thick=False)
    _style_map_axes(a_wind, "Wind", W_m, H_m)

    # 3. concentration
    logc = np.log1p(np.maximum(case.concentration, 0.0))
    vmax = max(float(logc.max()), 1.0)
    im = field_image(a_gas, logc, solid, extent, "inferno", 0.0, vmax)
    label_ppm_colorbar(fig.colorbar(im, ax=a_gas, shrink=0.9, pad=0.02), vmax)
    draw_openings(a_gas, inlets, outlets, W_m, H_m, thick=False)
    a_gas.plot(sx, sy, ls="none", zorder=8, **SOURCE_STYLE)
    _style_map_axes(a_gas, "Gas concentration", W_m, H_m)
    peak = float(case.concentration.max())
    a_gas.text(
        0.02,
        0.98,
        f"max {peak:,.0f} ppm" if peak >= 10 else f"max {peak:.3g} ppm",
        transform=a_gas.transAxes,
        ha="left",
        va="top",
        fontsize=8,
        color="white",
        zorder=9,
        bbox={"boxstyle": "round,pad=0.25", "fc": "black", "alpha": 0.55, "ec": "none"},
    )

    if own:
        fig.suptitle(_case_title(case), fontsize=12)
    return fig


def plot_layout(layout: Layout, *, ax: Axes | None = None) -> Figure:
    """The layout: solid cells dark grey, inlets green and outlets red on the boundary.

    Args:
        layout: the layout to draw.
        ax: one Axes to draw into (its figure is returned); ``None`` makes a new figure.

    Returns:
        The figure (1 axes on a new figure).
    """
    grid = layout.grid
    W_m, H_m = grid.width_m, grid.height_m
    axes = _as_axes(ax, 1, "plot_layout")
    own = axes is None
    if axes is None:
        fig = _new_figure(1, W_m, H_m)
        a = fig.subplots()
    else:
        a = axes[0]
        fig = a.get_figure()  # type: ignore[assignment]
    _draw_occupancy(a, layout.occupancy, (0.0, W_m, 0.0, H_m))
    draw_openings(a, layout.inlets, layout.outlets, W_m, H_m)
    n_in, n_out = len(layout.inlets), len(layout.outlets)
    openings = (
        "1 inlet, 1 outlet"
        if n_in == n_out == 1
        else f"{n_in} inlet{'s' * (n_in > 1)}, {n_out} outlet{'s' * (n_out > 1)}"
    )
    free = 100.0 * float(layout.free.mean())
    _style_map_axes(a, f"{layout.name}: {W_m:g} x {H_m:g} m, {openings}, {free:.0f} % free", W_m, H_m)
    _add_legend(fig, a, _layout_handles(with_source=False), own)
    return fig


# -- internals ---------------------------------------------------------------------------
def _field_cmap(name: str) -> Colormap:
    """Colormap ``name`` with masked (solid) cells light grey."""

    return colormaps[name].with_extremes(bad=SOLID_IN_FIELD)


def field_image(
    ax: Axes,
    field: np.ndarray,
    solid: np.ndarray,
    extent: tuple[float, float, float, float],
    cmap: str,
    vmin: float,
    vmax: float,
) -> AxesImage:
    """``field`` ``(H, W)`` drawn in metres (``extent``), its ``solid`` cells light grey."""
    return ax.imshow(
        np.ma.masked_where(solid, field),
        cmap=_field_cmap(cmap),
        origin="lower",
        extent=extent,
        interpolation="nearest",
        vmin=vmin,
        vmax=vmax,
    )


def wind_arrows(
    ax: Axes,
    wind: np.ndarray,
    solid: np.ndarray,
    res: float,
    along: int = _ARROWS_ALONG,
    width: float = 0.0045,
) -> None:
    """Unit-length direction arrows of ``wind`` ``(2, H, W)`` (m/s) on a sub-grid of free cells.

    About ``along`` arrows along the longer side, each 0.7 of the sub-grid's step long,
    where the speed is above 1e-3 of the largest; ``width``: the shafts' width as a
    fraction of the axes' width.
    """
    H, W = solid.shape
    speed = np.hypot(wind[0], wind[1])
    step = max(1, math.ceil(max(H, W) / along))
    ii, jj = np.meshgrid(np.arange(step // 2, H, step), np.arange(step // 2, W, step), indexing="ij")
    s = speed[ii, jj]
    keep = ~solid[ii, jj] & (s > 1e-3 * max(float(speed.max()), 1e-12))
    if not keep.any():
        return
    ii, jj, s = ii[keep], jj[keep], s[keep]
    length = 0.7 * step * res  # m
    ax.quiver(
        (jj + 0.5) * res,
        (ii + 0.5) * res,
        wind[0][ii, jj] / s,
        wind[1][ii, jj] / s,
        angles="xy",
        scale_units="xy",
        scale=1.0 / length,
        pivot="mid",
        color="white",
        edgecolor="black",
        linewidth=0.3,
        width=width,
        headwidth=4,
        headlength=4.5,
        headaxislength=4,
        zorder=5,
    )


def _case_title(case: Case) -> str:
    meta = case.meta
    parts = [case.name]
    if "inlet_velocity" in meta:
        parts.append(f"inlet {float(meta['inlet_velocity']):.2f} m/s")
    if "release_rate_gps" in meta:
        parts.append(f"release {float(meta['release_rate_gps']):.3g} g/s")
    parts.append(f"{case.grid.width_m:g} x {case.grid.height_m:g} m")
    if "solver" in meta:
        parts.append(f"solver {meta['solver']}")
    return "  |  ".join(parts)
