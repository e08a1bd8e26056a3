"""A case file cannot raise its limits past the ceilings (only ``truestep run
--trust-limits --limit`` can), its cost is checked before anything is built in every
form a scene takes, its steps are not absurdly small, and ``truestep.load_case`` judges
its gates exactly as the command line does."""

from __future__ import annotations

import resource
import time
from pathlib import Path

import pytest

from truestep.cases import CaseError, load_case
from truestep.cases.fields import Fields
from truestep.cases.limits import CEILING, KEYS, MIN_STEP_S, parse_override
from truestep.cases.scene import read_scene
from truestep.cli import main

CASE = """kind = "particles"
[scene]
gravity = [0.0, -9.81, 0.0]
[[scene.particles]]
position = [[0.0, 1.0, 0.0]]
mass = 1.0
[run]
duration = {duration}
dt = {dt}
{extra}
"""


def _case(
    tmp_path: Path, *, duration: str = "1.0", dt: str = "[0.01]", extra: str = "", body: str | None = None
) -> Path:
    path = tmp_path / "ceiling-case.toml"
    path.write_text(body or CASE.format(duration=duration, dt=dt, extra=extra))
    return path


@pytest.mark.parametrize("key", KEYS)
def test_a_case_file_cannot_raise_a_limit_past_its_ceiling(tmp_path, key):
    over = getattr(CEILING, key) * 10
    value = int(over) if isinstance(getattr(CEILING, key), int) else over
    with pytest.raises(CaseError, match="over the ceiling") as err:
        load_case(_case(tmp_path, extra=f"[limits]\n{key} = {value}\n"))
    assert err.value.field == f"limits.{key}" and "--trust-limits" in err.value.reason
    at = getattr(CEILING, key)
    load_case(_case(tmp_path, extra=f"[limits]\n{key} = {at}\n"))


