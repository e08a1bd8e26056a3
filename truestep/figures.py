"""The lecture's figures, reproduced with the reference implementation.

Every figure is computed by :mod:`reference_impl` (its systems, solvers, meshes,
emitters, collisions and strands) through the same step loop the harness uses, never
drawn by hand, and carries a caption naming the lecture slide it reproduces.
:func:`write_lecture_figures` writes them all as PNGs and returns ``(path, caption)``
pairs for the report.

Colours: a line that is an engine/method series is styled by
:func:`truestep.plots.series_style` (every line here is the reference engine; shades of
its colour tell step sizes apart). Things that are not engines (particles, scene
variants) take :data:`SCENE_COLOURS`, none of which is an engine's colour; exact
solutions are a light grey band under the computed lines.

Each ``fig_*`` function draws one figure into the PNG ``path`` and returns its caption.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.colors as mcolors
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import EllipseCollection, LineCollection
from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

from truestep.adapters.reference import build_system
from truestep.cases.exact import EXACT, oscillator
from truestep.cases.loader import CASE_DIR, load_case
from truestep.plots import ENGINE_COLOURS, save, series_style
from truestep.reference_impl import forces, meshes
from truestep.reference_impl.collisions import box_planes
from truestep.reference_impl.emitters import Emitter, lifetime_values, spawn_count_moments, spawn_mean
from truestep.reference_impl.integrate import Run, integrate
from truestep.reference_impl.model import EmitterSpec, ParticleModel, Plane, Springs
from truestep.reference_impl.odes import CircleField
from truestep.reference_impl.particles import ParticleSystem, total_energy
from truestep.reference_impl.passes import passes_for
from truestep.reference_impl.solvers import get_solver
from truestep.reference_impl.strands import Strands, collect_strands
from truestep.reference_impl.system import System

DPI = 80
"""Resolution of every figure, dots per inch (as the report's other figures)."""
SCENE_COLOURS = ("#ff7f0e", "#17becf", "#8c564b", "#bcbd22", "#e377c2")
"""Colours for particles and scene variants; none is in :data:`ENGINE_COLOURS`."""
NIGHT = "#0d0d17"
"""Background of the particle renderings: particles add light, as point light sources."""
EXACT_COLOUR = "#c9c9c9"
"""Exact solutions are a light band under the computed lines."""
G = 9.81
"""Gravitational acceleration of the particle scenes, m/s^2 (along -y)."""


# -- helpers ------------------------------------------------------------------------------
def _simulate(system: System, method: str, t_end: float, dt: float) -> Run:
    """Step ``system`` with a reference solver to ``t_end`` (s), recording every step."""
    solver = get_solver(method)(system)
    return integrate(solver, t_end, dt, max_records=max(1, round(t_end / dt)))


def _split(run: Run, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Positions and velocities (T, n, 3) of a particle run's flat states."""
    return run.x[:, : 3 * n].reshape(-1, n, 3), run.x[:, 3 * n : 6 * n].reshape(-1, n, 3)


def _shade(colour: str, k: int, count: int) -> tuple[float, float, float]:
    """The ``k``-th of ``count`` shades of ``colour``: 0 is the colour itself, later ones lighter."""
    rgb = np.array(mcolors.to_rgb(colour))
    return tuple(rgb + (1.0 - rgb) * 0.6 * k / max(count - 1, 1))


def _ref(method: str, k: int = 0, count: int = 1, **over: object) -> dict:
    """``series_style("reference", method)``, in shade ``k`` of ``count`` (step sizes)."""
    style = series_style("reference", method)
    style["color"] = _shade(style["color"], k, count)
    style.update(over)
    return style


def _exact_style(**over: object) -> dict:
    """Exact solutions: a wide light band drawn under the runs, so a run on it stays visible."""
    style = {"color": EXACT_COLOUR, "linestyle": "-", "linewidth": 5.0, "solid_capstyle": "round",
             "zorder": 1}
    style.update(over)
    return style


def _legend_below(ax: plt.Axes, ncol: int = 2, **kw: object) -> None:
    """A legend under the axes, where it cannot cover the data."""
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=ncol, fontsize=8,
              frameon=False, **kw)


def _save(fig: plt.Figure, path: Path) -> None:
    save(fig, path, dpi=DPI)


class LinearDecay(System):
    """The test equation ``x' = -k x`` (``k`` in 1/s) of the lecture's instability slide.

    Exact: ``x0 e^(-k t)``. Explicit Euler multiplies ``x`` by ``1 - k h`` every step, so
    it diverges, oscillating, once ``k h > 2``.
    """

    def __init__(self, x0: float, k: float) -> None:
        super().__init__(np.array([x0]))
        self.k = k

    def derivative(self, x: np.ndarray, t: float) -> np.ndarray:
        return -self.k * x

    def jacobian(self, x: np.ndarray, t: float) -> np.ndarray:
        return np.array([[-self.k]])


# -- 1. vector field and integral curves ----------------------------------------------------
def fig_vector_field(path: Path) -> str:
    """The circle field as arrows, and integral curves followed by the adaptive solver."""
    field = CircleField(np.zeros(2))
    g = np.linspace(-2.0, 2.0, 15)
    gx, gy = np.meshgrid(g, g)
    pts = np.stack([gx.ravel(), gy.ravel()], axis=1)
    f = np.array([field.derivative(p, 0.0) for p in pts])
    fig, axes = plt.subplots(1, 2, figsize=(11, 5.6))
    for ax, shade in zip(axes, ("0.3", "0.7"), strict=True):
        ax.quiver(pts[:, 0], pts[:, 1], f[:, 0], f[:, 1], color=shade, angles="xy",
                  scale_units="xy", scale=10.0, width=0.004)
        ax.set_aspect("equal")
        ax.set_xlim(-2.25, 2.25)
        ax.set_ylim(-2.25, 2.25)
        ax.set_xlabel("x (state, dimensionless)")
        ax.set_ylabel("y (state, dimensionless)")
    axes[0].set_title("Vector Field: x' = f(x) = (−y, x) at every point")
    tol = 1e-9
    starts = [(0.55, 0.0), (0.9, 0.75), (1.6, -0.9)]
    for k, s in enumerate(starts):
        system = CircleField(np.array(s))
        run = integrate(get_solver("dopri5")(system, rtol=tol, atol=tol), 2 * np.pi, 2 * np.pi)
        axes[1].plot(run.x[:, 0], run.x[:, 1], markevery=4,
                     label=f"integral curve: reference / dopri5, tolerance {tol:g}" if k == 0 else None,
                     **_ref("dopri5", linewidth=2.0))
        axes[1].plot(*s, "o", color=SCENE_COLOURS[0], markersize=8, zorder=5,
                     label="starting point" if k == 0 else None)
    axes[1].annotate("Start Here", starts[2], xytext=(0.45, -2.05), fontsize=10,
                     arrowprops={"arrowstyle": "->", "color": "black"})
    axes[1].set_title("Integral Curves: pick any starting point, follow the vectors")
    _legend_below(axes[1])
    fig.tight_layout()
    _save(fig, path)
    return ('Reproduces the lecture slides "Vector Field", "Integral Curves" and "Initial Value '
            "Problems\" (Differential Equation Basics): the field x' = (−y, x) drawn as arrows, "
            "and the integral curves through three starting points, followed over one period "
            f"by the reference's adaptive Dormand-Prince solver (tolerance {tol:g}); each "
            "closes into a circle.")


# -- 2. Euler's spiral ----------------------------------------------------------------------
def fig_euler_spiral(path: Path) -> str:
    """Explicit Euler's spiral on the circle field for three step sizes, and its radius error."""
    steps = (0.2, 0.1, 0.05)
    t_end = 4 * np.pi
    fig, axes = plt.subplots(1, 2, figsize=(11, 5.4), gridspec_kw={"width_ratios": [1, 1.15]})
    theta = np.linspace(0, 2 * np.pi, 400)
    axes[0].plot(np.cos(theta), np.sin(theta), label="exact: the unit circle",
                 **_exact_style())
    finals, worst = [], 0.0
    for k, h in enumerate(steps):
        run = _simulate(CircleField(np.array([1.0, 0.0])), "euler", t_end, h)
        r = np.linalg.norm(run.x, axis=1)
        finals.append(r[-1])
        growth = (1 + h * h) ** (np.arange(len(r)) / 2)
        worst = max(worst, float(np.max(np.abs(r / growth - 1))))
        style = _ref("euler", k, len(steps))
        every = max(1, len(run.t) // 30)
        axes[0].plot(run.x[:, 0], run.x[:, 1], markevery=every, label=f"Euler, h = {h}", **style)
        axes[1].plot(run.t[1:], r[1:] - 1.0, markevery=every, label=f"Euler, h = {h}", **style)
        axes[1].plot(run.t[1:], growth[1:] - 1, label=(
            "(1 + h²)^(n/2) − 1: Euler's growth per step, exact" if k == 0 else None),
            **_exact_style())
    axes[0].set_aspect("equal")
    axes[0].set_xlabel("x (dimensionless)")
    axes[0].set_ylabel("y (dimensionless)")
    axes[0].set_title("Two turns of x' = (-y, x) from (1, 0)")
    _legend_below(axes[0])
    axes[1].set_yscale("log")
    axes[1].set_xlabel("time t (two periods, 4π)")
    axes[1].set_ylabel("radius error r(t) − 1")
    axes[1].set_title("Smaller steps: slower growth, still growing")
    axes[1].grid(True, which="major", alpha=0.3)
    _legend_below(axes[1])
    fig.tight_layout()
    _save(fig, path)
    shown = ", ".join(f"{r:.2f} at h = {h}" for h, r in zip(steps, finals, strict=True))
    return ('Reproduces the lecture slide "Problem I: Inaccuracy" (Euler\'s method): explicit '
            "Euler on the circle field for three step sizes turns the circle into a spiral; "
            f"the radius after two turns is {shown} (exact: 1). Halving the step does not cure "
            "the error, it only slows its growth. Every run follows Euler's exact growth "
            f"factor sqrt(1 + h²) per step (to {worst:.0e} relative, round-off).")


# -- 3. Euler's instability -------------------------------------------------------------------
def fig_euler_instability(path: Path) -> str:
    """Explicit Euler on ``x' = -k x`` below, near and beyond ``k h = 2``."""
    k_rate = 1.0
    khs = (0.5, 1.5, 2.5)
    t_end = 40.0
    fig, axes = plt.subplots(1, 2, figsize=(11, 5.0))
    t = np.linspace(0, t_end, 800)
    for ax in axes:
        ax.plot(t, np.exp(-k_rate * t), label="exact e^(−kt)", **_exact_style())
    for i, kh in enumerate(khs):
        h = kh / k_rate
        run = _simulate(LinearDecay(1.0, k_rate), "euler", t_end, h)
        verdict = "diverges" if kh > 2 else "decays"
        label = f"Euler, k h = {kh}: |1 − kh| = {abs(1 - kh):g}, {verdict}"
        style = _ref("euler", len(khs) - 1 - i, len(khs))
        axes[0].plot(run.t, run.x[:, 0], label=label, **style)
        axes[1].plot(run.t, np.abs(run.x[:, 0]), label=label, **style)
    axes[0].set_xlim(0, 15)
    axes[0].set_ylim(-4, 4)
    axes[0].axhline(0, color="0.6", linewidth=0.6)
    axes[0].annotate("to Neptune!", xy=(9.75, 3.85), xytext=(3.2, 3.0), fontsize=11,
                     arrowprops={"arrowstyle": "->", "color": "black"})
    axes[0].set_title("x' = −k x, k = 1/s, from x = 1")
    axes[0].set_ylabel("x (dimensionless)")
    axes[1].set_yscale("log")
    axes[1].set_ylim(1e-12, 1e5)
    axes[1].set_title("The same runs, |x| on a log scale")
    axes[1].set_ylabel("|x|")
    axes[1].grid(True, which="major", alpha=0.3)
    for ax in axes:
        ax.set_xlabel("time t (s)")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=2, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.1, 1, 1))
    _save(fig, path)
    return ('Reproduces the lecture slide "Problem II: Instability" ("to Neptune!"): explicit '
            "Euler on x' = −kx multiplies x by (1 − kh) per step; at kh = 0.5 it decays "
            "smoothly, at kh = 1.5 it overshoots but decays, and at kh = 2.5 (beyond the "
            "stability limit kh = 2) it oscillates with growing amplitude, 1.5 times larger "
            "every step, while the exact solution decays.")


