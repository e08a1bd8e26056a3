"""How the lecture's figures look: resolution, colours, line styles, legends.

A line that is an engine/method series is styled by :func:`truestep.style.series_style`
(every line of the lecture's figures is the reference engine, in its method's colour;
shades of that colour tell step sizes apart). Things that are not engines (particles, scene variants) take
:data:`SCENE_COLOURS`, none of which is an engine's colour; exact solutions are a light
grey band under the computed lines.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.colors as mcolors
import matplotlib.pyplot as plt
import numpy as np

from truestep.style import save, series_style

DPI = 100
"""Resolution of every figure, dots per inch (as the report's other figures:
:data:`truestep.style.REPORT_DPI`)."""
SCENE_COLOURS = ("#e69f00", "#56b4e9", "#999933", "#cc79a7", "#44aa99")
"""Colours for particles and scene variants (none is an engine/method series' colour,
:data:`truestep.style.SERIES_COLOURS`)."""
NIGHT = "#0d0d17"
"""Background of the particle renderings: particles add light, as point light sources."""
EXACT_COLOUR = "#c9c9c9"
"""Exact solutions are a light band under the computed lines."""


def shade(colour: str, k: int, count: int) -> tuple[float, float, float]:
    """The ``k``-th of ``count`` shades of ``colour``: 0 is the colour itself, later ones lighter."""
    rgb = np.array(mcolors.to_rgb(colour))
    return tuple(rgb + (1.0 - rgb) * 0.6 * k / max(count - 1, 1))


def reference_style(method: str, k: int = 0, count: int = 1, **over: object) -> dict:
    """``series_style("reference", method)``, in shade ``k`` of ``count`` (step sizes)."""
    style = series_style("reference", method)
    style["color"] = shade(style["color"], k, count)
    style.update(over)
    return style


def exact_style(**over: object) -> dict:
    """Exact solutions: a wide light band drawn under the runs, so a run on it stays visible."""
    style = {
        "color": EXACT_COLOUR,
        "linestyle": "-",
        "linewidth": 5.0,
        "solid_capstyle": "round",
        "zorder": 1,
    }
    style.update(over)
    return style


def legend_below(ax: plt.Axes, ncol: int = 2, **kw: object) -> None:
    """A legend under the axes, where it cannot cover the data."""
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=ncol, fontsize=8, frameon=False, **kw)


def save_figure(fig: plt.Figure, path: Path) -> None:
    """Write ``fig`` to the PNG ``path`` at :data:`DPI` and close it."""
    save(fig, path, dpi=DPI)