def test_only_the_command_line_with_trust_goes_past_a_ceiling(tmp_path, capsys):
    with pytest.raises(ValueError, match="--trust-limits"):
        parse_override(["steps=1e12"])
    assert parse_override(["steps=1e12"], trusted=True) == {"steps": 1e12}
    with pytest.raises(CaseError, match="over the ceiling"):
        load_case(_case(tmp_path), limits={"steps": 1e12})
    assert load_case(_case(tmp_path), limits={"steps": 1e12}, trust_limits=True)
    assert (
        main(
            [
                "run",
                "--quick",
                "--engines",
                "reference",
                "--cases",
                str(_case(tmp_path)),
                "--limit",
                "particles=1e9",
                "--out",
                str(tmp_path / "rep"),
            ]
        )
        == 2
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--trust-limits" in err[0]
    assert not (tmp_path / "rep").exists()


EMITTER = (
    '[[scene.emitters]]\nshape = "cube"\ncenter = [0.0, 0.0, 0.0]\nsize = 0.1\n'
    "rate_n = 1.0\nspeed = 1.0\nlifetime = 2\ncapacity = 4\nframe_dt = {frame_dt}\n"
)


@pytest.mark.parametrize(
    ("change", "field"),
    [
        ({"dt": "[1e-12]", "duration": "1e-9"}, "run.dt"),
        ({"dt": "[1e-300]", "duration": "1e-296"}, "run.duration"),
        ({"extra": "[stability]\nhorizon = 1.0\ndt_lo = 1e-300\ndt_hi = 0.1\n"}, "stability.dt_lo"),
        ({"extra": '[reference]\nexact = "reference-run"\nmethod = "rk4"\ndt = 1e-12\n'}, "reference.dt"),
    ],
)
def test_steps_below_the_smallest_are_refused(tmp_path, change, field):
    with pytest.raises(CaseError) as err:
        load_case(_case(tmp_path, **change))
    assert err.value.field == field and f"{MIN_STEP_S:g}" in err.value.reason


@pytest.mark.parametrize(("frame_dt", "reason"), [("1e-300", "at least"), ("1e-8", "frames")])
def test_an_emitters_frames_count_as_steps(tmp_path, frame_dt, reason):
    body = CASE.format(duration="1.0", dt="[0.01]", extra="").replace(
        "[run]", EMITTER.format(frame_dt=frame_dt) + "[run]"
    )
    with pytest.raises(CaseError, match=reason) as err:
        load_case(_case(tmp_path, body=body))
    assert err.value.field == "scene.emitters[0].frame_dt"


def test_a_dense_exact_solution_of_a_big_scene_is_refused_before_it_is_built(tmp_path):
    body = (
        'kind = "particles"\n[scene]\n[[scene.blocks]]\ncount = 20000\nlow = [0.0, 0.0, 0.0]\n'
        "high = [1.0, 1.0, 1.0]\nmass = 1.0\n[run]\nduration = 1.0\ndt = [0.01]\n"
        '[reference]\nexact = "linear"\n'
    )
    started = time.monotonic()
    with pytest.raises(CaseError, match="at most 1000 particles"):
        load_case(_case(tmp_path, body=body))
    assert time.monotonic() - started < 5.0


def _grown_by(fn) -> float:
    """MiB the peak resident memory of this process grew by while ``fn()`` ran."""
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    fn()
    return (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) / 1024


@pytest.mark.parametrize(
    "scene",
    [
        lambda: {"particles": [{"position": [[0.0, 0.0, 0.0]] * 2_000_000, "mass": 1.0}]},
        lambda: {
            "particles": [
                {"position": [[0.0, 0.0, 0.0]], "mass": 1.0, "velocity": [[0.0, 0.0, 0.0]] * 2_000_000}
            ]
        },
        lambda: {"particles": [{"position": [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]], "mass": [1.0] * 2_000_000}]},
        lambda: {
            "particles": [{"position": [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]], "mass": 1.0}],
            "springs": [{"pairs": [[0, 1]] * 6_000_000, "stiffness": 1.0}],
        },
        lambda: {"gravity": [0.0] * 2_000_000},
    ],
    ids=["positions", "velocities", "masses", "spring pairs", "a vector"],
)
def test_explicit_lists_are_counted_before_an_array_is_built(scene):
    table = scene()

    def read() -> None:
        with pytest.raises(CaseError):
            read_scene(Fields("api", table, "scene"))

    assert _grown_by(read) < 20  # MiB; the arrays would take 48 to 144


def test_load_case_refuses_the_gates_the_command_line_refuses(tmp_path, capsys):
    gates = {
        "a property the case does not name": (
            '[[gates]]\nkind = "property"\nname = "final_speed"\nmethod = "rk4"\ndt = 0.01\nmax = 1.0\n',
            "name",
        ),
        "an unknown engine": (
            '[[gates]]\nkind = "status"\nengine = "nosuch"\nmethod = "rk4"\ndt = 0.01\nexpect = "ok"\n',
            "engine",
        ),
    }
    for text, field in gates.values():
        path = _case(tmp_path, extra=text)
        with pytest.raises(CaseError) as err:
            load_case(path)
        assert err.value.field == f"gates[0].{field}"
        assert main(["list", "--cases", str(path)]) == 2
        assert f"gates[0].{field}" in capsys.readouterr().err
    path = _case(tmp_path, extra=gates["an unknown engine"][0])
    assert load_case(path, engines={"nosuch"}).gates[0].engine == "nosuch"


def test_the_python_api_refuses_gates_on_unknown_engines_as_the_command_line_does(tmp_path):
    import pandas as pd

    import truestep
    from truestep.api import Tables

    tables = Tables(pd.DataFrame({"case": ["free-fall"], "engine": ["mine"]}))
    gate = {"cases": "*", "kind": "order", "engine": "nosuch", "method": "x", "expect": 1.0, "tol": 0.1}
    with pytest.raises(CaseError, match="unknown engine 'nosuch'"):
        truestep.check(tables, gates=[gate])