# -- 4. midpoint against Euler -----------------------------------------------------------------
def fig_midpoint(path: Path) -> str:
    """Midpoint against Euler on the circle field, and one midpoint step taken apart."""
    fig, axes = plt.subplots(1, 3, figsize=(14, 5.2), gridspec_kw={"width_ratios": [1, 1, 1.2]})
    theta = np.linspace(0, 2 * np.pi, 400)
    h = 0.3
    ax = axes[0]
    ax.plot(np.cos(theta), np.sin(theta), label="exact circle", **_exact_style())
    for method in ("euler", "midpoint"):
        run = _simulate(CircleField(np.array([1.0, 0.0])), method, 2 * np.pi, h)
        ax.plot(run.x[:, 0], run.x[:, 1], label=f"{method}, h = {h}", **_ref(method))
    ax.set_aspect("equal")
    ax.set_title(f"One turn, every step marked (h = {h})")
    ax.set_xlabel("x (dimensionless)")
    ax.set_ylabel("y (dimensionless)")
    _legend_below(ax)

    ax = axes[1]
    hs = 1.0
    x0 = np.array([1.0, 0.0])
    field = CircleField(x0)
    dx = hs * field.derivative(x0, 0.0)
    xm = x0 + dx / 2
    f_mid = field.derivative(xm, hs / 2)
    solver = get_solver("midpoint")(field)
    solver.step(hs)
    x_mid = field.get_state()
    arc = np.linspace(-0.2, 1.25, 100)
    ax.plot(np.cos(arc), np.sin(arc), label="exact integral curve", **_exact_style())
    arrow = {"angles": "xy", "scale_units": "xy", "scale": 1.0, "width": 0.012}
    euler_c, mid_c = _shade(ENGINE_COLOURS["reference"], 2, 3), ENGINE_COLOURS["reference"]
    ax.quiver(*x0, *dx, color=euler_c, **arrow)
    ax.quiver(*xm, *(0.5 * hs * f_mid), color=SCENE_COLOURS[0], **arrow)
    ax.quiver(*x0, *(x_mid - x0), color=mid_c, **arrow)
    ax.plot(*xm, "o", color=SCENE_COLOURS[0], markersize=7, zorder=5)
    ax.plot(*x0, "o", color="black", markersize=7, zorder=5)
    ax.annotate("x(t)", x0 + np.array([0.05, -0.03]), fontsize=10)
    ax.annotate("a", x0 + 0.75 * dx + np.array([0.04, 0.0]), fontsize=12, color=euler_c,
                weight="bold")
    ax.annotate("b", xm + 0.25 * hs * f_mid + np.array([0.05, 0.03]), fontsize=12,
                color=SCENE_COLOURS[0], weight="bold")
    ax.annotate("c", 0.5 * (x0 + x_mid) + np.array([-0.1, 0.0]), fontsize=12, color=mid_c,
                weight="bold")
    ax.set_xlim(0.0, 1.5)
    ax.set_ylim(-0.2, 1.2)
    ax.set_aspect("equal")
    ax.set_title(f"One midpoint step, Δt = {hs:g}, from x(t) = (1, 0)")
    ax.set_xlabel("x (dimensionless)")
    ax.set_ylabel("y (dimensionless)")
    handles = [
        plt.Line2D([], [], color=euler_c, lw=3, label="a. Euler step Δx = Δt f(x, t)"),
        plt.Line2D([], [], color=SCENE_COLOURS[0], lw=3, marker="o",
                   label="b. f_mid = f(x + Δx/2, t + Δt/2) (drawn × Δt/2)"),
        plt.Line2D([], [], color=mid_c, lw=3, label="c. x(t + Δt) = x(t) + Δt f_mid"),
        plt.Line2D([], [], **_exact_style(), label="exact integral curve"),
    ]
    ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=1, fontsize=8,
              frameon=False)

    ax = axes[2]
    hs_err = (0.3, 0.1)
    for method in ("euler", "midpoint"):
        for k, hh in enumerate(hs_err):
            run = _simulate(CircleField(np.array([1.0, 0.0])), method, 4 * np.pi, hh)
            r = np.linalg.norm(run.x, axis=1)
            every = max(1, len(run.t) // 15)
            ax.plot(run.t[1:], r[1:] - 1.0, markevery=every, label=f"{method}, h = {hh}",
                    **_ref(method, k, len(hs_err)))
    ax.set_yscale("log")
    ax.grid(True, which="major", alpha=0.3)
    ax.set_xlabel("time t (two periods, 4π)")
    ax.set_ylabel("radius error r(t) − 1")
    ax.set_title("Radius error: 1st order against 2nd order")
    _legend_below(ax)
    fig.tight_layout()
    _save(fig, path)
    return ('Reproduces the lecture slide "The Midpoint Method": (a) an Euler step, (b) the '
            "field evaluated at the midpoint, (c) a full step with the midpoint slope, here "
            "one step of the reference midpoint solver drawn with the field values it uses "
            "(the slide's (x + Δx)/2 means x + Δx/2). Left and right: Euler's spiral against "
            "midpoint on the circle field; midpoint's radius error is smaller by orders of "
            "magnitude (order 2 against order 1).")


# -- 5. undamped against damped spring ------------------------------------------------------------
def fig_springs(path: Path) -> str:
    """The harmonic-oscillator and damped-oscillator cases: position and energy."""
    names = ("harmonic-oscillator", "damped-oscillator")
    method, dt = "rk4", 4e-3
    fig, axes = plt.subplots(2, 2, figsize=(11, 6.4), sharex=True, sharey="row")
    for col, name in enumerate(names):
        case = load_case(CASE_DIR / f"{name}.toml")
        system = build_system(case)
        run = _simulate(system, method, case.duration, dt)
        x, v = _split(run, case.model.n)
        energy = total_energy(case.model, x, v)
        exact = EXACT[case.exact](case, run.t)
        axes[0, col].plot(run.t, x[:, 0, 0], markevery=25, label=f"reference / {method}, dt = {dt:g} s",
                          **_ref(method, linewidth=1.6))
        axes[0, col].plot(run.t, exact.x[:, 0, 0], label="exact", **_exact_style())
        axes[1, col].plot(run.t, energy, markevery=25, label=f"reference / {method}",
                          **_ref(method, linewidth=1.6))
        axes[1, col].plot(run.t, exact.energy, label="exact", **_exact_style())
        a = case.model.anchors
        axes[0, col].set_title(f"{case.title} (case {name})\nk_s = {a.stiffness[0]:g} N/m, "
                               f"k_d = {a.damping[0]:g} N s/m", fontsize=10)
        axes[1, col].set_xlabel("time (s)")
    axes[0, 0].set_ylabel("position x (m)")
    axes[1, 0].set_ylabel("total energy (J)")
    for ax in axes.ravel():
        ax.grid(True, alpha=0.3)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=2, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    _save(fig, path)
    return ('Reproduces the lecture slides "Damper" ("Un-damped spring" beside a damped one): '
            "the cases harmonic-oscillator and damped-oscillator (1 kg on an anchored spring, "
            "released 0.1 m out), run by the reference RK4 at dt = 4 ms against their exact "
            "solutions. Undamped, the energy stays at 0.5 J; the damper removes it and the "
            "amplitude decays as e^(−t).")


# -- 6. spring-damper pair -----------------------------------------------------------------------
def fig_spring_damper_pair(path: Path) -> str:
    """Two free masses on one spring-damper, with and without the damper."""
    m1, m2, k_s, rest, length0 = 1.0, 2.0, 40.0, 1.0, 1.5
    dampings = (1.5, 0.0)
    method, dt, t_end = "rk4", 1e-2, 5.0
    mu = m1 * m2 / (m1 + m2)
    fig, axes = plt.subplots(1, 2, figsize=(12, 5.0))
    for k, k_d in enumerate(dampings):
        model = ParticleModel(
            mass=np.array([m1, m2]), x0=np.array([[0.0, 0, 0], [length0, 0, 0]]),
            v0=np.zeros((2, 3)), radius=np.zeros(2), fixed=np.zeros(2, bool),
            springs=Springs(np.array([0]), np.array([1]), np.array([k_s]), np.array([k_d]),
                            np.array([rest])),
        )
        run = _simulate(ParticleSystem(model), method, t_end, dt)
        x, _ = _split(run, 2)
        length = np.linalg.norm(x[:, 1] - x[:, 0], axis=1)
        u, _ = oscillator(mu, k_s, k_d, length0 - rest, 0.0, run.t)
        worst = np.max(np.abs(length - (rest + u)))
        axes[1].plot(run.t, length, markevery=25, label=f"reference / {method}, k_d = {k_d:g} N s/m "
                     f"(deviation from exact ≤ {worst:.0e} m)", **_ref(method, k, 2, linewidth=1.6))
        if k == 0:
            axes[1].plot(run.t, rest + u, label="exact (reduced mass μ = m1 m2 / (m1 + m2))",
                         **_exact_style())
            com0 = m2 * length0 / (m1 + m2)
            axes[0].plot(run.t, x[:, 0, 0], color=SCENE_COLOURS[0], linewidth=1.5,
                         label=f"p1, m1 = {m1:g} kg")
            axes[0].plot(run.t, x[:, 1, 0], color=SCENE_COLOURS[1], linewidth=1.5,
                         label=f"p2, m2 = {m2:g} kg")
            axes[0].plot(run.t, (m1 * x[:, 0, 0] + m2 * x[:, 1, 0]) / (m1 + m2), color="black",
                         linewidth=1.0, label="centre of mass")
            for i, (mi, sign) in enumerate(((m2, -1.0), (m1, 1.0))):
                axes[0].plot(run.t, com0 + sign * mi / (m1 + m2) * (rest + u),
                             label="exact" if i == 0 else None, **_exact_style())
    axes[1].axhline(rest, color="0.5", linewidth=0.8, linestyle=":", label="rest length L_r")
    axes[0].set_title(f"Positions along x, k_s = {k_s:g} N/m, k_d = {dampings[0]:g} N s/m")
    axes[0].set_ylabel("position x (m)")
    axes[1].set_title("Spring length L_c = |p2 − p1|")
    axes[1].set_ylabel("length (m)")
    for ax in axes:
        ax.set_xlabel("time (s)")
        ax.grid(True, alpha=0.3)
    _legend_below(axes[0], ncol=2)
    _legend_below(axes[1], ncol=1)
    fig.tight_layout()
    _save(fig, path)
    return ('Reproduces the lecture slide "Spring-Damper Pair": two free point masses (1 kg and '
            "2 kg) joined by the lecture's spring-damper f = (k_s (L_c − L_r) + k_d (ṗ2 − ṗ1)·u) u, "
            "u = (p2 − p1)/|p2 − p1| (the damper's sign taken so that it resists the change of "
            "length, as the damped-spring slide writes it), released 0.5 m stretched. Reference "
            "RK4 at dt = 10 ms against the exact solution; the centre of mass stays put, and "
            "without the damper (k_d = 0) the pair oscillates for ever.")


# -- 7. the triangle, step by step ---------------------------------------------------------------
def fig_triangle(path: Path) -> str:
    """The triangle of springs, a force on V2 for one step, then step by step."""
    mesh = meshes.triangle(1.0)
    mass, springs = meshes.mass_spring(mesh, 3.0, 300.0, 0.0)
    dt, force, n_show = 0.04, np.array([25.0, 0.0, 0.0]), 8
    model = ParticleModel(mass, mesh.vertices.copy(), np.zeros((3, 3)), np.zeros(3),
                          np.zeros(3, bool), springs=springs,
                          impulses=[(1, force, 0.0, 0.5 * dt)], dimension=2)
    system = ParticleSystem(model)
    run = _simulate(system, "lecture", (n_show - 1) * dt, dt)
    x, v = _split(run, 3)
    fig, axes = plt.subplots(2, n_show // 2, figsize=(13, 7.0), sharex=True, sharey=True)
    ext_scale, spring_scale = 0.008, 0.03  # m of arrow per N
    ext_colour, spring_colour = "black", SCENE_COLOURS[4]
    strain_norm = mcolors.TwoSlopeNorm(vcenter=0.0, vmin=-0.08, vmax=0.08)
    cmap = plt.get_cmap("PuOr_r")
    moved = np.linalg.norm(x - x[0], axis=2) * 1000  # mm
    a2 = force[0] / mass[1]
    notes = {
        0: "F acts on V2 for this one step",
        1: f"V2 moved ½ a2 Δt² = {moved[1, 1]:.0f} mm",
        2: "E12, E23 act on V1, V2, V3",
    }
    for s, ax in enumerate(axes.ravel()):
        rest_tri = np.vstack([mesh.vertices[:, :2], mesh.vertices[:1, :2]])
        ax.plot(rest_tri[:, 0], rest_tri[:, 1], color="0.7", linewidth=1.0, linestyle="--")
        for e, (i, j) in enumerate(mesh.edges):
            strain = (np.linalg.norm(x[s, i] - x[s, j]) - springs.rest[e]) / springs.rest[e]
            ax.plot(x[s, [i, j], 0], x[s, [i, j], 1], color=cmap(strain_norm(strain)), linewidth=3.5,
                    solid_capstyle="round")
        ax.plot(x[s, :, 0], x[s, :, 1], "o", color="black", markersize=5, zorder=4)
        f_spring = np.zeros((3, 3))
        forces.add_springs(f_spring, x[s], v[s], springs)
        t = run.t[s]
        for i in range(3):
            if np.linalg.norm(f_spring[i]) > 1e-9:
                ax.annotate("", xy=x[s, i, :2] + spring_scale * f_spring[i, :2], xytext=x[s, i, :2],
                            arrowprops={"arrowstyle": "-|>", "color": spring_colour, "lw": 2.0})
        for i, f_ext, t_on, t_off in model.impulses:
            if t_on <= t < t_off:
                ax.annotate("", xy=x[s, i, :2] + ext_scale * f_ext[:2], xytext=x[s, i, :2],
                            arrowprops={"arrowstyle": "-|>", "color": ext_colour, "lw": 2.4})
                ax.annotate("F", x[s, i, :2] + ext_scale * f_ext[:2] + np.array([0.03, 0.0]),
                            color=ext_colour, fontsize=11)
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
        plt.Line2D([], [], color=ext_colour, lw=2.4, label=f"external force F = {force[0]:g} N on V2, "
                   f"first step only ({ext_scale * 1000:g} mm per N)"),
        plt.Line2D([], [], color=spring_colour, lw=2.0,
                   label=f"spring forces acting in the next step ({spring_scale * 1000:g} mm per N)"),
        plt.Line2D([], [], color="0.7", lw=1.0, ls="--", label="rest shape"),
    ]
    fig.legend(handles=handles, loc="lower center", ncol=3, fontsize=9, frameon=False)
    sm = plt.cm.ScalarMappable(norm=strain_norm, cmap=cmap)
    fig.tight_layout(rect=(0, 0.05, 0.9, 1))
    cax = fig.add_axes((0.915, 0.2, 0.012, 0.6))
    fig.colorbar(sm, cax=cax, label="edge strain (L − L_r) / L_r")
    _save(fig, path)
    return ('Reproduces the lecture slides "A simple example" (7.2 Spring Animation Examples): an '
            f"equilateral triangle of 1 m sides, 1 kg per vertex and edge springs of "
            f"{springs.stiffness[0]:g} N/m, stepped by the lecture's update (v' = v + a Δt, "
            f"p' = p + (v + v') Δt / 2) with Δt = {dt} s. A force of {force[0]:g} N pushes V2 "
            f"for the first step only (a2 = F / m2 = {a2:g} m/s², v2' = a2 Δt = {a2 * dt:g} m/s); "
            f"after it V2 has moved ½ a2 Δt² = {moved[1, 1]:.0f} mm and edges E12 and E23 are "
            "strained, and from the next step on their springs carry the disturbance to V1 and "
            "V3, one step at a time. Edge colour: strain; arrows: the forces acting during the "
            "next step.")


# -- 8. the cube: edge springs alone against face and volume springs -----------------------------
CUBE_PUSH = np.array([20.0, -20.0, 0.0])
"""Force on each top vertex of the cube figure, N."""
CUBE_TOP, CUBE_BOTTOM = (2, 3, 6, 7), (0, 1, 4, 5)
"""Vertices of the top (pushed) and bottom (pinned) faces of :func:`truestep.reference_impl.meshes.cube`."""


@dataclass
class CubeRun:
    """A pinned-base cube pushed sideways: its mesh, times (T,), positions (T, 8, 3), volume (T,)."""

    mesh: meshes.Mesh
    t: np.ndarray
    x: np.ndarray
    volume: np.ndarray


def simulate_cube(bracing: str, *, t_end: float = 3.0, dt: float = 2e-3) -> CubeRun:
    """A 1 m, 8 kg cube, bottom face pinned, each top vertex pushed by :data:`CUBE_PUSH`.

    Springs 200 N/m with 1 N s/m dampers, viscous drag 2 N s/m; velocity Verlet.
    """
    mesh = meshes.cube(1.0, np.array([0.0, 0.5, 0.0]), bracing)
    mass, springs = meshes.mass_spring(mesh, 8.0, 200.0, 1.0)
    fixed = np.zeros(8, bool)
    fixed[list(CUBE_BOTTOM)] = True
    push = [(i, CUBE_PUSH, 0.0, np.inf) for i in CUBE_TOP]
    model = ParticleModel(mass, mesh.vertices.copy(), np.zeros((8, 3)), np.zeros(8), fixed,
                          drag=2.0, springs=springs, impulses=push, surfaces=[mesh.faces])
    run = _simulate(ParticleSystem(model), "verlet", t_end, dt)
    x, _ = _split(run, 8)
    return CubeRun(mesh, run.t, x, meshes.signed_volume(x, mesh.faces))


def _up(x: np.ndarray) -> np.ndarray:
    """Scene coordinates (..., 3) in matplotlib's 3-D order: x, z, then y (up) as the vertical."""
    return x[..., [0, 2, 1]]


def _draw_cube(ax: plt.Axes, mesh: meshes.Mesh, x: np.ndarray, colour: str) -> None:
    p = _up(x)
    ax.add_collection3d(Poly3DCollection(p[mesh.faces], facecolor=colour, alpha=0.2,
                                         edgecolor="none"))
    styles = {0: ("black", 2.0), 1: ("0.4", 0.8), 2: ("0.55", 0.8)}
    for kind, (col, lw) in styles.items():
        sel = mesh.edges[mesh.kind == kind]
        if len(sel):
            ax.add_collection3d(Line3DCollection(p[sel], colors=col, linewidths=lw))
    ax.scatter(*p.T, color="black", s=10, depthshade=False)
    ax.scatter(*p[list(CUBE_BOTTOM)].T, color="black", marker="s", s=28, depthshade=False)
    top = p[list(CUBE_TOP)]
    arrow = np.broadcast_to(_up(CUBE_PUSH) / np.linalg.norm(CUBE_PUSH) * 0.35, top.shape)
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
    runs = {"edges": simulate_cube("edges"), "volume": simulate_cube("volume")}
    labels = {"edges": "edge springs only (12)", "volume": "edge, face and volume springs (28)"}
    colours = {"edges": SCENE_COLOURS[0], "volume": SCENE_COLOURS[1]}
    v_edges = runs["edges"].volume
    t = runs["edges"].t
    flat = int(np.argmax(v_edges <= 0))
    times = (0.0, float(t[flat]), float(t[-1]))
    fig = plt.figure(figsize=(14, 7.6))
    grid = fig.add_gridspec(2, 4, width_ratios=[1, 1, 1, 1.25], left=0.03, right=0.98, top=0.9,
                            bottom=0.2, hspace=0.25, wspace=0.25)
    for row, key in enumerate(runs):
        r = runs[key]
        for col, when in enumerate(times):
            ax = fig.add_subplot(grid[row, col], projection="3d")
            s = int(np.argmin(np.abs(r.t - when)))
            _draw_cube(ax, r.mesh, r.x[s], colours[key])
            volume = np.round(r.volume[s], 2) + 0.0  # no "-0.00"
            ax.set_title(f"t = {r.t[s]:.2f} s, volume {volume:+.2f} m³", fontsize=9, pad=0)
        fig.text(0.01, 0.73 - 0.36 * row, labels[key], rotation=90, va="center", fontsize=11,
                 color=colours[key], weight="bold")
    ax = fig.add_subplot(grid[:, 3])
    for key, r in runs.items():
        ax.plot(r.t, r.volume, color=colours[key], linewidth=1.8, label=labels[key])
    for when in times:
        ax.axvline(when, color="0.6", linewidth=0.8, linestyle=":")
    ax.axhline(0.0, color="0.5", linewidth=0.8)
    ax.text(r.t[-1], 0.03, "flat", ha="right", fontsize=8, color="0.4")
    ax.text(r.t[-1], -0.1, "inside out", ha="right", fontsize=8, color="0.4")
    ax.set_xlabel("time (s); dotted: the snapshots")
    ax.set_ylabel("signed volume (m³)")
    ax.set_title("Signed volume of the cube's surface")
    ax.grid(True, alpha=0.3)
    handles = [
        *ax.get_legend_handles_labels()[0],
        plt.Line2D([], [], color=SCENE_COLOURS[4], lw=1.5,
                   label=f"push: {np.linalg.norm(CUBE_PUSH):.0f} N on each top vertex"),
        plt.Line2D([], [], color="black", marker="s", ls="none", label="pinned vertices"),
    ]
    ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.09), fontsize=8,
              frameon=False)
    fig.suptitle("A cube of springs pushed sideways: edge springs alone let it turn inside out",
                 fontsize=12)
    _save(fig, path)
    return ('Reproduces the lecture slide on the cube that turns inside out (7.2 Spring Animation '
            'Examples: "the cube can turn inside out; additional springs can be added across '
            "the object's faces and its volume\"): two 1 m, 8 kg cubes with the bottom face "
            "pinned (squares) and the top face pushed along (1, −1, 0) by 28 N per vertex (springs "
            "200 N/m with 1 N s/m dampers, drag 2 N s/m, velocity Verlet at 2 ms). With edge "
            "springs alone nothing resists shear: the cube folds flat at "
            f"t = {times[1]:.2f} s and ends inside out (signed volume {v_edges[-1]:+.2f} m³); "
            "with face and volume springs it keeps "
            f"{runs['volume'].volume[-1]:.2f} m³ of its 1 m³. Thick lines: edges; thin: "
            "face and body diagonals.")


