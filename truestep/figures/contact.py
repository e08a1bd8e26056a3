"""The lecture's figures on collisions and contact: bouncing off the walls, sliding along one.

Scenes: ``cases/figures/particle-in-a-box.toml`` and ``inclined-wall-drop.toml``, run by
the reference adapter (:mod:`truestep.figures.scenes`). Bounces are found by the harness's
own detector, :func:`truestep.measures.restitution.bounces`. Each ``fig_*`` function draws one
figure into the PNG ``path`` and returns its caption.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, cast

import matplotlib.pyplot as plt
import numpy as np

from truestep.adapters.base import Trajectory
from truestep.cases.case import Case
from truestep.figures.scenes import figure_case, run_reference
from truestep.figures.style import SCENE_COLOURS, exact_style, legend_below, save_figure
from truestep.measures.restitution import CONTACT_BAND, Bounce, bounces, heights
from truestep.reference_impl.collisions import EPS_DISTANCE, EPS_SPEED

BOX_RESTITUTIONS = (1.0, 0.75, 0.5)
"""Coefficients of restitution k_r of the bouncing figure's three runs (variants of its case)."""


@dataclass
class PlaneBounce:
    """One bounce of a particle off a plane: the plane's index in the case, the shared
    detector's :class:`~truestep.measures.restitution.Bounce`, and the velocity (3,) m/s at the
    sample before the contact (the one the detector's ``v_in`` is read at)."""

    plane: int
    bounce: Bounce
    v_before: np.ndarray


def floor_bounces(case: Case, traj: Trajectory) -> list[PlaneBounce]:
    """Bounces of particle 0 off every plane that gravity pulls it toward or along (the
    floor and the side walls), in time order, by :func:`truestep.measures.restitution.bounces`;
    a ceiling (gravity away from it) is not measured."""
    m = case.particles
    out = []
    for k, plane in enumerate(m.planes):
        g_n = float(-(m.gravity @ plane.normal))
        if g_n < -1e-12:
            continue
        g_n = max(g_n, 0.0)
        h, vn = heights(
            traj.x[:, 0], cast(np.ndarray, traj.v)[:, 0], plane.point, plane.normal, float(m.radius[0])
        )
        for b in bounces(traj.t, h, vn, g_n):
            out.append(PlaneBounce(k, b, cast(np.ndarray, traj.v)[int(np.searchsorted(traj.t, b.t)), 0]))
    return sorted(out, key=lambda pb: pb.bounce.t)


def with_restitution(case: Case, e: float) -> Case:
    """The case with every plane's coefficient of restitution set to ``e``."""
    planes = [replace(p, restitution=e) for p in case.particles.planes]
    return replace(case, scene=replace(case.particles, planes=planes))


def _box_outline(case: Case) -> tuple[np.ndarray, np.ndarray]:
    """Corners (2,) x and (2,) y of the box the case's planes bound in the x-y plane, m."""
    lo, hi = np.full(3, -np.inf), np.full(3, np.inf)
    for p in case.particles.planes:
        axis = int(np.argmax(np.abs(p.normal)))
        if p.normal[axis] > 0:
            lo[axis] = p.point[axis]
        else:
            hi[axis] = p.point[axis]
    return np.array([lo[0], hi[0]]), np.array([lo[1], hi[1]])


