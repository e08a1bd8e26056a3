"""The lecture's figures on particle systems: the cube emitter's fountain and its strands.

Scene: ``cases/figures/cube-emitter-5000.toml``, run by the reference adapter
(:mod:`truestep.figures.scenes`), one step per frame. What the figures need beyond
positions and velocities is read off the trajectory's ``alive`` mask (one record per
frame, no pool slot used twice): a particle's birth is the record at which its slot turns
alive, its age the records since, its lifespan the records it stays alive. The per-particle
size the emitter draws is not in the trajectory: every particle is drawn at the emitter's
``particle_size``. Each ``fig_*`` function draws one figure into the PNG ``path`` and
returns its caption.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import TYPE_CHECKING, cast

import matplotlib.colors as mcolors
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import EllipseCollection, LineCollection

from truestep.cases.case import Case
from truestep.figures.scenes import figure_case, run_reference
from truestep.figures.style import NIGHT, SCENE_COLOURS, exact_style, save_figure
from truestep.reference_impl.emitters import Emitter, lifetime_values, spawn_count_moments, spawn_mean
from truestep.reference_impl.model import EmitterSpec
from truestep.reference_impl.strands import Strands, collect_strands

if TYPE_CHECKING:
    from mpl_toolkits.mplot3d import Axes3D

    from truestep.reference_impl.particles import ParticleSystem

FOUNTAIN_TARGET = 5000
"""The fountain is drawn at the first frame with this many live particles (the slide's 5000)."""
STRAND_FRAMES = 4
"""The strand figure draws the whole lives of the particles born in the first frames."""
STRAND_TAPER = 0.8
"""Fraction by which a strand's thickness falls from root to tip."""
FOUNTAIN_VIEW = ((-2.5, 2.5), (-4.4, 1.0))
"""x and y limits (m) of the side views of the fountain and its strands."""


@dataclass
class EmitterCounts:
    """Per-record counts of an emitter, read off the alive mask (one record per frame).

    population, spawned : ndarray of int, shape (T,)  alive after the frame, born in it
    dropped : int  new particles that found the pool full: 0, as the pool never filled
    """

    population: np.ndarray
    spawned: np.ndarray
    dropped: int


@dataclass
class Fountain:
    """The cube emitter's run, one record per frame, and what the figures read off it.

    case, spec : the scene and its emitter;  emitter : its counts
    t : (T,) s; x, v : (T, capacity, 3) m and m/s; alive : (T, capacity) bool
    born : (capacity,) record of each slot's birth (-1: never born)
    lifespan : (capacity,) records each slot lives (0: never born)
    snapshot : record index of the first frame with :data:`FOUNTAIN_TARGET` live particles
    colors : (capacity, 4) RGBA at the snapshot; shapes : (capacity, 2) ellipse semi-axes, m
    """

    case: Case
    spec: EmitterSpec
    emitter: EmitterCounts
    t: np.ndarray
    x: np.ndarray
    v: np.ndarray
    alive: np.ndarray
    born: np.ndarray
    lifespan: np.ndarray
    snapshot: int
    colors: np.ndarray
    shapes: np.ndarray


def _lives(case: Case, alive: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Birth record and lifespan (records) of every pool slot, each (capacity,), from the
    alive mask (T, capacity); raises if a slot lived twice (the pool was reused)."""
    turned_on = np.vstack([alive[:1], alive[1:] & ~alive[:-1]])
    if np.any(turned_on.sum(axis=0) > 1):
        raise RuntimeError(f"{case.name}: a pool slot was used twice; raise the emitter's capacity")
    ever = alive.any(axis=0)
    return np.where(ever, np.argmax(alive, axis=0), -1), alive.sum(axis=0)


def _render_attributes(
    spec: EmitterSpec,
    gravity: np.ndarray,
    age: np.ndarray,
    lifespan: np.ndarray,
    x: np.ndarray,
    v: np.ndarray,
    alive: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The lecture's particle attributes at one record, as the reference emitter computes
    them (:meth:`Emitter.colors`, :meth:`Emitter.shapes`): RGBA (n, 4) and ellipse
    semi-axes (n, 2) m, from ages and lifespans (frames) and the recorded state (n, 3)."""
    emitter = Emitter(spec, 0, -gravity)
    emitter.age[:], emitter.lifespan[:] = age, np.maximum(lifespan, 1)
    emitter.size[:] = spec.particle_size
    # the fields of a ParticleSystem that the colours and shapes read
    state = cast("ParticleSystem", SimpleNamespace(positions=x, velocities=v, alive=alive))
    return emitter.colors(state), emitter.shapes(state)


def simulate_fountain(case: Case | None = None, *, target: int = FOUNTAIN_TARGET) -> Fountain:
    """Run the cube emitter's case (default ``cube-emitter-5000``) by the lecture's update
    at one step per frame, and read the snapshot of the first frame with ``target`` live
    particles off it. Raises if the pool filled, or if a particle alive at the snapshot or
    born in the first :data:`STRAND_FRAMES` frames outlives the run (its life would not be
    whole)."""
    case = figure_case("cube-emitter-5000") if case is None else case
    (spec,) = case.particles.emitters
    traj = run_reference(case, "lecture", spec.frame_dt)
    alive = cast(np.ndarray, traj.alive)  # an emitter scene's run
    born, lifespan = _lives(case, alive)
    population = alive.sum(axis=1)
    if population.max() >= spec.capacity:
        raise RuntimeError(f"{case.name}: the emitter's pool filled; raise its capacity")
    reached = np.flatnonzero(population >= target)
    if not len(reached):
        raise RuntimeError(f"{case.name}: {target} particles never alive at once")
    s = int(reached[0])
    whole = alive[s] | ((born >= 0) & (born < STRAND_FRAMES))
    if np.any(whole & alive[-1]):
        raise RuntimeError(f"{case.name}: particles the figures draw outlive the run; lengthen it")
    spawned = np.bincount(born[born >= 0], minlength=len(traj.t))
    colors, shapes = _render_attributes(
        spec, case.particles.gravity, s - born, lifespan, traj.x[s], cast(np.ndarray, traj.v)[s], alive[s]
    )
    return Fountain(
        case,
        spec,
        EmitterCounts(population, spawned, 0),
        traj.t,
        traj.x,
        cast(np.ndarray, traj.v),
        alive,
        born,
        lifespan,
        s,
        colors,
        shapes,
    )


def _night(ax: plt.Axes, view: tuple = FOUNTAIN_VIEW) -> None:
    ax.set_facecolor(NIGHT)
    ax.set_aspect("equal")
    ax.set_xlim(*view[0])
    ax.set_ylim(*view[1])
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m, up)")


def _up(x: np.ndarray) -> np.ndarray:
    """Scene coordinates (..., 3) in matplotlib's 3-D order: x, z, then y (up) as the vertical."""
    return x[..., [0, 2, 1]]


def _add_night_3d(fig: plt.Figure, spec: object) -> Axes3D:
    """A dark 3-D box with y up (scene coordinates drawn through :func:`_up`)."""
    with plt.rc_context({"grid.color": (1.0, 1.0, 1.0, 0.15)}):
        ax = fig.add_subplot(spec, projection="3d")
    ax.set_facecolor(NIGHT)
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        axis.set_pane_color(mcolors.to_rgba(NIGHT))
    (x0, x1), (y0, y1) = FOUNTAIN_VIEW
    ax.set_xlim(x0, x1)
    ax.set_ylim(x0, x1)
    ax.set_zlim(y0, y1)
    ax.set_box_aspect((x1 - x0, x1 - x0, y1 - y0))
    for name, label in (("x", "x (m)"), ("y", "z (m)"), ("z", "y (m, up)")):
        getattr(ax, f"set_{name}label")(label, fontsize=8, color="0.55")
    ax.tick_params(labelsize=7, colors="0.55")
    ax.view_init(elev=12, azim=-60)
    return ax


def _emitter_outline(ax: plt.Axes, spec: EmitterSpec) -> None:
    h = spec.size / 2
    cx, cy = spec.center[:2]
    ax.plot(
        [cx - h, cx + h, cx + h, cx - h, cx - h],
        [cy - h, cy - h, cy + h, cy + h, cy - h],
        color="white",
        linewidth=0.8,
    )


def fig_fountain(path: Path, fountain: Fountain) -> str:
    """The cube emitter's particles at the first frame with 5000 alive, and the population."""
    f, spec = fountain, fountain.spec
    s = f.snapshot
    live = f.alive[s]
    pos, vel = f.x[s][live], f.v[s][live]
    rgba, semi = f.colors[live], f.shapes[live]
    fig = plt.figure(figsize=(15, 6.0))
    grid = fig.add_gridspec(
        1, 3, width_ratios=[1, 1.1, 1], left=0.05, right=0.98, bottom=0.1, top=0.88, wspace=0.22
    )
    ax = fig.add_subplot(grid[0])
    angles = np.degrees(np.arctan2(vel[:, 1], vel[:, 0]))
    ax.add_collection(
        EllipseCollection(
            2 * semi[:, 0],
            2 * semi[:, 1],
            angles,
            units="xy",
            offsets=pos[:, :2],
            offset_transform=ax.transData,
            facecolors=rgba,
            edgecolors="none",
        )
    )
    _night(ax)
    _emitter_outline(ax, spec)
    ax.set_title(
        f"Side view at frame {s} (t = {f.t[s]:.2f} s): {live.sum()} live particles,\n"
        "ellipses stretched along the velocity by one frame's travel",
        fontsize=10,
    )

    ax3 = _add_night_3d(fig, grid[1])
    p3 = _up(pos)
    ax3.scatter(p3[:, 0], p3[:, 1], p3[:, 2], c=rgba, s=1.5, depthshade=False, linewidths=0)
    ax3.set_title("The same particles in 3-D, as points", fontsize=10)

    ax = fig.add_subplot(grid[2])
    population = f.emitter.population
    frames = np.arange(len(population))
    mean, _ = spawn_count_moments(spawn_mean(spec), spec.rate_r)
    lives = lifetime_values(spec)
    expected = mean * np.cumsum([(lives > a).mean() for a in frames])
    steady = frames >= lives.max()
    off = np.max(np.abs(population[steady] / expected[steady] - 1)) if steady.any() else np.nan
    ax.plot(
        frames,
        population,
        color=SCENE_COLOURS[0],
        linewidth=1.8,
        marker="o",
        markersize=3,
        label="live particles (reference emitter)",
    )
    ax.plot(frames, expected, label="expected: (n + r/2) Σ P(lifetime > age)", **exact_style())
    ax.axvline(s, color="0.5", linewidth=0.8, linestyle=":")
    ax.axhline(FOUNTAIN_TARGET, color="0.5", linewidth=0.8, linestyle=":")
    ax.annotate(
        "the snapshot",
        (s, FOUNTAIN_TARGET),
        xytext=(s - 8, FOUNTAIN_TARGET / 2),
        fontsize=9,
        arrowprops={"arrowstyle": "->", "color": "0.3"},
    )
    ax.set_xlabel(f"frame (1/{1 / spec.frame_dt:.0f} s each)")
    ax.set_ylabel("particles alive")
    ax.set_title(
        f"# new per frame = n + Rand() r, n = {spec.rate_n:g}, r = {spec.rate_r:g};\n"
        f"lifetime {spec.lifetime} ± {spec.lifetime_jitter} frames",
        fontsize=10,
    )
    ax.grid(True, alpha=0.3)
    ax.legend(loc="lower right", fontsize=8, frameon=False)
    save_figure(fig, path)
    g = float(np.linalg.norm(f.case.particles.gravity))
    return (
        'Reproduces the lecture slide "A cube emitting 5000 animated particles, obeying a '
        "'gravitational' force in -Y direction\" (Snowflakes vs Hair): the reference emitter "
        f"sprays from all six faces of a {spec.size:g} m cube along the face normals "
        f"({spec.speed:g} m/s ± {100 * spec.speed_jitter:g} %, within {spec.spread:g} rad), "
        f"one lecture-update step per frame at {1 / spec.frame_dt:.0f} frames/s under "
        f"g = {g:g} m/s² along −y; drawn at the first frame with at least {FOUNTAIN_TARGET} "
        f"particles alive ({live.sum()} at frame {s}). Colour goes from yellow at birth to red "
        f"at death; opacity falls with age and with height (e-folding {spec.fade_height:g} m); "
        "each particle is an ellipse stretched along its velocity: the lecture's particle "
        "attributes, drawn as point light sources. Right: the population against its "
        f"expectation, which it follows to {100 * off:.1f} % once the first particles expire."
    )


def _strand_segments(st: Strands) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Segments (k, 2, 3) of all strands, their thickness (k,) in m and life fraction (k,)."""
    idx = st.strand_index()
    a = np.flatnonzero(idx[1:] == idx[:-1])
    seg = np.stack([st.points[a], st.points[a + 1]], axis=1)
    thick = 0.5 * (st.thickness[a] + st.thickness[a + 1])
    born = st.times[st.start[:-1]][idx[a]]
    died = st.times[st.start[1:] - 1][idx[a]]
    frac = (st.times[a] - born) / np.maximum(died - born, 1e-12)
    return seg, thick, frac


def _draw_strands(ax: plt.Axes, seg: np.ndarray, thick: np.ndarray, colours: np.ndarray) -> None:
    """Strand segments in x-y with their thickness in metres turned into points on this axes."""
    fig = cast(plt.Figure, ax.figure)
    ax.apply_aspect()
    width_in = ax.get_position().width * fig.get_figwidth()
    pt_per_m = width_in * 72 / np.ptp(ax.get_xlim())
    ax.add_collection(
        LineCollection(
            seg[:, :, :2],  # type: ignore[arg-type]  # stubs: segments as a sequence, not an array
            linewidths=thick * pt_per_m,
            colors=colours,
            alpha=0.6,
            capstyle="butt",
        )
    )


def fig_strands(path: Path, fountain: Fountain) -> str:
    """The fountain's first particles drawn over their whole lives as strands."""
    f, spec = fountain, fountain.spec
    first = (f.born >= 0) & (f.born < STRAND_FRAMES)
    alive = f.alive & first[None, :]
    root = 2 * spec.particle_size
    sub = collect_strands(f.t, f.x, f.v, alive, root_thickness=root, taper=STRAND_TAPER)
    seg, thick, frac = _strand_segments(sub)
    cmap = mcolors.LinearSegmentedColormap.from_list("life", [spec.color_birth, spec.color_death])
    colours = cmap(frac)
    zoom = ((0.6, 1.8), (-1.1, 0.1))
    fig = plt.figure(figsize=(14, 6.4))
    grid = fig.add_gridspec(1, 2, width_ratios=[1, 1.1])
    ax = fig.add_subplot(grid[0])
    _night(ax)
    _draw_strands(ax, seg, thick, colours)
    _emitter_outline(ax, spec)
    (zx0, zx1), (zy0, zy1) = zoom
    ax.plot(
        [zx0, zx1, zx1, zx0, zx0], [zy0, zy0, zy1, zy1, zy0], color="white", linewidth=0.8, linestyle="--"
    )
    ax.set_title(
        f"{len(sub)} strands: every particle born in the first {STRAND_FRAMES} frames,\n"
        "its whole life drawn at once",
        fontsize=10,
    )
    ax = fig.add_subplot(grid[1])
    _night(ax, zoom)
    margin = 0.5  # m, longer than any segment (one frame's travel), so none is cut off
    inside = np.any(
        (seg[:, :, 0] > zx0 - margin)
        & (seg[:, :, 0] < zx1 + margin)
        & (seg[:, :, 1] > zy0 - margin)
        & (seg[:, :, 1] < zy1 + margin),
        axis=1,
    )
    _draw_strands(ax, seg[inside], thick[inside], colours[inside])
    _emitter_outline(ax, spec)
    ax.set_title(
        f"Zoom on the dashed box, thickness to scale: {1000 * root:.0f} mm at the root "
        f"(twice the particle size),\ntapering to {100 * (1 - STRAND_TAPER):.0f} % of it "
        "at the tip",
        fontsize=10,
    )
    sm = plt.cm.ScalarMappable(norm=mcolors.Normalize(0, 1), cmap=cmap)
    fig.colorbar(sm, ax=ax, fraction=0.04, pad=0.02, label="fraction of the particle's life")
    fig.tight_layout()
    save_figure(fig, path)
    lengths = sub.lengths()
    return (
        'Reproduces the lecture slide "The same cube emitter rendered using static particles, '
        'or strands" (Snowflakes vs Hair): the emitter and forces of the fountain figure, but '
        f"each of the {len(sub)} particles born in its first {STRAND_FRAMES} frames drawn over "
        "its whole life at once, as a polyline through its positions frame by frame "
        f"(truestep.reference_impl.strands), {lengths.min():.1f} to {lengths.max():.1f} m long. "
        f"Each strand is {1000 * root:.0f} mm thick at the root (twice the emitter's particle "
        f"size), tapering linearly along the strand to {100 * (1 - STRAND_TAPER):.0f} %; colour "
        "runs from birth to death as in the fountain."
    )
