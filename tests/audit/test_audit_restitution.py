"""The property audit of ``restitution.csv`` (see :mod:`audit_runs`): rebound over
impact speed across each contact found here, apexes the highest samples of the flights
found here, and the impact-phase columns.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from audit_runs import (
    G_FLOOR,
    _close,
    _installed,
    _measured,
    _vertex_check,
    velocity_noise,
)

from truestep.adapters import get_adapter

# -- restitution.csv --------------------------------------------------------------------------

RESTITUTION_RUNS = [(0.5, 1 / 240), (0.8, 1 / 240), (0.0, 1 / 240), (0.8, 1 / 1000)]


def _restitution_params():
    from truestep.execution.analyses import bounce_case

    out = []
    probe = bounce_case(0.5, 1 / 240)
    for engine in ("reference", "pymunk", "pybullet", "mujoco"):
        if not _installed(engine):
            continue
        adapter = get_adapter(engine)
        for method in getattr(adapter, "bounce_methods", None) or adapter.methods:
            if adapter.missing(probe, method) or method in adapter.adaptive_methods:
                continue
            for e, dt in RESTITUTION_RUNS:
                out.append(pytest.param(engine, method, e, dt, id=f"{engine}-{method}-e{e:g}-dt{dt:.3g}"))
    return out


_DROPS: dict[tuple, tuple] = {}


def _drop(engine, method, e, dt, *, phases: bool = False):
    """The restitution table's rows for one drop, and the trajectory they were read from
    (``analyses.get_adapter`` is wrapped to keep it: the engine runs once, unmocked); with
    ``phases``, the impact-phase drops' trajectory (its second run) instead."""
    from truestep.execution import analyses

    key = (engine, method, e, dt)
    if key not in _DROPS:
        kept = []
        real = analyses.get_adapter

        class Keeping:
            def __init__(self, adapter):
                self.adapter = adapter

            def simulate(self, case, method, dt):
                kept.append(self.adapter.simulate(case, method, dt))
                return kept[-1]

        with pytest.MonkeyPatch.context() as patch:
            patch.setattr(analyses, "get_adapter", lambda name: Keeping(real(name)))
            rows = analyses._bounce_rows(engine, method, e, dt)
        assert len(kept) == 2, "one drop, then the impact-phase drops"
        _DROPS[key] = (rows, *kept)
    rows, single, spread = _DROPS[key]
    return rows, (spread if phases else single)