# -- 9 and 10. the fountain and its strands -------------------------------------------------
@dataclass
class Fountain:
    """A cube emitter's run, one record per frame.

    spec : the emitter; emitter : its pass (per-frame counts, sizes, ages)
    t : (T,) s; x, v : (T, capacity, 3) m and m/s; alive : (T, capacity) bool
    snapshot : record index of the first frame with ``target`` live particles
    colors : (capacity, 4) RGBA at the snapshot; shapes : (capacity, 2) ellipsoid semi-axes, m
    """

    spec: EmitterSpec
    emitter: Emitter
    t: np.ndarray
    x: np.ndarray
    v: np.ndarray
    alive: np.ndarray
    snapshot: int
    colors: np.ndarray
    shapes: np.ndarray


FOUNTAIN_SPEC = EmitterSpec(
    shape="cube", center=np.zeros(3), size=0.3, rate_n=260.0, rate_r=20.0, speed=3.0,
    spread=0.35, lifetime=20, lifetime_jitter=5, capacity=12000, speed_jitter=0.2,
    particle_size=0.006, size_jitter=0.5, fade_height=1.0, seed=7,
)
"""The fountain: a 0.3 m cube spraying about 270 particles a frame at 30 frames a second,
each living 20 +- 5 frames: about 5400 alive once the first ones expire."""
STRAND_FRAMES = 4
"""The strand figure draws the whole lives of the particles born in the first frames."""
FOUNTAIN_VIEW = ((-2.5, 2.5), (-4.4, 1.0))
"""x and y limits (m) of the side views of the fountain and its strands."""


