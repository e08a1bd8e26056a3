"""The lecture's figures on ODEs and their solvers: the vector field, Euler's spiral and
instability, the midpoint method.

Scenes: ``cases/figures/integral-curves.toml``, ``circle-field-two-turns.toml`` and
``viscous-decay.toml``, run by the reference adapter (:mod:`truestep.figures.scenes`).
Each ``fig_*`` function draws one figure into the PNG ``path`` and returns its caption.
"""

from __future__ import annotations

from dataclasses import replace
from itertools import pairwise
from pathlib import Path
from typing import Any, cast

import matplotlib.pyplot as plt
import numpy as np

from truestep.cases.case import ode_states
from truestep.cases.exact import EXACT
from truestep.cases.plugins import ode_system
from truestep.figures.scenes import figure_case, run_reference, step_taken
from truestep.figures.style import (
    SCENE_COLOURS,
    exact_style,
    legend_below,
    reference_style,
    save_figure,
)
from truestep.reference_impl.solvers import get_solver
from truestep.reference_impl.system import System
from truestep.style import series_colour

MORE_STARTS = ((0.9, 0.75), (1.6, -0.9))
"""Starting points of the vector-field figure's other integral curves (its case has the first)."""
MIDPOINT_STEPS = (0.3, 0.1)
"""Steps (s) of the midpoint figure's comparison with Euler."""
DIAGRAM_STEP = 1.0
"""Step (s) of the one midpoint step the midpoint figure takes apart."""


class LinearDecay(System):
    """The test equation ``x' = -k x`` (``k`` in 1/s) of the lecture's instability slide.

    Exact: ``x0 e^(-k t)``. Explicit Euler multiplies ``x`` by ``1 - k h`` every step, so
    it diverges, oscillating, once ``k h > 2``. A case file can only name registered
    systems, so the figure runs this equation as a particle under viscous drag
    (``v' = -(b/m) v``, ``cases/figures/viscous-decay.toml``); this plain system is what the
    tests check that scene against.
    """

    def __init__(self, x0: float, k: float) -> None:
        super().__init__(np.array([x0]))
        self.k = k

    def derivative(self, x: np.ndarray, t: float) -> np.ndarray:
        return -self.k * x

    def jacobian(self, x: np.ndarray, t: float) -> np.ndarray:
        return np.array([[-self.k]])


def _radius(traj) -> np.ndarray:
    """Distance from the origin (T,) of a circle-field trajectory's states."""
    return np.linalg.norm(ode_states(traj), axis=1)


def _exact_circle(case, points: int = 400) -> np.ndarray:
    """The case's exact solution over one period, ``points`` states (points, 2)."""
    return ode_states(EXACT[case.exact](case, np.linspace(0.0, 2 * np.pi, points)))


# -- 1. vector field and integral curves ----------------------------------------------------
def fig_vector_field(path: Path) -> str:
    """The circle field as arrows, and integral curves followed by the adaptive solver."""
    case = figure_case("integral-curves")
    field = cast(type[System], ode_system(case.ode_spec.system))(case.ode_spec.y0)
    g = np.linspace(-2.0, 2.0, 15)
    gx, gy = np.meshgrid(g, g)
    pts = np.stack([gx.ravel(), gy.ravel()], axis=1)
    f = np.array([field.derivative(p, 0.0) for p in pts])
    tol = case.tolerances[0]
    starts = [case.ode_spec.y0, *(np.array(s) for s in MORE_STARTS)]
    runs = [run_reference(replace(case, scene=replace(case.ode_spec, y0=s)), "dopri5", tol) for s in starts]
    closure = max(float(np.linalg.norm(ode_states(r)[-1] - s)) for r, s in zip(runs, starts, strict=True))
    drift = max(float(np.max(np.abs(_radius(r) / _radius(r)[0] - 1))) for r in runs)

    fig, axes = plt.subplots(1, 2, figsize=(11, 5.6))
    for ax, grey in zip(axes, ("0.3", "0.7"), strict=True):
        ax.quiver(
            pts[:, 0],
            pts[:, 1],
            f[:, 0],
            f[:, 1],
            color=grey,
            angles="xy",
            scale_units="xy",
            scale=10.0,
            width=0.004,
        )
        ax.set_aspect("equal")
        ax.set_xlim(-2.25, 2.25)
        ax.set_ylim(-2.25, 2.25)
        ax.set_xlabel("x (state, dimensionless)")
        ax.set_ylabel("y (state, dimensionless)")
    axes[0].set_title("Vector Field: x' = f(x) = (−y, x) at every point")
    for k, (r, s) in enumerate(zip(runs, starts, strict=True)):
        y = ode_states(r)
        axes[1].plot(
            y[:, 0],
            y[:, 1],
            markevery=4,
            label=f"integral curve: reference / dopri5, tolerance {tol:g}" if k == 0 else None,
            **reference_style("dopri5", linewidth=2.0),
        )
        axes[1].plot(
            *s,
            "o",
            color=SCENE_COLOURS[0],
            markersize=8,
            zorder=5,
            label="starting point" if k == 0 else None,
        )
    axes[1].annotate(
        "Start Here",
        starts[2],
        xytext=(0.45, -2.05),
        fontsize=10,
        arrowprops={"arrowstyle": "->", "color": "black"},
    )
    axes[1].set_title("Integral Curves: pick any starting point, follow the vectors")
    legend_below(axes[1])
    fig.tight_layout()
    save_figure(fig, path)
    return (
        'Reproduces the lecture slides "Vector Field", "Integral Curves" and "Initial Value '
        "Problems\" (Differential Equation Basics): the field x' = (−y, x) drawn as arrows, "
        f"and the integral curves through {len(starts)} starting points, followed over one "
        f"period ({case.duration:.4g}) by the reference's adaptive Dormand-Prince solver "
        f"(tolerance {tol:g}); each closes into a circle: back within {closure:.0e} of its "
        f"start, its radius kept to {drift:.0e} relative."
    )


