"""Contact measured over impact phases (issue 35, finding 4): the restitution sweep's rows
carry the range of the first bounce's restitution over :data:`PHASES` drops whose contacts
begin at evenly spaced points of a step, and say where the asked e is not what every
phase gets. Each claim is checked by another route: the drop heights against the free
fall's closed form, a hard contact against the bound its sampling allows, pybullet's
phase dependence against a raw pybullet script, and the report's lines against the
table they read."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from truestep.execution.analyses import _bounce_rows, _phase_values, drop_geometry, phase_case
from truestep.measures.restitution import PHASE_BAND, PHASES, phase_contact
from truestep.reporting.sections import phase_lines, phase_sentence


def test_the_drops_first_touch_the_plane_at_evenly_spaced_points_of_a_step():
    """Free fall from rest, ``h = g t^2 / 2``: ball ``k``'s lowest point reaches the plane
    ``k / PHASES`` of a step after ball 0's, which is the single drop's; the balls stand
    apart along the plane."""
    dt = 1 / 240
    case = phase_case(0.5, dt)
    radius, height, g = drop_geometry()
    model = case.particles
    low = model.x0[:, 1] - radius - model.planes[0].point[1]
    t = np.sqrt(2 * low / g)
    np.testing.assert_allclose((t - t[0]) / dt, np.arange(PHASES) / PHASES, rtol=0, atol=1e-9)
    assert low[0] == pytest.approx(height, rel=1e-15)
    assert np.all(np.diff(model.x0[:, 0]) > 2 * radius) and np.all(model.v0 == 0)
    assert case.duration / dt == pytest.approx(round(case.duration / dt), abs=1e-9)


@pytest.mark.parametrize("e", [0.5, 0.9])
def test_a_hard_contact_gets_the_asked_restitution_at_every_phase(e):
    """The reference's collision pass reflects the normal speed exactly; read from the
    samples either side of the contact, each phase's e errs by at most ``(1 + e) g dt /
    v`` (the speed in read up to a step early, the speed out up to a step late), so the
    row says nothing of phases."""
    dt = 1 / 240
    values, note = _phase_values("reference", "rk4", e, dt)
    _, height, g = drop_geometry()
    bound = (1 + e) * g * dt / np.sqrt(2 * g * height)
    assert values["phases"] == PHASES and note == ""
    assert e - bound <= values["e_phase_min"] <= values["e_phase_max"] <= e + bound


@pytest.mark.engine
def test_pybullet_s_default_contact_depends_on_the_impact_phase_as_raw_pybullet_says():
    """pybullet's ``default`` (multibody contact with a Baumgarte push) at 1 ms, asked 0.5:
    a raw pybullet script of the same drops (its own bodies and calls, the velocities it
    reports the step before and the step after each ball turns) gives 0.16 to 0.55, the
    range the row publishes, and the row says the asked e is not what every phase gets;
    its ``clean`` method stays within the band."""
    import pybullet as p

    dt, e = 1e-3, 0.5
    case = phase_case(e, dt)
    cid = p.connect(p.DIRECT)
    try:
        p.setPhysicsEngineParameter(fixedTimeStep=dt, numSubSteps=0, physicsClientId=cid)
        p.setGravity(0, -9.81, 0, physicsClientId=cid)
        shape = p.createCollisionShape(p.GEOM_SPHERE, radius=0.05, physicsClientId=cid)
        balls = []
        for x in case.particles.x0:
            b = p.createMultiBody(1.0, shape, -1, x.tolist(), physicsClientId=cid)
            p.changeDynamics(  # pybullet's default damping (0.04) off, as in every engine here
                b,
                -1,
                localInertiaDiagonal=[0, 0, 0],
                linearDamping=0.0,
                angularDamping=0.0,
                restitution=1.0,
                lateralFriction=1.0,
                physicsClientId=cid,
            )
            balls.append(b)
        floor = p.createCollisionShape(p.GEOM_PLANE, planeNormal=[0, 1, 0], physicsClientId=cid)
        plane = p.createMultiBody(0.0, floor, -1, [0, 0, 0], physicsClientId=cid)
        p.changeDynamics(plane, -1, restitution=e, lateralFriction=0.0, physicsClientId=cid)
        vy = []
        for _ in range(round(case.duration / dt)):
            p.stepSimulation(physicsClientId=cid)
            vy.append([p.getBaseVelocity(b, physicsClientId=cid)[0][1] for b in balls])
    finally:
        p.disconnect(physicsClientId=cid)
    vy = np.array(vy)
    up = np.argmax(vy > 0, axis=0)
    raw = vy[up, np.arange(PHASES)] / -vy[up - 1, np.arange(PHASES)]
    values, note = _phase_values("pybullet", "default", e, dt)
    assert values["e_phase_min"] == pytest.approx(raw.min(), abs=5e-3)
    assert values["e_phase_max"] == pytest.approx(raw.max(), abs=5e-3)
    assert raw.min() < 0.2 and raw.max() > 0.54 and "not delivered across impact phases" in note
    clean, clean_note = _phase_values("pybullet", "clean", e, dt)
    assert (
        clean_note == "" and e - PHASE_BAND <= clean["e_phase_min"] <= clean["e_phase_max"] <= e + PHASE_BAND
    )


def test_the_first_bounce_row_carries_the_phases_and_the_later_ones_do_not():
    rows = _bounce_rows("reference", "symplectic-euler", 0.8, 1 / 240)
    assert rows[0]["phases"] == PHASES and np.isfinite(rows[0]["e_phase_median"])
    assert all("phases" not in r for r in rows[1:])
    # ball 0 of the phase drops is the single drop: its e lies in the range
    assert rows[0]["e_phase_min"] <= rows[0]["e_measured"] <= rows[0]["e_phase_max"]


def _sweep() -> pd.DataFrame:
    base = {"status": "ok", "bounce": 1, "phases": PHASES}
    return pd.DataFrame(
        [
            {
                **base,
                "engine": "a",
                "method": "m",
                "dt": 1e-3,
                "e_set": 0.5,
                "e_phase_min": 0.49,
                "e_phase_max": 0.51,
            },
            {
                **base,
                "engine": "b",
                "method": "m",
                "dt": 1e-3,
                "e_set": 0.5,
                "e_phase_min": 0.30,
                "e_phase_max": 0.52,
            },
            {
                **base,
                "engine": "b",
                "method": "m",
                "dt": 1e-3,
                "e_set": 0.9,
                "e_phase_min": 0.10,
                "e_phase_max": 0.90,
            },
            {**base, "engine": "b", "method": "m", "dt": 1e-3, "e_set": 0.8, "bounce": 2},
            {
                **base,
                "engine": "c",
                "method": "n",
                "dt": 1e-3,
                "e_set": 0.0,
                "e_phase_min": 0.0,
                "e_phase_max": 0.06,
            },
        ]
    ).assign(e_phase_median=lambda d: 0.5 * (d["e_phase_min"] + d["e_phase_max"]))


def test_rows_off_the_band_are_found_from_their_ranges_farthest_first():
    """``off`` is the farthest end of the range from the asked e, recomputed here; a row
    within :data:`PHASE_BAND` and a later bounce are not listed."""
    found = phase_contact(_sweep())
    assert list(zip(found["engine"], found["e_set"], strict=True)) == [("b", 0.9), ("b", 0.5), ("c", 0.0)]
    np.testing.assert_allclose(found["off"], [0.8, 0.2, 0.06])
    lines = phase_lines(found)
    assert len(lines) == 4 and lines[1].startswith("- b / m: asked 0.9, 0.100 to 0.900")
    assert "2 rows of its sweep leave the band" in lines[1]
    assert phase_lines(phase_contact(_sweep().iloc[:1])) == []


def test_a_contact_case_names_only_the_engines_it_ran(case_named):
    found = phase_contact(_sweep())
    ball = case_named("bouncing-ball")
    shown = pd.DataFrame({"engine": ["c", "a"], "method": ["n", "m"]})
    line = phase_sentence(ball, shown, found)
    assert "impact phase from c / n (the summary" in line and "b / m" not in line
    assert phase_sentence(case_named("harmonic-oscillator"), shown, found) == ""


def test_a_row_on_a_contact_case_says_when_its_contact_law_misses_the_asked_e_at_some_phase():
    """Issue 35, item 4 ("its rows ... say it does not"): each row that ran a contact case
    with an engine and method whose drops leave the band gets the farthest range in its
    message (after what it said already); rows of other cases, of pairs within the band,
    and rows that did not run are left as they are."""
    from truestep.measures.restitution import with_contact_notes

    results = pd.DataFrame(
        [
            ("bouncing-ball", "b", "m", "ok", "Warp CPU device"),
            ("bouncing-ball", "b", "m", "unsupported", "no planes"),
            ("bouncing-ball", "a", "m", "ok", ""),
            ("bouncing-ball", "c", "n", "unstable", np.nan),
            ("harmonic-oscillator", "b", "m", "ok", ""),
        ],
        columns=["case", "engine", "method", "status", "message"],
    )
    with_contact_notes(results, _sweep(), {"bouncing-ball"})
    farthest = (
        "contact law: asked e 0.9 gives 0.100 to 0.900 over the impact phases at dt 0.001 s "
        "(restitution.csv): its error on a contact case is partly its contact law's"
    )
    assert results.loc[0, "message"] == f"Warp CPU device; {farthest}"
    assert results.loc[1, "message"] == "no planes" and results.loc[2, "message"] == ""
    assert results.loc[3, "message"].startswith("contact law: asked e 0 gives 0.000 to 0.060")
    assert results.loc[4, "message"] == ""
