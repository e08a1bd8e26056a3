"""The lecture's figures on mass-spring meshes: the triangle step by step, the cube that
turns inside out.

Scenes: ``cases/figures/triangle-push.toml``, ``pushed-cube-edges.toml`` and
``pushed-cube-braced.toml``, run by the reference adapter (:mod:`truestep.figures.scenes`).
Each ``fig_*`` function draws one figure into the PNG ``path`` and returns its caption.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, cast

import matplotlib.colors as mcolors
import matplotlib.pyplot as plt
import numpy as np
from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

from truestep.cases.case import Case
from truestep.figures.scenes import figure_case, run_reference
from truestep.figures.style import SCENE_COLOURS, save_figure
from truestep.reference_impl import forces
from truestep.reference_impl.meshes import signed_volume

if TYPE_CHECKING:
    from mpl_toolkits.mplot3d import Axes3D

CUBE_CASES = {"edges": "pushed-cube-edges", "volume": "pushed-cube-braced"}
"""The cube figure's case for each bracing of :func:`truestep.reference_impl.meshes.cube`."""


# -- 7. the triangle, step by step ---------------------------------------------------------------
def fig_triangle(path: Path) -> str:
    """The triangle of springs, a force on V2 for one step, then step by step."""
    case = figure_case("triangle-push")
    model, springs = case.particles, case.particles.springs
    dt = case.dts[0]
    traj = run_reference(case, "lecture")
    x, v = traj.x, cast(np.ndarray, traj.v)
    n_show = len(traj.t)
    ((pushed, force, _, _),) = model.impulses
    fig, axes = plt.subplots(2, n_show // 2, figsize=(13, 7.0), sharex=True, sharey=True)
    ext_scale, spring_scale = 0.008, 0.03  # m of arrow per N
    ext_colour, spring_colour = "black", SCENE_COLOURS[4]
    strain_norm = mcolors.TwoSlopeNorm(vcenter=0.0, vmin=-0.08, vmax=0.08)
    cmap = plt.get_cmap("PuOr_r")
    moved = np.linalg.norm(x - x[0], axis=2) * 1000  # mm
    a2 = force[0] / model.mass[pushed]
    others = [i for i in range(model.n) if i != pushed]
    first_moved = min(int(np.argmax(moved[:, i] > 0)) for i in others)
    notes = {
        0: "F acts on V2 for this one step",
        1: f"V2 moved ½ a2 Δt² = {moved[1, pushed]:.0f} mm",
        2: "E12, E23 act on V1, V2, V3",
    }
    rest_tri = np.vstack([model.x0[:, :2], model.x0[:1, :2]])
    for s, ax in enumerate(axes.ravel()):
        ax.plot(rest_tri[:, 0], rest_tri[:, 1], color="0.7", linewidth=1.0, linestyle="--")
        for e, (i, j) in enumerate(zip(springs.i, springs.j, strict=True)):
            strain = (np.linalg.norm(x[s, i] - x[s, j]) - springs.rest[e]) / springs.rest[e]
            ax.plot(
                x[s, [i, j], 0],
                x[s, [i, j], 1],
                color=cmap(strain_norm(strain)),
                linewidth=3.5,
                solid_capstyle="round",
            )
        ax.plot(x[s, :, 0], x[s, :, 1], "o", color="black", markersize=5, zorder=4)
        f_spring = np.zeros((model.n, 3))
        forces.add_springs(f_spring, x[s], v[s], springs)
        t = traj.t[s]
        for i in range(model.n):
            if np.linalg.norm(f_spring[i]) > 1e-9:
                ax.annotate(
                    "",
                    xy=x[s, i, :2] + spring_scale * f_spring[i, :2],
                    xytext=x[s, i, :2],
                    arrowprops={"arrowstyle": "-|>", "color": spring_colour, "lw": 2.0},
                )
        for i, f_ext, t_on, t_off in model.impulses:
            if t_on <= t < t_off:
                ax.annotate(
                    "",
                    xy=x[s, i, :2] + ext_scale * f_ext[:2],
                    xytext=x[s, i, :2],
                    arrowprops={"arrowstyle": "-|>", "color": ext_colour, "lw": 2.4},
                )
                ax.annotate(
                    "F",
                    x[s, i, :2] + ext_scale * f_ext[:2] + np.array([0.03, 0.0]),
                    color=ext_colour,
                    fontsize=11,
                )
        for i, name in enumerate(("V1", "V2", "V3")):
            offset = {0: (-0.16, -0.1), 1: (-0.06, 0.08), 2: (0.05, -0.1)}[i]
            ax.annotate(name, x[s, i, :2] + np.array(offset), fontsize=9)
        note = notes.get(s, f"V1 moved {moved[s, 0]:.0f} mm, V3 {moved[s, 2]:.0f} mm")
        ax.set_title(f"after {s} step{'' if s == 1 else 's'} (t = {t:.2f} s)\n{note}", fontsize=9)
        ax.set_aspect("equal")
        ax.set_xlim(-0.75, 0.95)
        ax.set_ylim(-0.6, 0.85)
    for ax in axes[1]:
        ax.set_xlabel("x (m)")
    for ax in axes[:, 0]:
        ax.set_ylabel("y (m)")
    handles = [
        plt.Line2D(
            [],
            [],
            color=ext_colour,
            lw=2.4,
            label=f"external force F = {force[0]:g} N on V2, first step only ({ext_scale * 1000:g} mm per N)",
        ),
        plt.Line2D(
            [],
            [],
            color=spring_colour,
            lw=2.0,
            label=f"spring forces acting in the next step ({spring_scale * 1000:g} mm per N)",
        ),
        plt.Line2D([], [], color="0.7", lw=1.0, ls="--", label="rest shape"),
    ]
    fig.legend(handles=handles, loc="lower center", ncol=3, fontsize=9, frameon=False)
    sm = plt.cm.ScalarMappable(norm=strain_norm, cmap=cmap)
    fig.tight_layout(rect=(0, 0.05, 0.9, 1))
    cax = fig.add_axes((0.915, 0.2, 0.012, 0.6))
    fig.colorbar(sm, cax=cax, label="edge strain (L − L_r) / L_r")
    save_figure(fig, path)
    side = float(np.linalg.norm(model.x0[1] - model.x0[0]))
    return (
        'Reproduces the lecture slides "A simple example" (7.2 Spring Animation Examples): an '
        f"equilateral triangle of {side:g} m sides, {model.mass[0]:g} kg per vertex and edge "
        f"springs of {springs.stiffness[0]:g} N/m, stepped by the lecture's update (v' = v + a Δt, "
        f"p' = p + (v + v') Δt / 2) with Δt = {dt:g} s. A force of {force[0]:g} N pushes V2 "
        f"for the first step only (a2 = F / m2 = {a2:g} m/s²); after it V2 moves at "
        f"{v[1, pushed, 0]:g} m/s = a2 Δt and has moved ½ a2 Δt² = {moved[1, pushed]:.0f} mm, "
        "and edges E12 and E23 are strained; their springs carry the disturbance on to V1 and "
        f"V3, which first move in step {first_moved}, one step at a time. Edge colour: strain; "
        "arrows: the forces acting during the next step."
    )


# -- 8. the cube: edge springs alone against face and volume springs -----------------------------
@dataclass
class CubeRun:
    """A pinned-base cube pushed sideways: its case, times (T,) s, positions (T, 8, 3) m and
    the signed volume (T,) m^3 of its surface."""

    case: Case
    t: np.ndarray
    x: np.ndarray
    volume: np.ndarray


def simulate_cube(bracing: str) -> CubeRun:
    """The cube figure's scene of ``bracing`` (``"edges"`` or ``"volume"``), run by the
    reference adapter with velocity Verlet at its case's step (:data:`CUBE_CASES`)."""
    case = figure_case(CUBE_CASES[bracing])
    traj = run_reference(case, "verlet")
    return CubeRun(case, traj.t, traj.x, signed_volume(traj.x, case.particles.surfaces[0]))


def _spring_kinds(case: Case) -> np.ndarray:
    """0 for an edge, 1 for a face diagonal, 2 for a body diagonal of a cube, shape (m,):
    from the rest lengths, in the ratios 1, sqrt(2), sqrt(3)."""
    rest = case.particles.springs.rest
    return np.rint((rest / rest.min()) ** 2).astype(int) - 1


def _up(x: np.ndarray) -> np.ndarray:
    """Scene coordinates (..., 3) in matplotlib's 3-D order: x, z, then y (up) as the vertical."""
    return x[..., [0, 2, 1]]


def _draw_cube(ax: Axes3D, case: Case, x: np.ndarray, colour: str) -> None:
    """The cube of ``case`` at positions ``x`` (8, 3): faces, springs by kind, pinned
    vertices as squares, the push as arrows."""
    m, p = case.particles, _up(x)
    ax.add_collection3d(Poly3DCollection(p[m.surfaces[0]], facecolor=colour, alpha=0.2, edgecolor="none"))
    pairs, kinds = np.stack([m.springs.i, m.springs.j], axis=1), _spring_kinds(case)
    styles = {0: ("black", 2.0), 1: ("0.4", 0.8), 2: ("0.55", 0.8)}
    for kind, (col, lw) in styles.items():
        sel = pairs[kinds == kind]
        if len(sel):
            ax.add_collection3d(Line3DCollection(p[sel], colors=col, linewidths=lw))
    ax.scatter(*p.T, color="black", s=10, depthshade=False)
    ax.scatter(*p[m.fixed].T, color="black", marker="s", s=28, depthshade=False)
    top = p[[i for i, _, _, _ in m.impulses]]
    push = np.array([f for _, f, _, _ in m.impulses])
    arrow = _up(push) / np.linalg.norm(push, axis=1)[:, None] * 0.35
    ax.quiver(*top.T, *arrow.T, color=SCENE_COLOURS[4], linewidth=1.5, arrow_length_ratio=0.3)
    ax.set_xlim(-0.6, 1.4)
    ax.set_ylim(-0.7, 0.7)
    ax.set_zlim(-0.9, 1.1)
    ax.set_box_aspect((2.0, 1.4, 2.0))
    ax.view_init(elev=20, azim=-60)
    ax.set_xlabel("x (m)", fontsize=7, labelpad=-8)
    ax.set_ylabel("z (m)", fontsize=7, labelpad=-8)
    ax.set_zlabel("y (m, up)", fontsize=7, labelpad=-8)
    ax.set_xticks([-0.5, 0.0, 0.5, 1.0])
    ax.set_yticks([-0.5, 0.0, 0.5])
    ax.set_zticks([-0.5, 0.0, 0.5, 1.0])
    ax.tick_params(labelsize=6, pad=-3)


def fig_cube(path: Path) -> str:
    """Edge-sprung against fully braced cube under the same push: snapshots and volume."""
    runs = {key: simulate_cube(key) for key in CUBE_CASES}
    labels = {
        key: f"{label} ({len(r.case.particles.springs)})"
        for (key, r), label in zip(
            runs.items(), ("edge springs only", "edge, face and volume springs"), strict=True
        )
    }
    colours = {"edges": SCENE_COLOURS[0], "volume": SCENE_COLOURS[1]}
    v_edges = runs["edges"].volume
    t = runs["edges"].t
    folded = bool(np.any(v_edges <= 0))
    flat = int(np.argmax(v_edges <= 0)) if folded else int(np.argmin(v_edges))
    times = (0.0, float(t[flat]), float(t[-1]))
    fig = plt.figure(figsize=(14, 7.6))
    grid = fig.add_gridspec(
        2,
        4,
        width_ratios=[1, 1, 1, 1.25],
        left=0.03,
        right=0.98,
        top=0.9,
        bottom=0.2,
        hspace=0.25,
        wspace=0.25,
    )
    for row, key in enumerate(runs):
        r = runs[key]
        for col, when in enumerate(times):
            ax = fig.add_subplot(grid[row, col], projection="3d")
            s = int(np.argmin(np.abs(r.t - when)))
            _draw_cube(ax, r.case, r.x[s], colours[key])
            volume = np.round(r.volume[s], 2) + 0.0  # no "-0.00"
            ax.set_title(f"t = {r.t[s]:.2f} s, volume {volume:+.2f} m³", fontsize=9, pad=0)
        fig.text(
            0.01,
            0.73 - 0.36 * row,
            labels[key],
            rotation=90,
            va="center",
            fontsize=11,
            color=colours[key],
            weight="bold",
        )
    ax = fig.add_subplot(grid[:, 3])
    for key, r in runs.items():
        ax.plot(r.t, r.volume, color=colours[key], linewidth=1.8, label=labels[key])
    for when in times:
        ax.axvline(when, color="0.6", linewidth=0.8, linestyle=":")
    ax.axhline(0.0, color="0.5", linewidth=0.8)
    ax.text(t[-1], 0.03, "flat", ha="right", fontsize=8, color="0.4")
    ax.text(t[-1], -0.1, "inside out", ha="right", fontsize=8, color="0.4")
    ax.set_xlabel("time (s); dotted: the snapshots")
    ax.set_ylabel("signed volume (m³)")
    ax.set_title("Signed volume of the cube's surface")
    ax.grid(True, alpha=0.3)
    case = runs["edges"].case
    m = case.particles
    push = float(np.linalg.norm(m.impulses[0][1]))
    handles = [
        *ax.get_legend_handles_labels()[0],
        plt.Line2D([], [], color=SCENE_COLOURS[4], lw=1.5, label=f"push: {push:.0f} N on each top vertex"),
        plt.Line2D([], [], color="black", marker="s", ls="none", label="pinned vertices"),
    ]
    ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.09), fontsize=8, frameon=False)
    fig.suptitle(
        "A cube of springs pushed sideways: edge springs alone "
        + ("let it turn inside out" if folded else "keep it right side out"),
        fontsize=12,
    )
    save_figure(fig, path)
    direction = m.impulses[0][1] / np.abs(m.impulses[0][1]).max()
    side = float(np.cbrt(v_edges[0]))
    end_edges = "ends inside out" if v_edges[-1] < 0 else "ends right side out"
    braced = runs["volume"].volume
    return (
        "Reproduces the lecture slide on the cube that turns inside out (7.2 Spring Animation "
        'Examples: "the cube can turn inside out; additional springs can be added across '
        f"the object's faces and its volume\"): two {side:g} m, {m.mass.sum():g} kg cubes with "
        f"the bottom face pinned (squares) and the top face pushed along "
        f"({', '.join(f'{c:g}' for c in direction)}) by {push:.0f} N per vertex (springs "
        f"{m.springs.stiffness[0]:g} N/m with {m.springs.damping[0]:g} N s/m dampers, drag "
        f"{m.drag:g} N s/m, velocity Verlet at {1000 * case.dts[0]:g} ms). With edge springs "
        "alone nothing resists shear: the cube "
        + (f"folds flat at t = {times[1]:.2f} s" if folded else "never folds flat")
        + f" and {end_edges} (signed volume {v_edges[-1]:+.2f} m³); with face and volume springs it "
        f"keeps {braced[-1]:.2f} m³ of its {braced[0]:.2g} m³ (never less than "
        f"{braced.min():.2f}). Thick lines: edges; thin: face and body diagonals."
    )
