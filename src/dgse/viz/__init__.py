"""Figures: :func:`plot_case` (layout, wind, gas of one case) and :func:`plot_layout`.

Every function returns a :class:`matplotlib.figure.Figure` on the Agg canvas;
save it with ``fig.savefig(path)``.
"""

from dgse.viz.case import plot_case, plot_layout

__all__ = ["plot_case", "plot_layout"]