# -- 2. Euler's spiral ----------------------------------------------------------------------
def fig_euler_spiral(path: Path) -> str:
    """Explicit Euler's spiral on the circle field for three step sizes, and its radius error."""
    case = figure_case("circle-field-two-turns")
    steps = case.dts
    fig, axes = plt.subplots(1, 2, figsize=(11, 5.4), gridspec_kw={"width_ratios": [1, 1.15]})
    circle = _exact_circle(case)
    axes[0].plot(circle[:, 0], circle[:, 1], label="exact: the unit circle", **exact_style())
    finals, worst, growing = [], 0.0, True
    for k, dt in enumerate(steps):
        traj = run_reference(case, "euler", dt)
        y, r, h = ode_states(traj), _radius(traj), step_taken(case, dt)
        finals.append(r[-1])
        growth = (1 + h * h) ** (np.arange(len(r)) / 2)
        worst = max(worst, float(np.max(np.abs(r / growth - 1))))
        growing &= bool(np.all(np.diff(r) > 0))
        style = reference_style("euler", k, len(steps))
        every = max(1, len(traj.t) // 30)
        axes[0].plot(y[:, 0], y[:, 1], markevery=every, label=f"Euler, h = {dt:g}", **style)
        axes[1].plot(traj.t[1:], r[1:] - 1.0, markevery=every, label=f"Euler, h = {dt:g}", **style)
        axes[1].plot(
            traj.t[1:],
            growth[1:] - 1,
            label=("(1 + h²)^(n/2) − 1: Euler's growth per step, exact" if k == 0 else None),
            **exact_style(),
        )
    turns = case.duration / (2 * np.pi)
    axes[0].set_aspect("equal")
    axes[0].set_xlabel("x (dimensionless)")
    axes[0].set_ylabel("y (dimensionless)")
    axes[0].set_title(f"{turns:.2f} turns of x' = (-y, x) from (1, 0)")
    legend_below(axes[0])
    axes[1].set_yscale("log")
    axes[1].set_xlabel(f"time t ({case.duration:g}: {turns:.2f} periods of 2π)")
    axes[1].set_ylabel("radius error r(t) − 1")
    axes[1].set_title(
        "Smaller steps: slower growth, still growing" if growing else "Radius error of every run"
    )
    axes[1].grid(True, which="major", alpha=0.3)
    legend_below(axes[1])
    fig.tight_layout()
    save_figure(fig, path)
    shown = ", ".join(f"{r:.2f} at h = {h:g}" for h, r in zip(steps, finals, strict=True))
    excess = np.array(finals) - 1.0
    cuts = " and ".join(f"{a / b:.1f}" for a, b in pairwise(excess))
    still = (
        "it still grows at every step of every run"
        if growing
        else "it does not grow at every step of every run"
    )
    return (
        'Reproduces the lecture slide "Problem I: Inaccuracy" (Euler\'s method): explicit '
        f"Euler on the circle field for {len(steps)} step sizes turns the circle into a spiral; "
        f"the radius after {turns:.2f} turns is {shown} (exact: 1). Each halving of the step "
        f"divides the excess r − 1 only by {cuts}: it slows the error's growth, but {still}. "
        "Every run follows Euler's exact growth factor sqrt(1 + h²) per step (to "
        f"{worst:.0e} relative, round-off)."
    )


# -- 3. Euler's instability -------------------------------------------------------------------
def _decay_verdict(factor: float) -> str:
    """What a per-step factor does to the solution, in the lecture's words."""
    if abs(factor) >= 1:
        return "diverges" + (", oscillating" if factor < 0 else "")
    return "decays" + (", changing sign every step" if factor < 0 else "")


def fig_euler_instability(path: Path) -> str:
    """Explicit Euler on ``v' = -k v`` below, near and beyond ``k h = 2``."""
    case = figure_case("viscous-decay")
    m = case.particles
    k_rate = float(m.drag / m.mass[0])
    v0 = float(m.v0[0, 0])
    steps = sorted(case.dts)
    fig, axes = plt.subplots(1, 2, figsize=(11, 5.0))
    t = np.linspace(0, case.duration, 800)
    exact = cast(np.ndarray, EXACT[cast(str, case.exact)](case, t).v)[:, 0, 0]
    for ax in axes:
        ax.plot(t, exact, label="exact v0 e^(−kt)", **exact_style())
    said = []
    for i, dt in enumerate(steps):
        traj = run_reference(case, "euler", dt)
        v = cast(np.ndarray, traj.v)[:, 0, 0]
        kh = k_rate * step_taken(case, dt)
        factor = float(v[1] / v[0])
        said.append((kh, factor, _decay_verdict(factor)))
        label = f"Euler, k h = {kh:g}: v × {factor:+g} per step, {_decay_verdict(factor).split(',')[0]}"
        style = reference_style("euler", len(steps) - 1 - i, len(steps))
        axes[0].plot(traj.t, v, label=label, **style)
        axes[1].plot(traj.t, np.abs(v), label=label, **style)
    axes[0].set_xlim(0, 15)
    axes[0].set_ylim(-4, 4)
    axes[0].axhline(0, color="0.6", linewidth=0.6)
    axes[0].annotate(
        "to Neptune!",
        xy=(9.75, 3.85),
        xytext=(3.2, 3.0),
        fontsize=11,
        arrowprops={"arrowstyle": "->", "color": "black"},
    )
    axes[0].set_title(f"v' = −k v, k = b/m = {k_rate:g}/s, from v = {v0:g} m/s")
    axes[0].set_ylabel("velocity v (m/s)")
    axes[1].set_yscale("log")
    axes[1].set_ylim(1e-12, 1e5)
    axes[1].set_title("The same runs, |v| on a log scale")
    axes[1].set_ylabel("|v| (m/s)")
    axes[1].grid(True, which="major", alpha=0.3)
    for ax in axes:
        ax.set_xlabel("time t (s)")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=2, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.1, 1, 1))
    save_figure(fig, path)
    runs = "; ".join(
        f"at kh = {kh:g} it multiplies v by {f:+g} per step and {verdict}" for kh, f, verdict in said
    )
    return (
        'Reproduces the lecture slide "Problem II: Instability" ("to Neptune!"): the test '
        f"equation x' = −kx as the velocity of a {m.mass[0]:g} kg particle under viscous drag "
        f"b = {m.drag:g} N s/m (v' = −(b/m) v, k = {k_rate:g}/s), stepped by explicit Euler, "
        f"which multiplies v by (1 − kh) per step: {runs}, while the exact solution decays "
        "(the stability limit of Euler on this equation is kh = 2)."
    )


