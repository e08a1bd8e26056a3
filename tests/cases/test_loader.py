"""Hostile case files get one short, clean error naming the file and the field; the cost
of a case is checked before anything is built; computations on case data end in rows.

Each case below is a shipped case file with one thing changed, the way a user's typo,
a generator's bug or a hostile file would change it.
"""

from __future__ import annotations

import re
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from truestep.cases.errors import CaseError
from truestep.cases.limits import DEFAULT, parse_override
from truestep.cases.loader import CASE_DIR, load_case

FREE_FALL = (CASE_DIR / "free-fall.toml").read_text()
CHAIN = (CASE_DIR / "spring-chain.toml").read_text()
CLOTH = (CASE_DIR / "hanging-cloth.toml").read_text()
FOUNTAIN = (CASE_DIR / "particle-fountain.toml").read_text()
RAIN = (CASE_DIR / "particle-rain.toml").read_text()
ROPE = (CASE_DIR / "rope-pendulum.toml").read_text()
ENCOUNTER = (CASE_DIR / "close-encounter.toml").read_text()
BALL = (CASE_DIR / "bouncing-ball.toml").read_text()


def _sub(text: str, pattern: str, new: str) -> str:
    out, n = re.subn(pattern, new, text, count=1, flags=re.M)
    assert n == 1, f"{pattern!r} not found"
    return out


def _scene(text: str, extra: str) -> str:
    """``extra`` TOML placed just after the ``[scene]`` table's first lines."""
    return _sub(text, r"^\[scene\]\n", "[scene]\n" + extra + "\n")