def _collision_diagram(ax: plt.Axes, vb: np.ndarray, v_out: float, n: np.ndarray, e: float) -> None:
    """V before (3,), V_N, V_T and V' of one collision with the plane of normal ``n``."""
    t_dir = vb - (vb @ n) * n
    t_dir /= np.linalg.norm(t_dir)
    b_t, b_n = vb @ t_dir, vb @ n  # before: along the wall (> 0) and along N (< 0)
    a_t, a_n = b_t, v_out  # after: the response keeps V_T
    arrow: dict[str, Any] = {"angles": "xy", "scale_units": "xy", "scale": 1.0, "width": 0.01}
    c_v, c_n, c_t, c_after = "black", SCENE_COLOURS[2], SCENE_COLOURS[3], SCENE_COLOURS[1]
    ax.quiver(-b_t, -b_n, b_t, b_n, color=c_v, **arrow)
    ax.quiver(-b_t, -b_n, b_t, 0, color=c_t, **arrow)
    ax.quiver(0, -b_n, 0, b_n, color=c_n, **arrow)
    ax.quiver(0, 0, a_t, a_n, color=c_after, **arrow)
    ax.quiver(0, 0, a_t, 0, color=c_t, **arrow)
    ax.quiver(a_t, 0, 0, a_n, color=c_n, **arrow)
    ax.fill_between([-1.35 * b_t, 1.35 * a_t + 2.4], -0.6, -0.04, color="0.85", zorder=0)
    ax.axhline(-0.04, color="black", linewidth=1.2, zorder=0)
    ax.annotate("wall", (1.35 * a_t + 2.3, -0.45), fontsize=9, ha="right", color="0.3")
    ax.quiver(-1.1 * b_t, 0, 0, 0.8, color="black", width=0.006, angles="xy", scale_units="xy", scale=1.0)
    ax.annotate("N", (-1.1 * b_t + 0.06, 0.55), fontsize=10)
    ax.annotate("V (before)", (-0.5 * b_t - 0.12, -0.5 * b_n), fontsize=10, ha="right")
    ax.annotate("V_T = V − V_N", (-0.5 * b_t, -b_n + 0.15), fontsize=10, color=c_t, ha="center")
    ax.annotate(f"V_N = (N·V) N,\n|V_N| = {-b_n:.2f} m/s", (0.1, -0.88 * b_n), fontsize=10, color=c_n)
    ax.annotate("V' = V_T − k_r V_N (after)", (a_t + 0.1, a_n + 0.2), fontsize=10, color=c_after)
    ax.annotate(f"−k_r V_N,\n|k_r V_N| = {a_n:.2f} m/s", (a_t + 0.1, 0.45 * a_n), fontsize=10, color=c_n)
    ax.annotate("V_T", (0.5 * a_t, 0.12), fontsize=10, color=c_t, ha="center")
    ax.set_xlim(-1.35 * b_t, 1.35 * a_t + 2.4)
    ax.set_ylim(-0.6, -b_n + 0.6)
    ax.set_aspect("equal")
    ax.set_xlabel("velocity along the wall (m/s)")
    ax.set_ylabel("velocity along N (m/s)")
    ax.set_title(
        f"The first floor collision at k_r = {e:g}, velocities from the run:\n"
        f"{-b_n:.2f} m/s in along N, {a_n:.2f} m/s out (ratio {a_n / -b_n:.3f})",
        fontsize=10,
    )