def simulate_fountain(spec: EmitterSpec = FOUNTAIN_SPEC, *, target: int = 5000,
                      strand_frames: int = STRAND_FRAMES) -> Fountain:
    """Run the emitter frame by frame (one lecture-update step per frame) under gravity -y.

    Stops once ``target`` particles are alive and every particle born in the first
    ``strand_frames`` frames has died (their whole lives make the strands). The pool
    is large enough that no slot is reused, so a slot's size is its particle's.
    """
    cap = spec.capacity
    model = ParticleModel(np.full(cap, spec.particle_mass), np.zeros((cap, 3)), np.zeros((cap, 3)),
                          np.zeros(cap), np.zeros(cap, bool), gravity=np.array([0.0, -G, 0.0]),
                          emitters=[spec])
    system = ParticleSystem(model, passes_for(model))
    emitter = next(p for p in system.passes if isinstance(p, Emitter))
    solver = get_solver("lecture")(system)
    dt = spec.frame_dt
    last_frame = strand_frames + int(lifetime_values(spec).max())
    ts, xs, vs, alive = [0.0], [system.positions.copy()], [system.velocities.copy()], [system.alive.copy()]
    snapshot, colors, shapes = -1, np.zeros((cap, 4)), np.zeros((cap, 2))
    while snapshot < 0 or emitter.frame <= last_frame:
        solver.step(dt)
        system.between_steps(dt)
        ts.append(system.get_time())
        xs.append(system.positions.copy())
        vs.append(system.velocities.copy())
        alive.append(system.alive.copy())
        if snapshot < 0 and emitter.population[-1] >= target:
            snapshot = len(ts) - 1
            colors, shapes = emitter.colors(system), emitter.shapes(system)
        if emitter.frame > 10 * last_frame:
            raise RuntimeError(f"fountain: {target} particles never alive at once")
    if sum(emitter.spawned) > cap:
        raise RuntimeError("fountain: the pool reused slots; raise its capacity")
    return Fountain(spec, emitter, np.array(ts), np.array(xs), np.array(vs), np.array(alive),
                    snapshot, colors, shapes)