HOSTILE = {
    "nan dt": (_sub(FREE_FALL, r"^dt = .*$", "dt = [nan]"), "run.dt", "finite"),
    "inf tolerance": (
        _sub(FREE_FALL, r"^tolerances = .*$", "tolerances = [inf]"),
        "run.tolerances",
        "finite",
    ),
    "tolerance below float64": (
        _sub(FREE_FALL, r"^tolerances = .*$", "tolerances = [1e-300]"),
        "run.tolerances",
        "1e-14",
    ),
    "non-finite quick_dt": (
        _sub(FREE_FALL, r"^quick_dt = .*$", "quick_dt = [-inf]"),
        "run.quick_dt",
        "finite",
    ),
    "1e8 steps": (_sub(FREE_FALL, r"^dt = .*$", "dt = [1e-8]"), "run.dt", "steps, over the limit"),
    "a step of 1e-12 s": (_sub(FREE_FALL, r"^dt = .*$", "dt = [1e-12]"), "run.dt", "below the smallest"),
    "timeout 1e300": (
        _sub(FREE_FALL, r"^duration = .*$", "duration = 1.0\ntimeout = 1e300"),
        "run.timeout",
        "at most",
    ),
    "huge integer": (
        _sub(FREE_FALL, r"^duration = .*$", "duration = 1.0\nmax_records = " + "9" * 400),
        "run.max_records",
        "digits",
    ),
    "integer beyond the digit limit": (FREE_FALL + "\nx = " + "9" * 5000 + "\n", "<toml>", "digits"),
    "number beyond float range": (
        _scene(FREE_FALL, "drag = " + "9" * 400),
        "scene.drag",
        "beyond the range of a float",
    ),
    "deep nesting": (FREE_FALL + "\nx = " + "[" * 3000 + "]" * 3000 + "\n", "<toml>", "nested"),
    "moderate nesting": (FREE_FALL + "\nx = " + "[" * 100 + "]" * 100 + "\n", "<toml>", "nested"),
    "truncated": (FREE_FALL[: FREE_FALL.index("[run]") + 4], "<toml>", ""),
    "unknown top-level key": (FREE_FALL + "\nbogus = 1\n", "bogus", "unknown field"),
    "unknown reference key": (
        _sub(FREE_FALL, r"^exact = .*$", 'exact = "uniform-gravity"\nrtol = 1e-9'),
        "reference.rtol",
        "unknown field",
    ),
    "wrong-kind exact solution": (
        _sub(FREE_FALL, r"^exact = .*$", 'exact = "kepler"'),
        "reference.exact",
        "ode cases",
    ),
    "bounces = []": (_sub(BALL, r"^bounces = .*$", "bounces = []"), "reference.bounces", "integer"),
    "rtol = 1e-300": (_sub(ENCOUNTER, r"^rtol = .*$", "rtol = 1e-300"), "reference.exact", "rtol"),
    "zero plane normal": (
        _scene(FREE_FALL, "planes = [{ point = [0, 0, 0], normal = [0, 0, 0] }]"),
        "scene.planes[0].normal",
        "non-zero",
    ),
    "denormal plane normal": (
        _scene(FREE_FALL, "planes = [{ point = [0, 0, 0], normal = [0, 1e-320, 0] }]"),
        "scene.planes[0].normal",
        "non-zero",
    ),
    "vortex centre of strings": (
        _scene(FREE_FALL, 'fields = [{ kind = "vortex", strength = 1.0, center = ["a", "b", "c"] }]'),
        "scene.fields[0].center",
        "shape",
    ),
    "vortex without strength": (
        _scene(FREE_FALL, 'fields = [{ kind = "vortex" }]'),
        "scene.fields[0].strength",
        "missing",
    ),
    "unknown field parameter": (
        _scene(FREE_FALL, 'fields = [{ kind = "wind", direction = [1, 0, 0], gale = 3 }]'),
        "scene.fields[0].gale",
        "unknown",
    ),
    "zero wind direction": (
        _scene(FREE_FALL, 'fields = [{ kind = "wind", direction = [0, 0, 0] }]'),
        "scene.fields[0].direction",
        "non-zero",
    ),
    "dangling spring": (_sub(CHAIN, r"^pairs = .*$", "pairs = [[0, 99]]"), "pairs", "out of range"),
    "fractional spring index": (_sub(CHAIN, r"^pairs = .*$", "pairs = [[0.5, 1]]"), "pairs", "integers"),
    'fixed = "yes"': (
        _sub(FREE_FALL, r"^mass = .*$", 'mass = [1.0, 0.5, 2.0]\nfixed = "yes"'),
        "scene.particles[0].fixed",
        "true, false",
    ),
    "3000 x 3000 cloth": (
        _sub(_sub(CLOTH, r"^rows = .*$", "rows = 3000"), r"^cols = .*$", "cols = 3000"),
        "scene.meshes[0].rows",
        "particles, over the limit",
    ),
    "1e8-particle rope": (
        _sub(ROPE, r"^count = .*$", "count = 100000000"),
        "scene.meshes[0].count",
        "particles, over the limit",
    ),
    "1e12-particle block": (
        _sub(RAIN, r"^count = .*$", "count = 1000000000000"),
        "scene.blocks[0].count",
        "particles, over the limit",
    ),
    "1e12 emitter pool": (
        _sub(FOUNTAIN, r"^capacity = .*$", "capacity = 1000000000000"),
        "scene.emitters[0].capacity",
        "particles, over the limit",
    ),
    "emitter rate 1e300": (
        _sub(FOUNTAIN, r"^rate_n = .*$", "rate_n = 1e300"),
        "scene.emitters[0].rate_n",
        "per frame",
    ),
    "gate step not swept": (
        FREE_FALL + '\n[[gates]]\nkind = "error"\nmethod = "rk4"\ndt = 0.123\nmax = 1\n',
        "dt",
        "not a step or tolerance",
    ),
    "unknown property": (
        FREE_FALL.replace('family = "particles"', 'family = "particles"\nproperties = ["nope"]'),
        "properties",
        "not one of",
    ),
    "100 kB description": (
        FREE_FALL.replace('kind = "particles"', 'kind = "particles"\n').replace(
            'title = "', 'hard = "' + "x" * 100_000 + '"\ntitle = "', 1
        ),
        "hard",
        "characters",
    ),
    "a long unknown key": (FREE_FALL + "\n" + "k" * 5000 + " = 1\n", "kkk", "unknown field"),
}


@pytest.mark.parametrize("label", list(HOSTILE))
def test_a_hostile_case_file_is_one_short_clean_error(tmp_path: Path, label: str) -> None:
    text, field, reason = HOSTILE[label]
    path = tmp_path / "hostile-case.toml"
    path.write_text(text)
    started = time.perf_counter()
    with pytest.raises(CaseError) as err:
        load_case(path)
    message = str(err.value)
    assert time.perf_counter() - started < 10.0
    assert message.startswith(f"{path}: "), message
    assert field in err.value.field, message
    assert reason in err.value.reason, message
    assert "\n" not in message and len(message) <= 300 + len(str(path)), message


@pytest.mark.parametrize("raw", [b'title = "\xff\xfe"\n', b"\x00\x01\x02binary", b"\xef\xbb\xbf\xc3("])
def test_bytes_that_are_not_utf8_toml_are_one_clean_error(tmp_path: Path, raw: bytes) -> None:
    path = tmp_path / "binary-case.toml"
    path.write_bytes(raw)
    with pytest.raises(CaseError) as err:
        load_case(path)
    assert err.value.field == "<toml>" and "\n" not in str(err.value)


