"""The style leaf: how every figure of truestep looks and is saved. One colour per
engine/method series, one marker and line style per engine, the same in every figure (the
report's, the lecture's, the scaling plot's); a series of an engine it does not know takes
a style chosen by its name, the same on every machine. It imports nothing of truestep, so
every part that draws may import it."""

from __future__ import annotations

import zlib
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

SERIES_COLOURS: dict[tuple[str, str], str] = {
    ("reference", "euler"): "#e6194b",
    ("reference", "midpoint"): "#3cb44b",
    ("reference", "heun"): "#f58231",
    ("reference", "rk4"): "#4363d8",
    ("reference", "dopri5"): "#911eb4",
    ("reference", "symplectic-euler"): "#12a4c4",
    ("reference", "verlet"): "#f032e6",
    ("reference", "implicit-euler"): "#9a6324",
    ("reference", "lecture"): "#000075",
    ("scipy", "RK45"): "#469990",
    ("scipy", "DOP853"): "#808000",
    ("scipy", "Radau"): "#800000",
    ("pymunk", "default"): "#d4a000",
    ("pybullet", "default"): "#ff5c8a",
    ("pybullet", "clean"): "#556b2f",
    ("mujoco", "Euler"): "#000000",
    ("mujoco", "implicit"): "#708090",
    ("mujoco", "implicitfast"): "#7b68ee",
    ("mujoco", "RK4"): "#2e8b57",
    ("drake", "explicit_euler"): "#c71585",
    ("drake", "semi_explicit_euler"): "#00ced1",
    ("drake", "runge_kutta2"): "#ff8c00",
    ("drake", "runge_kutta3"): "#6a5acd",
    ("drake", "implicit_euler"): "#8b0000",
    ("drake", "radau1"): "#bc8f8f",
    ("drake", "radau3"): "#006400",
    ("drake", "runge_kutta5"): "#0000cd",
    ("drake", "bogacki_shampine3"): "#9acd32",
    ("drake", "radau3-ec"): "#483d8b",
    ("mujoco-warp", "Euler"): "#8b7d6b",
    ("mujoco-warp", "implicit"): "#20b2aa",
    ("mujoco-warp", "implicitfast"): "#da70d6",
    ("mujoco-warp", "RK4"): "#e9967a",
    ("newton", "semi-implicit"): "#b03060",
    ("newton", "xpbd"): "#00fa9a",
    ("newton", "vbd"): "#87ceeb",
}
"""A colour for each built-in engine/method series, distinct from every other's, in every
figure. A series of another engine or method takes one of :data:`MORE_COLOURS`, chosen by
its name (the same in every run)."""
MORE_COLOURS = ("#a9a9a9", "#8b4513", "#ff1493", "#1e90ff", "#b22222", "#228b22", "#daa520", "#4b0082")
ENGINE_MARKERS = {
    "reference": "o",
    "scipy": "s",
    "pymunk": "^",
    "pybullet": "D",
    "mujoco": "v",
    "drake": "h",
    "mujoco-warp": "P",
    "newton": "X",
}
"""A marker for each engine (another engine's is chosen by its name from :data:`MORE_MARKERS`,
none of which is a built-in engine's)."""
MORE_MARKERS = ("*", "p", "<", ">", "8", "d")
ENGINE_LINES: dict[str, str | tuple] = {
    "reference": "-",
    "scipy": ":",
    "pymunk": "--",
    "pybullet": "-.",
    "mujoco": (0, (6, 2, 1, 2, 1, 2)),
    "drake": (0, (1, 1)),
    "mujoco-warp": (0, (3, 1, 1, 1)),
    "newton": (0, (5, 1)),
}
"""A line style for each engine (another engine's is solid)."""
LEGEND_FONT = 9
"""Legend text, points (12 px at :data:`REPORT_DPI`)."""
LEGEND_ROW_IN = 0.2
"""Inches a legend entry takes at :data:`LEGEND_FONT` (text and spacing)."""


def legend_height(entries: int, least: float) -> float:
    """A figure height (in) at least ``least`` and tall enough for a one-column legend of
    ``entries`` beside the axes: a run with every engine has about 30 series, which a
    fixed height would cut at both ends."""
    return max(least, LEGEND_ROW_IN * entries + 0.8)


def _chosen(name: str, options: tuple) -> object:
    """One of ``options`` for ``name``, the same in every run and on every machine."""
    return options[zlib.crc32(name.encode("utf-8", "replace")) % len(options)]


def series_colour(engine: str, method: str) -> str:
    """The colour of an engine/method series in every figure."""
    known = SERIES_COLOURS.get((engine, method))
    return known if known is not None else str(_chosen(f"{engine}/{method}", MORE_COLOURS))


REPORT_DPI = 100
"""Resolution of the report's figures: at least 1000 pixels across at the widths drawn
(the page shows them at most 1100 wide), small enough to inline."""


def save(fig, path: Path, dpi: int = REPORT_DPI) -> Path:
    """Write ``fig`` as a compact PNG: ``dpi``, then reduced to a 256-colour palette.

    Line plots use a few dozen colours (one per series, and their anti-aliased edges), so
    the palette keeps each series' own colour and the file (inlined in the HTML report)
    shrinks about threefold.

    The figure is drawn once on its Agg canvas at ``dpi`` and its pixels reduced from
    there: the pixels ``savefig`` would write (tested), without encoding a full-colour PNG
    and reading it back.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from PIL import Image

    path.parent.mkdir(parents=True, exist_ok=True)
    if fig.dpi != dpi:
        fig.set_dpi(dpi)
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    width, height = canvas.get_width_height()
    pixels = Image.frombuffer("RGBA", (width, height), canvas.buffer_rgba(), "raw", "RGBA", 0, 1)
    small = pixels.convert("RGB").quantize(colors=256, method=Image.Quantize.FASTOCTREE)
    plt.close(fig)
    small.save(path, optimize=True)
    return path


def series_style(engine: str, method: str) -> dict:
    """Matplotlib keywords of an engine/method series: its colour (:func:`series_colour`),
    its engine's marker and line style."""
    return {
        "color": series_colour(engine, method),
        "linestyle": ENGINE_LINES.get(engine, "-"),
        "marker": ENGINE_MARKERS.get(engine) or _chosen(engine, MORE_MARKERS),
        "markersize": 5,
        "linewidth": 1.4,
    }