def _night(ax: plt.Axes, view: tuple = FOUNTAIN_VIEW) -> None:
    ax.set_facecolor(NIGHT)
    ax.set_aspect("equal")
    ax.set_xlim(*view[0])
    ax.set_ylim(*view[1])
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m, up)")


def _add_night_3d(fig: plt.Figure, spec: object) -> plt.Axes:
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
    ax.plot([cx - h, cx + h, cx + h, cx - h, cx - h], [cy - h, cy - h, cy + h, cy + h, cy - h],
            color="white", linewidth=0.8)


def fig_fountain(path: Path, fountain: Fountain) -> str:
    """The cube emitter's particles at the first frame with 5000 alive, and the population."""
    f, spec = fountain, fountain.spec
    s = f.snapshot
    live = f.alive[s]
    pos, vel = f.x[s][live], f.v[s][live]
    rgba, semi = f.colors[live], f.shapes[live]
    fig = plt.figure(figsize=(15, 6.0))
    grid = fig.add_gridspec(1, 3, width_ratios=[1, 1.1, 1], left=0.05, right=0.98, bottom=0.1,
                            top=0.88, wspace=0.22)
    ax = fig.add_subplot(grid[0])
    angles = np.degrees(np.arctan2(vel[:, 1], vel[:, 0]))
    ax.add_collection(EllipseCollection(2 * semi[:, 0], 2 * semi[:, 1], angles, units="xy",
                                        offsets=pos[:, :2], offset_transform=ax.transData,
                                        facecolors=rgba, edgecolors="none"))
    _night(ax)
    _emitter_outline(ax, spec)
    ax.set_title(f"Side view at frame {s} (t = {f.t[s]:.2f} s): {live.sum()} live particles,\n"
                 "ellipses stretched along the velocity by one frame's travel", fontsize=10)

    ax3 = _add_night_3d(fig, grid[1])
    p3 = _up(pos)
    ax3.scatter(p3[:, 0], p3[:, 1], p3[:, 2], c=rgba, s=1.5, depthshade=False, linewidths=0)
    ax3.set_title("The same particles in 3-D, as points", fontsize=10)

    ax = fig.add_subplot(grid[2])
    e = f.emitter
    frames = np.arange(len(e.population))
    mean, _ = spawn_count_moments(spawn_mean(spec), spec.rate_r)
    lives = lifetime_values(spec)
    expected = mean * np.cumsum([(lives > a).mean() for a in frames])
    ax.plot(frames, e.population, color=SCENE_COLOURS[0], linewidth=1.8, marker="o", markersize=3,
            label="live particles (reference emitter)")
    ax.plot(frames, expected, label="expected: (n + r/2) Σ P(lifetime > age)", **_exact_style())
    ax.axvline(s, color="0.5", linewidth=0.8, linestyle=":")
    ax.axhline(5000, color="0.5", linewidth=0.8, linestyle=":")
    ax.annotate("the snapshot", (s, 5000), xytext=(s - 8, 2500), fontsize=9,
                arrowprops={"arrowstyle": "->", "color": "0.3"})
    ax.set_xlabel(f"frame (1/{1 / spec.frame_dt:.0f} s each)")
    ax.set_ylabel("particles alive")
    ax.set_title(f"# new per frame = n + Rand() r, n = {spec.rate_n:g}, r = {spec.rate_r:g};\n"
                 f"lifetime {spec.lifetime} ± {spec.lifetime_jitter} frames", fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="lower right", fontsize=8, frameon=False)
    _save(fig, path)
    return ('Reproduces the lecture slide "A cube emitting 5000 animated particles, obeying a '
            "'gravitational' force in -Y direction\" (Snowflakes vs Hair): the reference emitter "
            f"sprays from all six faces of a {spec.size:g} m cube along the face normals "
            f"({spec.speed:g} m/s ± {100 * spec.speed_jitter:g} %, within {spec.spread:g} rad), "
            "one lecture-update step per frame at 30 frames/s under g = 9.81 m/s² along −y, run "
            f"until the first frame with at least 5000 particles alive ({live.sum()} at frame "
            f"{s}). Colour goes from yellow at birth to red at death; opacity falls with age and "
            f"with height (e-folding {spec.fade_height:g} m); each particle is an ellipse "
            "stretched along its velocity: the lecture's particle attributes, drawn as point "
            "light sources. Right: the population against its expectation.")


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


