"""The lecture's figures, reproduced with the reference implementation: the index.

Every figure's scene is a case file (:mod:`truestep.figures.scenes`: ``cases/figures/*.toml``
and library cases) run by the reference adapter; the drawing lives by topic in
:mod:`truestep.figures.odes`, :mod:`truestep.figures.springs`, :mod:`truestep.figures.meshes`,
:mod:`truestep.figures.particles` and :mod:`truestep.figures.contact`. Every figure carries
a caption naming the lecture slide it reproduces, its numbers computed from the runs.
:func:`write_lecture_figures` writes them all as PNGs and returns ``(path, caption)``
pairs for the report.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cached_property
from pathlib import Path

from truestep.figures.contact import fig_bounce, fig_contact
from truestep.figures.meshes import CubeRun, fig_cube, fig_triangle, simulate_cube
from truestep.figures.odes import (
    LinearDecay,
    fig_euler_instability,
    fig_euler_spiral,
    fig_midpoint,
    fig_vector_field,
)
from truestep.figures.particles import Fountain, fig_fountain, fig_strands, simulate_fountain
from truestep.figures.springs import fig_spring_damper_pair, fig_springs

__all__ = [
    "FIGURES",
    "CubeRun",
    "Fountain",
    "LinearDecay",
    "lecture_figure_shares",
    "simulate_cube",
    "simulate_fountain",
    "write_lecture_figures",
]


class _Shared:
    """Simulations that more than one figure draws, run once."""

    @cached_property
    def fountain(self) -> Fountain:
        return simulate_fountain()


FIGURES: list[tuple[str, Callable[[Path, _Shared], str]]] = [
    ("lecture-01-vector-field", lambda p, s: fig_vector_field(p)),
    ("lecture-02-euler-spiral", lambda p, s: fig_euler_spiral(p)),
    ("lecture-03-euler-instability", lambda p, s: fig_euler_instability(p)),
    ("lecture-04-midpoint", lambda p, s: fig_midpoint(p)),
    ("lecture-05-damped-spring", lambda p, s: fig_springs(p)),
    ("lecture-06-spring-damper-pair", lambda p, s: fig_spring_damper_pair(p)),
    ("lecture-07-triangle", lambda p, s: fig_triangle(p)),
    ("lecture-08-cube-inside-out", lambda p, s: fig_cube(p)),
    ("lecture-09-fountain", lambda p, s: fig_fountain(p, s.fountain)),
    ("lecture-10-strands", lambda p, s: fig_strands(p, s.fountain)),
    ("lecture-11-bouncing", lambda p, s: fig_bounce(p)),
    ("lecture-12-contact", lambda p, s: fig_contact(p)),
]
"""File name (without ``.png``) and drawing function of every lecture figure, in slide order."""


def write_lecture_figures(fig_dir: Path, names: list[str] | None = None) -> list[tuple[Path, str]]:
    """Compute and write the lecture figures (those in ``names``, default all) into
    ``fig_dir``; return (path, caption) pairs in slide order."""
    fig_dir = Path(fig_dir)
    fig_dir.mkdir(parents=True, exist_ok=True)
    shared = _Shared()
    out = []
    for name, draw in FIGURES:
        if names is None or name in names:
            path = fig_dir / f"{name}.png"
            out.append((path, draw(path, shared)))
    return out


def lecture_figure_shares(parts: int) -> list[list[str]]:
    """The figure names split into ``parts`` lists of about equal work, to draw in
    separate processes; figures that share a simulation (the fountain and its strands)
    stay together."""
    units: list[list[str]] = []
    for name, _ in FIGURES:
        if units and "fountain" in units[-1][-1] and "strands" in name:
            units[-1].append(name)
        else:
            units.append([name])
    shares: list[list[str]] = [[] for _ in range(max(1, parts))]
    for unit in sorted(units, key=len, reverse=True):
        min(shares, key=len).extend(unit)
    return [s for s in shares if s]
