"""Case files: every committed case loads; bad ones name the file, the field and why."""

from __future__ import annotations

import pytest

from truestep.cases import CaseError, case_files, load_case

GOOD = """
kind = "particles"
[scene]
dimension = 2
[[scene.particles]]
position = [[0.1, 0.0, 0.0]]
mass = 1.0
[[scene.anchors]]
particle = 0
point = [0.0, 0.0, 0.0]
stiffness = 100.0
rest = 0.0
[run]
duration = 1.0
dt = [0.01]
"""


@pytest.mark.parametrize("path", case_files(), ids=lambda p: p.stem)
def test_every_case_file_loads(path):
    case = load_case(path)
    assert case.name == path.stem
    assert case.dts and case.duration > 0


def write(tmp_path, text, name="bad-case"):
    p = tmp_path / f"{name}.toml"
    p.write_text(text)
    return p


@pytest.mark.parametrize(
    ("change", "field", "reason"),
    [
        (("mass = 1.0", "mass = -1.0"), "scene.particles[0].mass", "positive"),
        (("duration = 1.0", "duration = 0.0"), "run.duration", "must be positive"),
        (("dt = [0.01]", "dt = [2.0]"), "run.dt", "exceeds the duration"),
        (("stiffness = 100.0", "stiffnes = 100.0"), "scene.anchors[0].stiffness", "missing"),
        (("particle = 0", "particle = 3"), "scene.anchors[0].particle", "out of range"),
        (('kind = "particles"', 'kind = "fluid"'), "kind", "not one of"),
        (("position = [[0.1, 0.0, 0.0]]", "position = [[0.1, 0.0]]"), "scene.particles[0].position", "shape"),
        (("[run]", "[run]\nspeed = 3"), "run.speed", "unknown field"),
        (("dimension = 2", "dimension = 2\ngravity = [0, 0, -9.8]"), "scene.dimension", "z = 0"),
    ],
)
def test_bad_field_names_file_field_and_reason(tmp_path, change, field, reason):
    path = write(tmp_path, GOOD.replace(*change))
    with pytest.raises(CaseError) as err:
        load_case(path)
    assert err.value.file == str(path)
    assert err.value.field == field
    assert reason in err.value.reason
    assert str(err.value).count("\n") == 0


def test_toml_syntax_error_is_a_case_error(tmp_path):
    with pytest.raises(CaseError, match="<toml>"):
        load_case(write(tmp_path, GOOD + "\n[[[ nonsense"))


def test_the_good_case_loads(tmp_path):
    case = load_case(write(tmp_path, GOOD, "good-case"))
    assert case.features == {"point-masses", "2d", "anchored-springs"}