# -- 4. midpoint against Euler -----------------------------------------------------------------
def _midpoint_diagram(ax: plt.Axes, case) -> None:
    """One midpoint step of :data:`DIAGRAM_STEP` from the case's start, taken apart."""
    hs = DIAGRAM_STEP
    x0 = case.ode_spec.y0
    field = cast(type[System], ode_system(case.ode_spec.system))(x0)
    dx = hs * field.derivative(x0, 0.0)
    xm = x0 + dx / 2
    f_mid = field.derivative(xm, hs / 2)
    x_mid = ode_states(run_reference(replace(case, duration=hs), "midpoint", hs))[-1]
    arc = np.linspace(-0.2, 1.25, 100)
    ax.plot(np.cos(arc), np.sin(arc), label="exact integral curve", **exact_style())
    arrow: dict[str, Any] = {"angles": "xy", "scale_units": "xy", "scale": 1.0, "width": 0.012}
    euler_c, mid_c = series_colour("reference", "euler"), series_colour("reference", "midpoint")
    ax.quiver(*x0, *dx, color=euler_c, **arrow)
    ax.quiver(*xm, *(0.5 * hs * f_mid), color=SCENE_COLOURS[0], **arrow)
    ax.quiver(*x0, *(x_mid - x0), color=mid_c, **arrow)
    ax.plot(*xm, "o", color=SCENE_COLOURS[0], markersize=7, zorder=5)
    ax.plot(*x0, "o", color="black", markersize=7, zorder=5)
    ax.annotate("x(t)", x0 + np.array([0.05, -0.03]), fontsize=10)
    ax.annotate("a", x0 + 0.75 * dx + np.array([0.04, 0.0]), fontsize=12, color=euler_c, weight="bold")
    ax.annotate(
        "b",
        xm + 0.25 * hs * f_mid + np.array([0.05, 0.03]),
        fontsize=12,
        color=SCENE_COLOURS[0],
        weight="bold",
    )
    ax.annotate("c", 0.5 * (x0 + x_mid) + np.array([-0.1, 0.0]), fontsize=12, color=mid_c, weight="bold")
    ax.set_xlim(0.0, 1.5)
    ax.set_ylim(-0.2, 1.2)
    ax.set_aspect("equal")
    ax.set_title(f"One midpoint step, Δt = {hs:g}, from x(t) = ({x0[0]:g}, {x0[1]:g})")
    ax.set_xlabel("x (dimensionless)")
    ax.set_ylabel("y (dimensionless)")
    handles = [
        plt.Line2D([], [], color=euler_c, lw=3, label="a. Euler step Δx = Δt f(x, t)"),
        plt.Line2D(
            [],
            [],
            color=SCENE_COLOURS[0],
            lw=3,
            marker="o",
            label="b. f_mid = f(x + Δx/2, t + Δt/2) (drawn × Δt/2)",
        ),
        plt.Line2D([], [], color=mid_c, lw=3, label="c. x(t + Δt) = x(t) + Δt f_mid"),
        plt.Line2D([], [], **exact_style(), label="exact integral curve"),
    ]
    ax.legend(
        handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=1, fontsize=8, frameon=False
    )