def test_a_directory_or_a_huge_file_is_refused_before_it_is_read(tmp_path: Path) -> None:
    folder = tmp_path / "folder.toml"
    folder.mkdir()
    with pytest.raises(CaseError, match="is a directory"):
        load_case(folder)
    huge = tmp_path / "huge.toml"
    with huge.open("wb") as fh:
        fh.truncate(17 * 2**20)  # sparse: nothing is written, nothing should be read
    with pytest.raises(CaseError, match="MiB"):
        load_case(huge)


def test_a_case_raises_its_own_limits_and_the_command_line_sets_them_for_a_run(tmp_path: Path) -> None:
    path = tmp_path / "fine-steps.toml"
    path.write_text(_sub(FREE_FALL, r"^dt = .*$", "dt = [1e-8, 0.1, 0.05, 0.02, 0.01]"))  # 1e8 steps
    with pytest.raises(CaseError, match=r"1e\+08 steps, over the limit of 2e\+07"):
        load_case(path)
    path.write_text(
        _sub(FREE_FALL, r"^dt = .*$", "dt = [1e-8, 0.1, 0.05, 0.02, 0.01]")
        + "\n[limits]\nsteps = 200000000\n"
    )
    assert min(load_case(path).dts) == 1e-8
    with pytest.raises(CaseError, match=r"over the limit of 1e\+07"):
        load_case(path, limits={"steps": 1e7})  # the run's --limit has the last word
    path.write_text(FREE_FALL + "\n[limits]\nstesp = 3\n")
    with pytest.raises(CaseError, match=r"limits\.stesp: unknown field"):
        load_case(path)


def test_the_limits_hold_every_shipped_case_and_refuse_the_next_size_up() -> None:
    cases = [load_case(p) for p in sorted(CASE_DIR.glob("*.toml"))]
    biggest = max(c.model.n for c in cases if c.model is not None)
    assert biggest * 10 <= DEFAULT.particles
    assert max(c.duration / min(c.dts) for c in cases) * 10 <= DEFAULT.steps


@pytest.mark.parametrize("item", ["steps", "steps=", "steps=abc", "steps=-1", "steps=inf", "bogus=3"])
def test_a_bad_limit_override_says_what_is_wrong(item: str) -> None:
    with pytest.raises(ValueError, match="--limit"):
        parse_override([item])


def test_memory_of_the_records_is_a_limit(tmp_path: Path) -> None:
    path = tmp_path / "many-records.toml"
    text = _sub(RAIN, r"^max_records = .*$", "max_records = 100000")
    path.write_text(_sub(text, r"^dt = .*$", "dt = [0.00001]"))
    with pytest.raises(CaseError, match="MiB, over the limit"):
        load_case(path, limits={"memory_mb": 100})


def _coincident_bodies(tmp_path: Path) -> Path:
    """Two of the close encounter's bodies in one place: the force is 1/0 at the start."""
    text = _sub(
        ENCOUNTER, r"^position = .*$", "position = [[-1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.05, 0.0]]"
    )
    text = re.sub(r"^\[reference\]\n(.+\n)+", "", text, flags=re.M)
    text = re.sub(r"^\[\[gates\]\]\n(.+\n)+", "", text, flags=re.M)
    path = tmp_path / "coincident.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize("engine", ["reference", "scipy"])
def test_a_state_that_goes_non_finite_is_unstable_at_once_for_every_method(
    tmp_path: Path, engine: str
) -> None:
    """Division by zero in the compiled loops, dopri5, implicit Euler's Newton solve and
    scipy's three methods: each an ``unstable`` run with its time, within a second, not
    an exception (``crashed``) or a wait for the timeout."""
    from truestep.adapters import get_adapter

    case = load_case(_coincident_bodies(tmp_path))
    adapter = get_adapter(engine)
    for method in adapter.methods:
        step = 1e-8 if method in adapter.adaptive_methods else 1e-3
        started = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            traj = adapter.simulate(case, method, step)
        assert traj.status == "unstable", (method, traj.status, traj.message)
        assert traj.t_fail is not None and traj.t_fail <= 0.002 + 1e-12, method
        assert time.perf_counter() - started < 5.0, method