@pytest.mark.engine
@pytest.mark.parametrize(("engine", "method", "e", "dt"), _restitution_params())
def test_restitution_rows(engine, method, e, dt):
    """``e_measured``, ``v_in``, ``v_out``, ``apex``, ``e_apex`` and ``penetration`` of the
    first three bounces of a ball (r = 5 cm) dropped from 1 m, stepped at exactly the
    ``dt`` its rows name: contacts are what lies between the flights found here (free-fall
    kicks above the plane); speeds in and out at the flight samples on either side,
    apexes the highest sample of each flight, ``e_apex = sqrt(H_n / H_(n-1))`` with
    ``H_0`` the highest sample before the first contact."""
    rows, traj = _drop(engine, method, e, dt)
    assert all(r["status"] == "ok" for r in rows), rows
    # the drop takes whole steps of the dt named: every record one step apart, the run
    # a whole number of them (the step is dt to round-off, not duration / round(duration / dt))
    assert np.allclose(np.diff(traj.t), dt, rtol=1e-9, atol=0), "the drop is not stepped at its dt"
    assert abs(traj.t[-1] / dt - round(traj.t[-1] / dt)) <= 1e-9 * traj.t[-1] / dt
    u, w = traj.x[:, 0, 1] - 0.05, traj.v[:, 0, 1]
    drop, found, _ = _measured(traj.t, u, w, engine)
    assert drop == pytest.approx(1.0, abs=1e-12), "a drop from 1 m, from rest"
    _vertex_check(traj.t, u, w, found, 3, f"{engine}/{method} e {e}", velocity_noise(engine, traj.t, u, w))
    kick = G_FLOOR * dt
    apex_prev = drop
    for k, row in enumerate(rows, start=1):
        if k > len(found):
            assert np.isnan(row.get("e_measured", np.nan)), f"bounce {k}: published where none was found"
            continue
        contact = found[k - 1]
        before, after = contact["before"], contact["after"]
        end = len(traj.t) - 1 if after is None else after
        penetration = max(0.0, -float(np.min(u[before : end + 1])))
        # the deepest sample of the contact: the band adds samples above the floor only
        assert _close(row["penetration"], penetration), (
            f"bounce {k}: penetration {row['penetration']:.6f} m, here {penetration:.6f} m"
        )
        v_in = -float(w[before])
        # A flight sample within the table's 1 mm contact band counts as contact there: the
        # sample before or after is then one step further out, where the normal speed
        # differs by one step of gravity, g h; the ratio by g h (1 + e) / v_in.
        assert abs(row["v_in"] - v_in) <= kick * (1 + 1e-9), f"bounce {k}: v_in {row['v_in']} vs {v_in}"
        if after is None:
            # no flight after this contact: the ball stays on the floor (and no more rows)
            assert row["v_out"] == 0.0 and row["apex"] == 0.0, (
                f"bounce {k}: the ball never left the floor here, published v_out {row['v_out']}, "
                f"apex {row['apex']}"
            )
            assert all(np.isnan(r.get("e_measured", np.nan)) for r in rows[k:])
            break
        v_out = float(w[after])
        assert abs(row["v_out"] - v_out) <= kick * (1 + 1e-9), f"bounce {k}: v_out {row['v_out']} vs {v_out}"
        e_here = v_out / v_in
        assert abs(row["e_measured"] - e_here) <= kick * (1 + e_here) / v_in * (1 + 1e-9) + 1e-12, (
            f"bounce {k}: e_measured {row['e_measured']:.5f}, here {e_here:.5f}"
        )
        # the highest sample of the flight: the same sample, by two detectors
        apex = contact["apex"]
        assert _close(row["apex"], apex), (
            f"bounce {k}: apex {row['apex']:.6f} m, highest sample here {apex:.6f} m"
        )
        e_apex = math.sqrt(apex / apex_prev) if apex_prev > 0 else math.nan
        assert _close(row["e_apex"], e_apex), f"bounce {k}: e_apex {row['e_apex']:.6f}, here {e_apex:.6f}"
        apex_prev = apex


@pytest.mark.engine
@pytest.mark.parametrize(("engine", "method", "e", "dt"), _restitution_params())
def test_restitution_phase_columns(engine, method, e, dt):
    """``phases``, ``e_phase_median``, ``e_phase_min`` and ``e_phase_max`` of the first
    bounce row: each ball of the impact-phase drops read here (its first contact between
    the flights found by this file's detector, speeds at the flight samples either side),
    the median and range of those e within the same one-kick allowance as
    ``e_measured``; and the balls' first contacts at most two samples apart (they begin
    at evenly spaced points of one step)."""
    rows, traj = _drop(engine, method, e, dt, phases=True)
    row = rows[0]
    kick = G_FLOOR * dt
    here, starts = [], []
    for k in range(traj.x.shape[1]):
        u, w = traj.x[:, k, 1] - 0.05, traj.v[:, k, 1]
        _, found, _ = _measured(traj.t, u, w, engine)
        if not found:
            continue
        before, after = found[0]["before"], found[0]["after"]
        v_in = -float(w[before])
        here.append(0.0 if after is None else float(w[after]) / v_in)
        starts.append(before)
    assert row["phases"] == len(here) > 0, f"phases {row['phases']}, {len(here)} first bounces here"
    allow = kick * (1 + e) / float(np.sqrt(2 * G_FLOOR)) * (1 + 1e-9) + 1e-12
    for name, mine in (
        ("e_phase_min", min(here)),
        ("e_phase_max", max(here)),
        ("e_phase_median", float(np.median(here))),
    ):
        assert abs(row[name] - mine) <= allow, f"{name} {row[name]:.5f}, here {mine:.5f}"
    assert max(starts) - min(starts) <= 2, "the first contacts span more than a step"