def fig_midpoint(path: Path) -> str:
    """Midpoint against Euler on the circle field, and one midpoint step taken apart."""
    case = figure_case("circle-field-two-turns")
    fig, axes = plt.subplots(1, 3, figsize=(14, 5.2), gridspec_kw={"width_ratios": [1, 1, 1.2]})
    h = MIDPOINT_STEPS[0]
    ax = axes[0]
    circle = _exact_circle(case)
    ax.plot(circle[:, 0], circle[:, 1], label="exact circle", **exact_style())
    one_turn = replace(case, duration=case.duration / 2)
    for method in ("euler", "midpoint"):
        y = ode_states(run_reference(one_turn, method, h))
        ax.plot(y[:, 0], y[:, 1], label=f"{method}, h = {h:g}", **reference_style(method))
    ax.set_aspect("equal")
    ax.set_title(f"One turn, every step marked (h = {h:g})")
    ax.set_xlabel("x (dimensionless)")
    ax.set_ylabel("y (dimensionless)")
    legend_below(ax)

    _midpoint_diagram(axes[1], case)

    ax = axes[2]
    final = {}
    for method in ("euler", "midpoint"):
        for k, hh in enumerate(MIDPOINT_STEPS):
            traj = run_reference(case, method, hh)
            r = _radius(traj)
            final[method, hh] = abs(r[-1] - 1.0)
            every = max(1, len(traj.t) // 15)
            ax.plot(
                traj.t[1:],
                r[1:] - 1.0,
                markevery=every,
                label=f"{method}, h = {hh:g}",
                **reference_style(method, k, len(MIDPOINT_STEPS)),
            )
    ax.set_yscale("log")
    ax.grid(True, which="major", alpha=0.3)
    ax.set_xlabel(f"time t ({case.duration:g}: {case.duration / (2 * np.pi):.2f} periods of 2π)")
    ax.set_ylabel("radius error r(t) − 1")
    orders = {m: get_solver(m).order for m in ("euler", "midpoint")}
    ax.set_title(f"Radius error: order {orders['euler']} against order {orders['midpoint']}")
    legend_below(ax)
    fig.tight_layout()
    save_figure(fig, path)
    ratios = " and ".join(
        f"{final['euler', hh] / final['midpoint', hh]:.0f} times smaller at h = {hh:g}"
        for hh in MIDPOINT_STEPS
    )
    return (
        'Reproduces the lecture slide "The Midpoint Method": (a) an Euler step, (b) the '
        "field evaluated at the midpoint, (c) a full step with the midpoint slope, here "
        "one step of the reference midpoint solver drawn with the field values it uses "
        "(the slide's (x + Δx)/2 means x + Δx/2). Left and right: Euler's spiral against "
        f"midpoint on the circle field (orders {orders['euler']} and {orders['midpoint']}); "
        f"after {case.duration / (2 * np.pi):.2f} turns midpoint's radius error is {ratios} "
        "than Euler's."
    )