def _first_lives(st: Strands, t_born: float, alive_at_end: np.ndarray) -> Strands:
    """The strands born before ``t_born`` (s) whose particle has died by the end: whole lives."""
    born = st.times[st.start[:-1]]
    keep = np.flatnonzero((born < t_born) & ~alive_at_end[st.slot] & (np.diff(st.start) > 1))
    sel = np.concatenate([np.arange(st.start[k], st.start[k + 1]) for k in keep])
    start = np.concatenate([[0], np.cumsum(np.diff(st.start)[keep])])
    return Strands(st.points[sel], st.times[sel], st.velocities[sel], start, st.slot[keep],
                   st.thickness[sel])


def _draw_strands(ax: plt.Axes, seg: np.ndarray, thick: np.ndarray, colours: np.ndarray) -> None:
    """Strand segments in x-y with their thickness in metres turned into points on this axes."""
    fig = ax.figure
    ax.apply_aspect()
    width_in = ax.get_position().width * fig.get_figwidth()
    pt_per_m = width_in * 72 / np.ptp(ax.get_xlim())
    ax.add_collection(LineCollection(seg[:, :, :2], linewidths=thick * pt_per_m, colors=colours,
                                     alpha=0.6, capstyle="butt"))


def fig_strands(path: Path, fountain: Fountain) -> str:
    """The fountain's first particles drawn over their whole lives as strands."""
    f, spec = fountain, fountain.spec
    taper = 0.8
    st = collect_strands(f.t, f.x, f.v, f.alive, root_thickness=2 * f.emitter.size, taper=taper)
    sub = _first_lives(st, STRAND_FRAMES * spec.frame_dt - 1e-9, f.alive[-1])
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
    ax.plot([zx0, zx1, zx1, zx0, zx0], [zy0, zy0, zy1, zy1, zy0], color="white", linewidth=0.8,
            linestyle="--")
    roots = 2 * spec.particle_size * np.array([1 - spec.size_jitter, 1 + spec.size_jitter]) * 1000
    ax.set_title(f"{len(sub)} strands: every particle born in the first {STRAND_FRAMES} frames,\n"
                 "its whole life drawn at once", fontsize=10)
    ax = fig.add_subplot(grid[1])
    _night(ax, zoom)
    margin = 0.5  # m, longer than any segment (one frame's travel), so none is cut off
    inside = np.any((seg[:, :, 0] > zx0 - margin) & (seg[:, :, 0] < zx1 + margin)
                    & (seg[:, :, 1] > zy0 - margin) & (seg[:, :, 1] < zy1 + margin), axis=1)
    _draw_strands(ax, seg[inside], thick[inside], colours[inside])
    _emitter_outline(ax, spec)
    ax.set_title("Zoom on the dashed box, thickness to scale: each strand has its own root "
                 f"thickness\n({roots[0]:.0f}–{roots[1]:.0f} mm) and tapers to "
                 f"{100 * (1 - taper):.0f} % of it at the tip", fontsize=10)
    sm = plt.cm.ScalarMappable(norm=mcolors.Normalize(0, 1), cmap=cmap)
    fig.colorbar(sm, ax=ax, fraction=0.04, pad=0.02, label="fraction of the particle's life")
    fig.tight_layout()
    _save(fig, path)
    return ('Reproduces the lecture slide "The same cube emitter rendered using static particles, '
            'or strands" (Snowflakes vs Hair): the emitter and forces of the fountain figure, but '
            f"every particle born in its first {STRAND_FRAMES} frames drawn over its whole life at "
            "once, as a polyline through its positions frame by frame (truestep.reference_impl.strands). "
            "Each strand's thickness at the root is its particle's size (the shape parameter, "
            f"{roots[0]:.0f} to {roots[1]:.0f} mm), tapering linearly along the strand to "
            f"{100 * (1 - taper):.0f} %; colour runs from birth to death as in the fountain.")