def test_measuring_that_hangs_is_that_case_s_timeout_rows(monkeypatch) -> None:
    """An exact solution that never returns (a stand-in for a reference run at an absurd
    tolerance) times out that row at the case's limit; later rows of the case say so at
    once; the run goes on."""
    import dataclasses

    from truestep.adapters import get_adapter
    from truestep.execution import runner

    case = dataclasses.replace(load_case(CASE_DIR / "free-fall.toml"), timeout_s=0.5)
    traj = get_adapter("reference").simulate(case, "euler", 0.1)

    def never(*args, **kwargs):
        while True:
            np.sum(np.arange(10))

    monkeypatch.setattr(runner, "measure", never)
    monkeypatch.setattr(runner, "_MEASURE_TIMED_OUT", {})
    started = time.perf_counter()
    first = runner.row_from(case, "reference", "euler", 0.1, adaptive=False, outcome=traj)
    second = runner.row_from(case, "reference", "euler", 0.05, adaptive=False, outcome=traj)
    assert first["status"] == second["status"] == "timeout"
    assert "longer than 0.5 s" in first["message"]
    assert time.perf_counter() - started < 3.0


def test_a_property_of_another_scene_kind_is_refused_when_the_case_loads(tmp_path: Path) -> None:
    """Properties declare the kind of case they read (every one: particles): an ODE case
    naming one is refused at load, naming the field, not a crashed row at run time."""
    text = (CASE_DIR / "circle-field.toml").read_text()
    path = tmp_path / "circle-with-strain.toml"
    path.write_text(text.replace('kind = "ode"', 'kind = "ode"\nproperties = ["max_strain"]', 1))
    with pytest.raises(CaseError, match=r"properties: 'max_strain' is a property of particles cases"):
        load_case(path)


ENERGY_DRIFT_GATE = '\n[[gates]]\nkind = "energy_drift"\nmethod = "rk4"\ndt = {dt}\nmax = 1e-3\n'


@pytest.mark.parametrize(
    ("name", "dt", "warned"),
    [
        ("bouncing-ball", 0.002, True),  # dissipative contact; its exact bounce gives no energy
        ("hanging-cloth", 0.004, True),  # damped; a reference run gives no energy curve
        ("damped-oscillator", 0.002, False),  # damped; its closed form gives the energy curve
        ("harmonic-oscillator", 0.002, False),  # conservative: drift from the start
    ],
)
def test_an_energy_drift_gate_a_case_never_measures_warns_when_the_case_loads(
    tmp_path: Path, name: str, dt: float, warned: bool
) -> None:
    """Issue 36: a gate a case can never evaluate fails every run; refusing it when the
    case loads would break case files that loaded before, so it warns first (a
    ``FutureWarning``, which Python shows to users) and still loads. The published tables
    say the same: every ok row of the warned cases has no energy drift, and the others'
    have one."""
    import pandas as pd

    text = (CASE_DIR / f"{name}.toml").read_text() + ENERGY_DRIFT_GATE.format(dt=dt)
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        case = load_case(path)
    said = [w for w in seen if issubclass(w.category, FutureWarning)]
    assert case.gates[-1].kind == "energy_drift"
    assert len(said) == int(warned), [str(w.message) for w in said]
    if warned:
        assert f"{case.gates[-1].where}: an energy_drift gate on a case that never measures" in str(
            said[0].message
        )
    published = pd.read_csv(Path(__file__).resolve().parents[2] / "reports" / "results.csv")
    rows = published[(published["case"] == name) & (published["status"] == "ok")]
    assert len(rows) and bool(rows["energy_drift"].notna().any()) is not warned


def test_an_exact_solution_whose_check_never_returns_is_refused_as_a_hang(monkeypatch) -> None:
    """The check that a case's exact solution fits it ends within
    :data:`~truestep.cases.loader.EXACT_CHECK_S` (0.5 s here): one that never returns is
    the case's error, named a hang, not "does not fit"; the library's own checks end far
    inside the limit (the slowest, the million-particle rain, in about a second)."""
    from truestep.cases import loader

    def never(case, t):
        while True:
            np.sum(np.arange(10))

    monkeypatch.setattr(loader, "EXACT_CHECK_S", 0.5)
    monkeypatch.setattr(loader, "exact_named", lambda name: never)
    started = time.perf_counter()
    with pytest.raises(CaseError) as err:
        load_case(CASE_DIR / "free-fall.toml")
    assert time.perf_counter() - started < 5.0
    assert "did not end within 0.5 s (the guard against a check that never returns)" in str(err.value)
    assert "does not fit" not in str(err.value)