# -- 11. bouncing off the walls ---------------------------------------------------------------------
def fig_bounce(path: Path) -> str:
    """A particle bouncing in a box for three restitutions; one collision taken apart."""
    base = figure_case("particle-in-a-box")
    dt = base.dts[0]
    x0 = base.particles.x0[0]
    fig, axes = plt.subplots(1, 3, figsize=(15, 5.6), gridspec_kw={"width_ratios": [1, 1.1, 1]})
    measured, diagram = [], None
    for k, e in enumerate(BOX_RESTITUTIONS):
        case = with_restitution(base, e)
        traj = run_reference(case, "lecture")
        axes[0].plot(
            traj.x[:, 0, 0], traj.x[:, 0, 1], color=SCENE_COLOURS[k], linewidth=1.5, label=f"k_r = {e:g}"
        )
        found = floor_bounces(case, traj)
        measured += [(k, pb.bounce) for pb in found if pb.bounce.v_out > 0]
        floors = [
            pb for pb in found if -(case.particles.gravity @ case.particles.planes[pb.plane].normal) > 0
        ]
        if diagram is None and e < 1 and floors:
            pb = floors[0]
            diagram = (pb.v_before, pb.bounce.v_out, case.particles.planes[pb.plane].normal, e)
    if diagram is None:
        raise RuntimeError(f"{base.name}: no floor bounce to draw")
    ax = axes[0]
    bx, by = _box_outline(base)
    ax.plot(*x0[:2], "o", color="black", markersize=5, label="start")
    ax.plot(bx[[0, 1, 1, 0, 0]], by[[0, 0, 1, 1, 0]], color="black", linewidth=2)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m, up)")
    ax.set_title(
        f"A particle in a {bx[1] - bx[0]:g} m box under gravity, {base.duration:g} s\n"
        f"(lecture update, dt = {1000 * dt:g} ms)",
        fontsize=10,
    )
    legend_below(ax, ncol=4)

    _collision_diagram(axes[1], *diagram)

    ax = axes[2]
    v_in = np.array([b.v_in for _, b in measured])
    v_out = np.array([b.v_out for _, b in measured])
    k_of = np.array([k for k, _ in measured])
    top = 1.1 * v_in.max()
    for k, e in enumerate(BOX_RESTITUTIONS):
        sel = k_of == k
        ax.plot(
            v_in[sel],
            v_out[sel],
            "o",
            color=SCENE_COLOURS[k],
            markersize=6,
            label=f"measured, k_r = {e:g} ({sel.sum()} bounces)",
        )
        ax.plot([0, top], [0, e * top], color=SCENE_COLOURS[k], linewidth=0.9, linestyle=":")
    ax.plot([], [], color="0.3", linewidth=0.9, linestyle=":", label="|V'_N| = k_r |V_N| (the lecture)")
    worst = np.max(np.abs(v_out - np.array(BOX_RESTITUTIONS)[k_of] * v_in))
    ax.set_xlabel("normal speed before, −N·V (m/s)")
    ax.set_ylabel("normal speed after, N·V' (m/s)")
    ax.set_title(
        f"Every bounce off floor and walls, three runs:\nrebound within {worst:.3f} "
        "m/s of k_r x impact speed",
        fontsize=10,
    )
    ax.set_xlim(0, top)
    ax.set_ylim(0, top)
    ax.set_aspect("equal")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper left", fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    save_figure(fig, path)
    planes = len(base.particles.planes)
    g = float(np.linalg.norm(base.particles.gravity))
    restitutions = ", ".join(f"{e:g}" for e in BOX_RESTITUTIONS[:-1]) + f" and {BOX_RESTITUTIONS[-1]:g}"
    return (
        'Reproduces the lecture slides "Bouncing off the Walls", "Normal and Tangential '
        'Components", "Collision Detection" and "Collision Response" (coefficient of '
        f"restitution): a point particle in a {bx[1] - bx[0]:g} m box of {planes} planes under "
        f"gravity, for k_r = {restitutions}, stepped by the lecture's update at "
        f"{1000 * dt:g} ms with the reference collision pass between steps. Middle: one "
        "floor collision's V, V_N, V_T and V' = V_T − k_r V_N, taken from the run (the records "
        "either side of the contact); right: the normal speed after against before for "
        f"every bounce off the floor and the side walls ({len(measured)}, found by the "
        "harness's bounce detector, "
        "truestep.measures.restitution, from the records before and after each contact, which lasts "
        f"while the particle is within {1000 * CONTACT_BAND:g} mm of the floor), on the lines "
        f"of slope k_r: every rebound speed is within {worst:.3f} m/s of k_r times the impact "
        f"speed (gravity changes the speed by g dt = {g * dt:.3f} m/s per step)."
    )


# -- 12. contact: a particle moving along the wall ------------------------------------------------
def contact_start(d: np.ndarray, vn: np.ndarray) -> int | None:
    """First record from which the particle stays on the wall and moves along it to the
    end, within the collision pass's epsilons: ``|d| < EPS_DISTANCE`` and ``|N·V| <
    EPS_SPEED``; ``None`` if it is not in contact at the end. ``d``, ``vn`` : (T,), m, m/s."""
    on = (np.abs(d) < EPS_DISTANCE) & (np.abs(vn) < EPS_SPEED)
    if not on[-1]:
        return None
    off = np.flatnonzero(~on)
    return int(off[-1] + 1) if len(off) else 0