# -- 11. bouncing off the walls ---------------------------------------------------------------------
def _bounces(x: np.ndarray, v: np.ndarray, planes: list[Plane], near: float) -> list[tuple]:
    """Collisions of one particle in a recorded run: (record, plane, V before, V after).

    A collision is a record where the normal velocity turns from heading in to heading
    out while the particle is within ``near`` (m) of the plane.
    """
    out = []
    for k, p in enumerate(planes):
        vn = v @ p.normal
        d = (x - p.point) @ p.normal
        hits = np.flatnonzero((vn[:-1] < 0) & (vn[1:] > 0) & (d[1:] < near))
        out.extend((int(i + 1), k, v[i], v[i + 1]) for i in hits)
    return sorted(out, key=lambda b: b[0])


def fig_bounce(path: Path) -> str:
    """A particle bouncing in a box for three restitutions; one collision taken apart."""
    lo, hi = np.array([-1.0, 0.0, -1.0]), np.array([1.0, 2.0, 1.0])
    restitutions = (1.0, 0.75, 0.5)
    dt, t_end = 2e-3, 2.0
    x0, v0 = np.array([[-0.7, 1.6, 0.0]]), np.array([[2.6, 1.2, 0.0]])
    fig, axes = plt.subplots(1, 3, figsize=(15, 5.6), gridspec_kw={"width_ratios": [1, 1.1, 1]})
    measured = []
    diagram = None
    for k, e in enumerate(restitutions):
        planes = box_planes(lo, hi, restitution=e)
        model = ParticleModel(np.ones(1), x0.copy(), v0.copy(), np.zeros(1), np.zeros(1, bool),
                              gravity=np.array([0.0, -G, 0.0]), planes=planes, dimension=2)
        run = _simulate(ParticleSystem(model, passes_for(model)), "lecture", t_end, dt)
        x, v = _split(run, 1)
        axes[0].plot(x[:, 0, 0], x[:, 0, 1], color=SCENE_COLOURS[k], linewidth=1.5, label=f"k_r = {e:g}")
        bounces = _bounces(x[:, 0], v[:, 0], planes, near=0.05)
        for _, p, vb, va in bounces:
            n = planes[p].normal
            measured.append((k, -(vb @ n), va @ n, np.linalg.norm((va - (va @ n) * n) - (vb - (vb @ n) * n))))
        if diagram is None and e < 1:
            floor = next(b for b in bounces if b[1] == 2)
            diagram = (floor[2], floor[3], planes[2].normal, e)
    ax = axes[0]
    ax.plot(*x0[0, :2], "o", color="black", markersize=5, label="start")
    ax.plot([lo[0], hi[0], hi[0], lo[0], lo[0]], [lo[1], lo[1], hi[1], hi[1], lo[1]], color="black",
            linewidth=2)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m, up)")
    ax.set_title(f"A particle in a 2 m box under gravity, {t_end:g} s\n(lecture update, dt = "
                 f"{1000 * dt:g} ms)", fontsize=10)
    _legend_below(ax, ncol=4)

    ax = axes[1]
    if diagram is None:
        raise RuntimeError("bouncing figure: no floor collision to draw")
    vb, va, n, e = diagram
    t_dir = vb - (vb @ n) * n
    t_dir /= np.linalg.norm(t_dir)
    b_t, b_n = vb @ t_dir, vb @ n  # before: along the wall (> 0) and along N (< 0)
    a_t, a_n = va @ t_dir, va @ n
    arrow = {"angles": "xy", "scale_units": "xy", "scale": 1.0, "width": 0.01}
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
    ax.set_title(f"The first floor collision at k_r = {e:g}, velocities from the run:\n"
                 f"{-b_n:.2f} m/s in along N, {a_n:.2f} m/s out (ratio {a_n / -b_n:.3f})", fontsize=10)

    ax = axes[2]
    data = np.array(measured)
    top = 1.1 * data[:, 1].max()
    for k, e in enumerate(restitutions):
        d = data[data[:, 0] == k]
        ax.plot(d[:, 1], d[:, 2], "o", color=SCENE_COLOURS[k], markersize=6,
                label=f"measured, k_r = {e:g} ({len(d)} collisions)")
        ax.plot([0, top], [0, e * top], color=SCENE_COLOURS[k], linewidth=0.9, linestyle=":")
    ax.plot([], [], color="0.3", linewidth=0.9, linestyle=":", label="|V'_N| = k_r |V_N| (the lecture)")
    worst_t = np.max(data[:, 3])
    ax.set_xlabel("normal speed before, −N·V (m/s)")
    ax.set_ylabel("normal speed after, N·V' (m/s)")
    ax.set_title(f"Every collision of the three runs; V_T changed by at most\n{worst_t:.3f} m/s "
                 f"(= g dt, gravity over the step between records)", fontsize=10)
    ax.set_xlim(0, top)
    ax.set_ylim(0, top)
    ax.set_aspect("equal")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper left", fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    _save(fig, path)
    return ('Reproduces the lecture slides "Bouncing off the Walls", "Normal and Tangential '
            'Components", "Collision Detection" and "Collision Response" (coefficient of '
            "restitution): a point particle in a 2 m box of six planes under gravity, for "
            f"k_r = 1, 0.75 and 0.5, stepped by the lecture's update at {1000 * dt:g} ms with the "
            "reference collision pass between steps. Middle: one collision's V, V_N, V_T and "
            "V' = V_T − k_r V_N, taken from the run (before and after are the records either "
            "side of the collision); right: the normal speed after against before for every "
            "collision, on the lines of slope k_r.")


