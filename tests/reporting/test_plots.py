"""The report's plots: what each one shows for rows that are not plain numbers."""

from __future__ import annotations

import math

import matplotlib.pyplot as plt
import pandas as pd

from truestep import style
from truestep.reporting import plots


def _stability_rows() -> pd.DataFrame:
    rows = [
        ("ok", 0.1, 0.2, 0.1001, ""),
        ("ok", 0.5, math.nan, math.inf, "stable at every step tried"),
        ("ok", 0.0, math.nan, 0.001, "unstable at every step tried"),
        ("solver-failed", math.nan, math.nan, math.nan, "the solver failed at dt 0.03 s"),
        ("timeout", math.nan, math.nan, math.nan, "still searching"),
        ("unsupported", math.nan, math.nan, math.nan, "3d"),
    ]
    return pd.DataFrame(
        [
            {
                "case": "c",
                "engine": "reference",
                "method": f"m{i}",
                "status": st,
                "dt_limit": lim,
                "dt_limit_exact": ex,
                "dt_unstable": un,
                "note": note,
            }
            for i, (st, lim, ex, un, note) in enumerate(rows)
        ]
    )


def test_a_search_without_a_limit_keeps_its_row_and_a_lower_bound_is_hatched(tmp_path, monkeypatch):
    shown = {}

    def keep(fig, path, dpi=style.REPORT_DPI):
        ax = fig.axes[0]
        shown["labels"] = [t.get_text() for t in ax.get_yticklabels()]
        shown["texts"] = [t.get_text() for t in ax.texts]
        shown["hatches"] = [bar.get_hatch() for bar in ax.patches]
        shown["widths"] = [bar.get_width() for bar in ax.patches]
        plt.close(fig)
        return path

    monkeypatch.setattr(plots, "save", keep)
    plots.stability_bars(_stability_rows(), "c", tmp_path / "s.png")
    assert shown["labels"] == [f"reference / m{i}" for i in range(5)]  # unsupported: no row
    assert shown["texts"] == [" solver failed: no limit", " search timed out: no limit"]
    assert shown["hatches"] == [None, "//", None, None, None]
    assert shown["widths"][:2] == [0.1, 0.5] and shown["widths"][3:] == [0.0, 0.0]
    assert 0 < shown["widths"][2] < 0.1  # the stub of a method unstable at every step


def test_a_run_whose_cases_are_in_no_family_draws_no_scorecard(tmp_path, recwarn):
    card = pd.DataFrame(
        [
            {
                "engine": "reference",
                "method": "euler",
                "family": "orbits",
                "cost_ratio": 1.0,
                "cases_run": 1,
                "stability_ratio": 1.0,
            }
        ]
    )
    fidelity = pd.DataFrame(columns=["engine", "method", "median"])
    assert plots.scorecard(card, fidelity, [], 1e-4, tmp_path / "card.png") is None
    assert not (tmp_path / "card.png").exists()
    assert not [w for w in recwarn if issubclass(w.category, UserWarning)]


def test_every_built_in_series_has_its_own_colour_and_each_engine_its_marker():
    """One colour per engine/method, the same in every figure (``series_style`` is what
    every figure draws a series with), and one marker per engine."""
    from truestep.adapters import get_adapter

    pairs = [
        (e, m)
        for e in ("reference", "scipy", "pymunk", "pybullet", "mujoco", "drake", "mujoco-warp", "newton")
        for m in get_adapter(e).methods
    ]
    colours = [style.series_style(e, m)["color"] for e, m in pairs]
    assert len(set(colours)) == len(pairs), "two built-in series share a colour"
    markers = {e: style.series_style(e, m)["marker"] for e, m in pairs}
    assert len(set(markers.values())) == len(markers)
    # A plugin's series gets a colour too, the same on every call (and in every run).
    assert style.series_colour("my-euler", "semi-implicit") == style.series_colour(
        "my-euler", "semi-implicit"
    )


def test_every_built_in_series_has_a_colour_of_its_own():
    """Issue 38, item 3: reference/euler and newton/semi-implicit shared #e6194b, though the
    table's docstring says every colour is distinct."""
    from truestep.style import MORE_COLOURS, SERIES_COLOURS

    colours = [c.lower() for c in SERIES_COLOURS.values()]
    assert len(set(colours)) == len(colours)
    assert not set(colours) & {c.lower() for c in MORE_COLOURS}
    # nor does a plugin's engine take a built-in engine's marker
    assert not set(style.ENGINE_MARKERS.values()) & set(style.MORE_MARKERS)


def test_a_saved_figure_has_the_pixels_savefig_draws(tmp_path):
    """:func:`truestep.style.save` draws on the figure's Agg canvas and reduces those
    pixels: the same picture, pixel for pixel, as ``savefig`` at the report's resolution
    reduced alike, at the figure's own dpi and at another."""
    import numpy as np
    from PIL import Image

    def figure(dpi: float):
        fig, axes = plt.subplots(1, 2, figsize=(8, 3), dpi=dpi, sharey=True)
        for k in range(6):
            for ax in axes:
                ax.loglog([1e-3, 1e-2, 1e-1], [1e-6 * (k + 1), 1e-4, 1e-2], marker="o", label=f"s{k}")
        fig.suptitle("work against precision")
        fig.legend(loc="center left", bbox_to_anchor=(0.79, 0.5))
        fig.tight_layout(rect=(0, 0, 0.79, 1))
        return fig

    for dpi in (style.REPORT_DPI, 72):
        theirs_path = tmp_path / f"savefig-{dpi}.png"
        fig = figure(dpi)
        fig.savefig(theirs_path, dpi=style.REPORT_DPI)
        plt.close(fig)
        with Image.open(theirs_path) as img:
            theirs = img.convert("RGB").quantize(colors=256, method=Image.Quantize.FASTOCTREE).convert("RGB")
        mine_path = style.save(figure(dpi), tmp_path / f"save-{dpi}.png")
        with Image.open(mine_path) as img:
            assert img.mode == "P"
            mine = img.convert("RGB")
        assert mine.size == theirs.size
        assert np.array_equal(np.asarray(mine), np.asarray(theirs))