def fig_contact(path: Path) -> str:
    """A particle dropped onto an inclined wall: bounces, then contact and sliding."""
    case = figure_case("inclined-wall-drop")
    m = case.particles
    (plane,) = m.planes
    normal = plane.normal
    gravity = m.gravity
    g = float(np.linalg.norm(gravity))
    down = gravity - (gravity @ normal) * normal
    down /= np.linalg.norm(down)
    angle = float(np.arccos(-(gravity @ normal) / g))
    dt = case.dts[0]
    traj = run_reference(case, "lecture")
    t, x, v = traj.t, traj.x[:, 0], cast(np.ndarray, traj.v)[:, 0]
    d, vn = heights(x, v, plane.point, normal, float(m.radius[0]))
    s_down = (x - x[0]) @ down
    drop = float(d[0])
    first = contact_start(d, vn)
    if first is None:
        raise RuntimeError(f"{case.name}: the particle is not in contact at the end of the run")
    g_t = g * np.sin(angle)
    exact = 0.5 * g_t * t**2
    hops = [b for b in bounces(t, d, vn, g * np.cos(angle)) if b.v_out > 0]

    fig = plt.figure(figsize=(15, 5.6))
    grid = fig.add_gridspec(
        2, 3, width_ratios=[1.5, 1, 1], hspace=0.08, wspace=0.3, left=0.05, right=0.98, bottom=0.1, top=0.88
    )
    ax = fig.add_subplot(grid[:, 0])
    along = x @ down
    span = np.array([-0.3, along[-1] + 0.3])
    ax.fill(
        [span[0] * down[0], span[1] * down[0], span[0] * down[0]],
        [span[0] * down[1], span[1] * down[1], span[1] * down[1]],
        color="0.88",
        zorder=0,
    )
    ax.plot(span * down[0], span * down[1], color="black", linewidth=1.5)
    ax.plot(
        x[: first + 1, 0],
        x[: first + 1, 1],
        color=SCENE_COLOURS[0],
        linewidth=1.4,
        label=f"bouncing: collision response, k_r = {plane.restitution:g}",
    )
    ax.plot(
        x[first:, 0],
        x[first:, 1],
        color=SCENE_COLOURS[1],
        linewidth=4.0,
        alpha=0.8,
        label=f"in contact from t = {t[first]:.2f} s: sliding along the wall",
    )
    f = m.mass[0] * gravity
    fn = (f @ normal) * normal
    sc = 0.04
    lo_x, hi_x = span[1] * down[0] - 0.05, span[0] * down[0] + 0.05
    q = np.array([lo_x + 0.3 * (hi_x - lo_x), 0.4, 0.0])  # free space above the wall
    ax.plot(
        *np.stack([q - 0.3 * down, q + 0.3 * down])[:, :2].T, color="black", linewidth=0.8, linestyle="--"
    )
    arrow: dict[str, Any] = {"angles": "xy", "scale_units": "xy", "scale": 1.0, "width": 0.007, "zorder": 5}
    ax.quiver(*q[:2], *(sc * f[:2]), color="black", **arrow)
    ax.quiver(*q[:2], *(sc * fn[:2]), color=SCENE_COLOURS[2], **arrow)
    ax.quiver(*q[:2], *(sc * (f - fn)[:2]), color=SCENE_COLOURS[3], **arrow)
    ax.plot(*q[:2], "o", color=SCENE_COLOURS[1], markersize=7, zorder=6)
    ax.annotate("F = m g", q[:2] + sc * f[:2] + np.array([-0.03, -0.02]), fontsize=10, ha="right")
    ax.annotate(
        "F_N: the wall cancels it",
        q[:2] + sc * fn[:2] + np.array([0.04, -0.02]),
        fontsize=10,
        color=SCENE_COLOURS[2],
    )
    ax.annotate(
        "F' = F_T",
        q[:2] + sc * (f - fn)[:2] + np.array([-0.04, 0.03]),
        fontsize=10,
        color=SCENE_COLOURS[3],
        ha="right",
    )
    ax.annotate(
        "forces on the particle in contact\n(dashed: parallel to the wall)",
        q[:2] + np.array([0.0, 0.1]),
        fontsize=9,
        ha="center",
    )
    ax.set_xlim(lo_x, hi_x)
    ax.set_ylim(span[1] * down[1] - 0.05, 0.75)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m, up)")
    ax.set_title(
        f"A point dropped {drop:g} m onto a frictionless {np.degrees(angle):.0f}° wall\n"
        f"(force arrows for m = {m.mass[0]:g} kg, {sc:g} m per N)",
        fontsize=10,
    )
    ax.legend(loc="lower right", fontsize=8, frameon=False)

    ax_d = fig.add_subplot(grid[0, 1])
    ax_v = fig.add_subplot(grid[1, 1], sharex=ax_d)
    ax_d.plot(t, 1000 * d, color=SCENE_COLOURS[0], linewidth=1.3)
    ax_v.plot(t, vn, color=SCENE_COLOURS[2], linewidth=1.3)
    for a_ in (ax_d, ax_v):
        a_.axvspan(t[first], t[-1], color=SCENE_COLOURS[1], alpha=0.15)
        a_.axhline(0.0, color="0.5", linewidth=0.6)
        a_.grid(True, alpha=0.3)
    ax_d.text(
        t[first] + 0.02, 0.85 * 1000 * d.max(), "contact:\n(X − P)·N = 0\nN·V = 0", fontsize=9, va="top"
    )
    ax_d.set_ylabel("(X − P)·N (mm)")
    ax_v.set_ylabel("N·V (m/s)")
    ax_v.set_xlabel("time (s)")
    ax_d.tick_params(labelbottom=False)
    ax_d.set_title("On the wall, moving along the wall", fontsize=10)

    ax = fig.add_subplot(grid[:, 2])
    ax.plot(t, exact, label="exact: ½ g sin θ t²", **exact_style())
    ax.plot(t, s_down, color=SCENE_COLOURS[1], linewidth=1.8, label="reference run")
    err = np.max(np.abs(s_down - exact))
    ax.axvspan(t[first], t[-1], color=SCENE_COLOURS[1], alpha=0.15)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("distance down the slope (m)")
    ax.set_title(
        f"Along the wall: a = g sin θ = {g_t:.2f} m/s² throughout\n"
        f"(largest deviation from exact {err:.0e} m)",
        fontsize=10,
    )
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper left", fontsize=8, frameon=False)
    save_figure(fig, path)
    ratios = [b.e_velocity for b in hops]
    return (
        'Reproduces the lecture slides "Conditions for Contact" and "Contact Force" '
        "(F' = F_T: the wall pushes back, cancelling the normal component of F): a point "
        f"mass dropped {drop:g} m onto a frictionless plane inclined at "
        f"{np.degrees(angle):.0f}° (k_r = {plane.restitution:g}), stepped by the lecture's "
        f"update at {1000 * dt:g} ms. Its bounces shrink (the harness's bounce detector finds "
        f"{len(hops)} that rise above its {1000 * CONTACT_BAND:g} mm contact band, rebounding "
        f"at {min(ratios):.2f} to {max(ratios):.2f} times the impact speed) until, at "
        f"t = {t[first]:.2f} s, it is on the wall, moving along it and "
        "pushing against it; the reference contact pass then holds its normal distance and "
        "velocity at zero to the end and the force becomes F_T, so it slides with "
        f"a = g sin θ. Neither the collisions nor the contact touch the tangential motion, "
        f"which follows ½ g sin θ t² throughout (to {err:.0e} m)."
    )