# -- 12. contact: a particle moving along the wall ------------------------------------------------
def fig_contact(path: Path) -> str:
    """A particle dropped onto an inclined wall: bounces, then contact and sliding."""
    angle = np.radians(20.0)
    normal = np.array([-np.sin(angle), np.cos(angle), 0.0])
    down = -np.array([np.cos(angle), np.sin(angle), 0.0])
    plane = Plane(np.zeros(3), normal, restitution=0.5)
    drop, dt, t_end = 0.15, 1e-3, 1.0
    model = ParticleModel(np.ones(1), drop * normal[None, :], np.zeros((1, 3)), np.zeros(1),
                          np.zeros(1, bool), gravity=np.array([0.0, -G, 0.0]), planes=[plane],
                          dimension=2)
    system = ParticleSystem(model, passes_for(model))
    solver = get_solver("lecture")(system)
    n_steps = round(t_end / dt)
    t = np.zeros(n_steps + 1)
    x = np.zeros((n_steps + 1, 3))
    v = np.zeros((n_steps + 1, 3))
    contact = np.zeros(n_steps + 1, bool)
    x[0], v[0] = system.positions[0], system.velocities[0]
    for i in range(1, n_steps + 1):
        solver.step(dt)
        system.between_steps(dt)
        t[i], contact[i] = system.get_time(), system.contact[0, 0]
        x[i], v[i] = system.positions[0], system.velocities[0]
    d, vn, s_down = x @ normal, v @ normal, x @ down
    g_t = G * np.sin(angle)
    exact = 0.5 * g_t * t**2
    first = int(np.argmax(contact))
    held = bool(contact[first:].all())

    fig = plt.figure(figsize=(15, 5.6))
    grid = fig.add_gridspec(2, 3, width_ratios=[1.5, 1, 1], hspace=0.08, wspace=0.3, left=0.05,
                            right=0.98, bottom=0.1, top=0.88)
    ax = fig.add_subplot(grid[:, 0])
    span = np.array([-0.3, s_down[-1] + 0.3])
    ax.fill([span[0] * down[0], span[1] * down[0], span[0] * down[0]],
            [span[0] * down[1], span[1] * down[1], span[1] * down[1]], color="0.88", zorder=0)
    ax.plot(span * down[0], span * down[1], color="black", linewidth=1.5)
    ax.plot(x[: first + 1, 0], x[: first + 1, 1], color=SCENE_COLOURS[0], linewidth=1.4,
            label=f"bouncing: collision response, k_r = {plane.restitution:g}")
    ax.plot(x[first:, 0], x[first:, 1], color=SCENE_COLOURS[1], linewidth=4.0, alpha=0.8,
            label=f"in contact from t = {t[first]:.2f} s: sliding along the wall")
    f = np.array([0.0, -G, 0.0])
    fn = (f @ normal) * normal
    sc = 0.04
    lo_x, hi_x = span[1] * down[0] - 0.05, span[0] * down[0] + 0.05
    q = np.array([lo_x + 0.3 * (hi_x - lo_x), 0.4, 0.0])  # free space above the wall
    ax.plot(*np.stack([q - 0.3 * down, q + 0.3 * down])[:, :2].T, color="black", linewidth=0.8,
            linestyle="--")
    arrow = {"angles": "xy", "scale_units": "xy", "scale": 1.0, "width": 0.007, "zorder": 5}
    ax.quiver(*q[:2], *(sc * f[:2]), color="black", **arrow)
    ax.quiver(*q[:2], *(sc * fn[:2]), color=SCENE_COLOURS[2], **arrow)
    ax.quiver(*q[:2], *(sc * (f - fn)[:2]), color=SCENE_COLOURS[3], **arrow)
    ax.plot(*q[:2], "o", color=SCENE_COLOURS[1], markersize=7, zorder=6)
    ax.annotate("F = m g", q[:2] + sc * f[:2] + np.array([-0.03, -0.02]), fontsize=10, ha="right")
    ax.annotate("F_N: the wall cancels it", q[:2] + sc * fn[:2] + np.array([0.04, -0.02]),
                fontsize=10, color=SCENE_COLOURS[2])
    ax.annotate("F' = F_T", q[:2] + sc * (f - fn)[:2] + np.array([-0.04, 0.03]), fontsize=10,
                color=SCENE_COLOURS[3], ha="right")
    ax.annotate("forces on the particle in contact\n(dashed: parallel to the wall)",
                q[:2] + np.array([0.0, 0.1]), fontsize=9, ha="center")
    ax.set_xlim(lo_x, hi_x)
    ax.set_ylim(span[1] * down[1] - 0.05, 0.75)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m, up)")
    ax.set_title(f"A point dropped {drop:g} m onto a frictionless {np.degrees(angle):.0f}° wall\n"
                 f"(force arrows for m = 1 kg, {sc:g} m per N)", fontsize=10)
    ax.legend(loc="lower right", fontsize=8, frameon=False)

    ax_d = fig.add_subplot(grid[0, 1])
    ax_v = fig.add_subplot(grid[1, 1], sharex=ax_d)
    ax_d.plot(t, 1000 * d, color=SCENE_COLOURS[0], linewidth=1.3)
    ax_v.plot(t, vn, color=SCENE_COLOURS[2], linewidth=1.3)
    for a_ in (ax_d, ax_v):
        a_.axvspan(t[first], t[-1], color=SCENE_COLOURS[1], alpha=0.15)
        a_.axhline(0.0, color="0.5", linewidth=0.6)
        a_.grid(True, alpha=0.3)
    ax_d.text(t[first] + 0.02, 0.85 * 1000 * d.max(), "contact:\n(X − P)·N = 0\nN·V = 0",
              fontsize=9, va="top")
    ax_d.set_ylabel("(X − P)·N (mm)")
    ax_v.set_ylabel("N·V (m/s)")
    ax_v.set_xlabel("time (s)")
    ax_d.tick_params(labelbottom=False)
    ax_d.set_title("On the wall, moving along the wall", fontsize=10)

    ax = fig.add_subplot(grid[:, 2])
    ax.plot(t, exact, label="exact: ½ g sin θ t²", **_exact_style())
    ax.plot(t, s_down, color=SCENE_COLOURS[1], linewidth=1.8, label="reference run")
    err = np.max(np.abs(s_down - exact))
    ax.axvspan(t[first], t[-1], color=SCENE_COLOURS[1], alpha=0.15)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("distance down the slope (m)")
    ax.set_title(f"Along the wall: a = g sin θ = {g_t:.2f} m/s² throughout\n"
                 f"(largest deviation from exact {err:.0e} m)", fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper left", fontsize=8, frameon=False)
    _save(fig, path)
    kept = "and stays in contact to the end" if held else "(contact is not kept to the end)"
    return ('Reproduces the lecture slides "Conditions for Contact" and "Contact Force" '
            "(F' = F_T: the wall pushes back, cancelling the normal component of F): a point "
            f"mass dropped onto a frictionless plane inclined at {np.degrees(angle):.0f}° "
            f"(k_r = {plane.restitution:g}), stepped by the lecture's update at {1000 * dt:g} ms. "
            f"Its bounces shrink until, at t = {t[first]:.2f} s, it is on the wall, moving along "
            f"it and pushing against it; the reference contact pass then holds its normal "
            f"distance and velocity at zero and the force becomes F_T, so it slides with "
            f"a = g sin θ, {kept}. Neither the collisions nor the contact touch the tangential "
            "motion, which follows ½ g sin θ t² throughout.")


# -- all of them -------------------------------------------------------------------------------------
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
