"""The lecture's figures on springs and dampers: the damped spring, the spring-damper pair.

Scenes: the library cases ``harmonic-oscillator`` and ``damped-oscillator`` and
``cases/figures/stretched-spring-pair.toml``, run by the reference adapter
(:mod:`truestep.figures.scenes`) and drawn against their cases' exact solutions. Each
``fig_*`` function draws one figure into the PNG ``path`` and returns its caption.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from truestep.cases.exact import EXACT
from truestep.figures.scenes import figure_case, library_case, run_reference
from truestep.figures.style import SCENE_COLOURS, exact_style, legend_below, reference_style, save_figure

OSCILLATOR_CASES = ("harmonic-oscillator", "damped-oscillator")
"""The library cases of the damped-spring figure: undamped, then damped."""
OSCILLATOR_METHOD, OSCILLATOR_STEP = "rk4", 4e-3
"""Method and step (s) of the damped-spring figure."""
PAIR_METHOD = "rk4"
"""Method of the spring-damper pair figure (at its case's step)."""


def decay_rate(t: np.ndarray, x: np.ndarray) -> float:
    """Exponential decay rate (1/s) of an oscillation's amplitude: the slope of the log of
    its local maxima against time (least squares). ``t``, ``x`` : shape (T,)."""
    peak = np.flatnonzero((x[1:-1] > x[:-2]) & (x[1:-1] >= x[2:]) & (x[1:-1] > 0)) + 1
    peak = np.concatenate([[0], peak]) if x[0] > x[1] else peak
    return float(-np.polyfit(t[peak], np.log(x[peak]), 1)[0])


# -- 5. undamped against damped spring ------------------------------------------------------------
def fig_springs(path: Path) -> str:
    """The harmonic-oscillator and damped-oscillator cases: position and energy."""
    method, dt = OSCILLATOR_METHOD, OSCILLATOR_STEP
    cases = [library_case(name) for name in OSCILLATOR_CASES]
    fig, axes = plt.subplots(2, 2, figsize=(11, 6.4), sharex=True, sharey="row")
    measured = []
    for col, case in enumerate(cases):
        traj = run_reference(case, method, dt)
        assert case.exact is not None and traj.energy is not None  # the library's oscillators
        exact = EXACT[case.exact](case, traj.t)
        x = traj.x[:, 0, 0]
        measured.append((traj.energy, decay_rate(traj.t, x), np.max(np.abs(traj.x - exact.x))))
        axes[0, col].plot(
            traj.t,
            x,
            markevery=25,
            label=f"reference / {method}, dt = {dt:g} s",
            **reference_style(method, linewidth=1.6),
        )
        axes[0, col].plot(traj.t, exact.x[:, 0, 0], label="exact", **exact_style())
        axes[1, col].plot(
            traj.t,
            traj.energy,
            markevery=25,
            label=f"reference / {method}",
            **reference_style(method, linewidth=1.6),
        )
        axes[1, col].plot(traj.t, exact.energy, label="exact", **exact_style())
        a = case.particles.anchors
        axes[0, col].set_title(
            f"{case.title} (case {case.name})\nk_s = {a.stiffness[0]:g} N/m, k_d = {a.damping[0]:g} N s/m",
            fontsize=10,
        )
        axes[1, col].set_xlabel("time (s)")
    axes[0, 0].set_ylabel("position x (m)")
    axes[1, 0].set_ylabel("total energy (J)")
    for ax in axes.ravel():
        ax.grid(True, alpha=0.3)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=2, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    save_figure(fig, path)
    m = cases[0].particles
    (e_free, _, err_free), (e_damped, rate, err_damped) = measured
    out = float(np.linalg.norm(m.x0[0] - m.anchors.point[0]) - m.anchors.rest[0])
    return (
        'Reproduces the lecture slides "Damper" ("Un-damped spring" beside a damped one): '
        f"the cases {' and '.join(c.name for c in cases)} ({m.mass[0]:g} kg on an anchored "
        f"spring, released {out:g} m out), run by the reference {method.upper()} at dt = "
        f"{1000 * dt:g} ms against their exact solutions (largest deviation {err_free:.0e} and "
        f"{err_damped:.0e} m). Undamped, the energy stays at {e_free[0]:.3g} J (to "
        f"{np.max(np.abs(e_free / e_free[0] - 1)):.0e} relative); the damper removes "
        f"{100 * (1 - e_damped[-1] / e_damped[0]):.0f} % of it in {cases[1].duration:g} s and "
        f"the amplitude decays as e^(−{rate:.2f} t)."
    )


# -- 6. spring-damper pair -----------------------------------------------------------------------
def _undamped(case):
    """The case with every spring's damper removed."""
    springs = replace(case.particles.springs, damping=np.zeros_like(case.particles.springs.damping))
    return replace(case, scene=replace(case.particles, springs=springs))


def fig_spring_damper_pair(path: Path) -> str:
    """Two free masses on one spring-damper, with and without the damper."""
    damped = figure_case("stretched-spring-pair")
    m, s = damped.particles, damped.particles.springs
    m1, m2, k_s, rest = m.mass[0], m.mass[1], s.stiffness[0], s.rest[0]
    stretch = float(np.linalg.norm(m.x0[1] - m.x0[0]) - rest)
    fig, axes = plt.subplots(1, 2, figsize=(12, 5.0))
    kept = {}
    for k, case in enumerate((damped, _undamped(damped))):
        k_d = case.particles.springs.damping[0]
        traj = run_reference(case, PAIR_METHOD)
        x = traj.x
        exact = EXACT[case.exact](case, traj.t).x
        length = np.linalg.norm(x[:, 1] - x[:, 0], axis=1)
        exact_length = np.linalg.norm(exact[:, 1] - exact[:, 0], axis=1)
        worst = np.max(np.abs(length - exact_length))
        late = traj.t >= traj.t[-1] - 1.0
        kept[k_d] = np.max(np.abs(length[late] - rest)) / stretch
        axes[1].plot(
            traj.t,
            length,
            markevery=25,
            label=f"reference / {PAIR_METHOD}, k_d = {k_d:g} N s/m (deviation from exact ≤ {worst:.0e} m)",
            **reference_style(PAIR_METHOD, k, 2, linewidth=1.6),
        )
        if k == 0:
            com = (m1 * x[:, 0, 0] + m2 * x[:, 1, 0]) / (m1 + m2)
            com_moved = np.max(
                np.linalg.norm(
                    (m1 * x[:, 0] + m2 * x[:, 1]) / (m1 + m2) - (m1 * x[0, 0] + m2 * x[0, 1]) / (m1 + m2),
                    axis=1,
                )
            )
            axes[1].plot(
                traj.t, exact_length, label="exact (reduced mass μ = m1 m2 / (m1 + m2))", **exact_style()
            )
            axes[0].plot(
                traj.t, x[:, 0, 0], color=SCENE_COLOURS[0], linewidth=1.5, label=f"p1, m1 = {m1:g} kg"
            )
            axes[0].plot(
                traj.t, x[:, 1, 0], color=SCENE_COLOURS[1], linewidth=1.5, label=f"p2, m2 = {m2:g} kg"
            )
            axes[0].plot(traj.t, com, color="black", linewidth=1.0, label="centre of mass")
            for i in range(2):
                axes[0].plot(traj.t, exact[:, i, 0], label="exact" if i == 0 else None, **exact_style())
    axes[1].axhline(rest, color="0.5", linewidth=0.8, linestyle=":", label="rest length L_r")
    axes[0].set_title(f"Positions along x, k_s = {k_s:g} N/m, k_d = {s.damping[0]:g} N s/m")
    axes[0].set_ylabel("position x (m)")
    axes[1].set_title("Spring length L_c = |p2 − p1|")
    axes[1].set_ylabel("length (m)")
    for ax in axes:
        ax.set_xlabel("time (s)")
        ax.grid(True, alpha=0.3)
    legend_below(axes[0], ncol=2)
    legend_below(axes[1], ncol=1)
    fig.tight_layout()
    save_figure(fig, path)
    (k_d, damped_left), (_, free_left) = kept.items()
    return (
        'Reproduces the lecture slide "Spring-Damper Pair": two free point masses '
        f"({m1:g} kg and {m2:g} kg) joined by the lecture's spring-damper "
        "f = (k_s (L_c − L_r) + k_d (ṗ2 − ṗ1)·u) u, u = (p2 − p1)/|p2 − p1| (the damper's sign "
        "taken so that it resists the change of length, as the damped-spring slide writes it), "
        f"released {stretch:g} m stretched. Reference {PAIR_METHOD.upper()} at dt = "
        f"{1000 * damped.dts[0]:g} ms against the exact solution; the centre of mass moves by "
        f"at most {com_moved:.0e} m. In the last second the stretch is at most "
        f"{100 * damped_left:.1g} % of the initial one with the damper (k_d = {k_d:g} N s/m) and "
        f"{100 * free_left:.0f} % without it (k_d = 0)"
        + (": the undamped pair oscillates on at full amplitude." if free_left > 0.99 else ".")
    )
