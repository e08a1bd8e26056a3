"""`truestep gate` as CI calls it: gates for any engine, gates files, strictness, baseline
comparison and the CI outputs, on a real quick run whose tables are then altered."""

from __future__ import annotations

import dataclasses
import json
import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import truestep
from truestep.cases.plugins import CASE_DIR
from truestep.cli import main

GATES = """
[[gates]]
cases = "harmonic-*"
kind = "order"
engine = "*"
method = "rk4"
expect = 4.0
tol = 0.15

[[gates]]
cases = ["harmonic-oscillator"]
kind = "error"
engine = "reference"
method = "*"
dt = 1e-3
max = 0.5

[[gates]]
cases = "harmonic-oscillator"
kind = "no-worse-than"
engine = "reference"
method = "verlet"
than = "reference/symplectic-euler"
factor = 1.0

[[gates]]
cases = "harmonic-oscillator"
kind = "stability-limit"
engine = "reference"
method = "verlet"
rel_tol = 0.01
min = 0.19

[[gates]]
kind = "restitution"
engine = "reference"
method = "rk4"
quantity = "e_apex"
tol = 1e-6
"""


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("run")
    assert (
        main(
            ["run", "--quick", "--cases", "harmonic-oscillator", "--engines", "reference", "--out", str(out)]
        )
        == 0
    )
    return out


@pytest.fixture
def copy(run_dir, tmp_path):
    """A copy of the run's tables, to alter into another run's: returns (dir, results). Its
    ``run.json`` keeps no row counts (those of the run copied would refuse the altered
    tables as cut short or changed, :func:`truestep.tables.io.check_recorded_rows`); a test
    that makes the rows another engine's records that engine (:func:`_record_engines`)."""
    dest = tmp_path / "copy"
    shutil.copytree(run_dir, dest, ignore=shutil.ignore_patterns("figures", "index.*"))
    record = json.loads((dest / "run.json").read_text())
    record.pop("rows", None)
    (dest / "run.json").write_text(json.dumps(record))
    return dest, pd.read_csv(dest / "results.csv")


def _record_engines(d: Path, *engines: str) -> None:
    """Make the ``run.json`` of ``d`` name ``engines``, as a run of them would."""
    record = json.loads((d / "run.json").read_text())
    record["engines"] = list(engines)
    (d / "run.json").write_text(json.dumps(record))


def _gates_file(tmp_path: Path, text: str = GATES) -> str:
    path = tmp_path / "gates.toml"
    path.write_text(text)
    return str(path)


def test_gates_file_for_any_engine_with_wildcards(run_dir, tmp_path, capsys):
    code = main(["gate", "--results", str(run_dir / "results.csv"), "--gates", _gates_file(tmp_path), "-v"])
    out = capsys.readouterr().out
    assert code == 0, out
    assert "ok   harmonic-oscillator/order/reference/rk4#2 (gates[0] of gates.toml)" in out
    # `method = "*"` with a dt: every method that ran that step (adaptive ones did not)
    expanded = [line for line in out.splitlines() if "/error/reference/" in line and "(gates[1]" in line]
    assert len(expanded) == 8 and not any("dopri5" in line for line in expanded)
    assert "FAIL" not in out
    assert (
        "harmonic-oscillator/no-worse-than/reference/verlet/error-vs-reference/symplectic-euler (gates[2]"
        in out
    )
    assert "restitution-sweep/restitution/reference/rk4/e_apex (gates[4]" in out


def test_strict_nothing_evaluated_fails(copy, capsys):
    d, results = copy
    results[results["engine"] == "reference"].assign(engine="someone-else").to_csv(
        d / "results.csv", index=False
    )
    _record_engines(d, "someone-else")
    code = main(["gate", "--results", str(d / "results.csv")])
    out = capsys.readouterr().out
    assert code == 1
    assert "FAIL nothing was checked: no gate was evaluated" in out


def test_a_gated_row_that_crashed_fails_the_gate(copy, capsys):
    d, results = copy
    hit = (results["method"] == "verlet") & (results["dt"] == 1e-3)
    results["message"] = results["message"].astype(object)
    results.loc[hit, "status"] = "crashed"
    results.loc[hit, "message"] = "engine process died (exit code -11)"
    results.to_csv(d / "results.csv", index=False)
    code = main(["gate", "--results", str(d / "results.csv")])
    out = capsys.readouterr().out
    assert code == 1
    assert (
        "FAIL harmonic-oscillator/order/reference/verlet (gates[5] of harmonic-oscillator.toml): "
        "measured row dt=0.001 crashed" in out
    )
    assert "FAIL harmonic-oscillator/energy_drift/reference/verlet@0.001 (gates[8]" in out


def test_a_cases_item_that_matches_nothing_exits_2(run_dir, capsys):
    code = main(
        [
            "gate",
            "--results",
            str(run_dir / "results.csv"),
            "--cases",
            "harmonic-oscillator,harmonic-oscilator",
        ]
    )
    err = capsys.readouterr().err
    assert code == 2 and "no case matches 'harmonic-oscilator'" in err
    assert main(["run", "--cases", "free-fall,nosuch-*", "--out", "/nonexistent"]) == 2
    assert "no case matches 'nosuch-*'" in capsys.readouterr().err


def test_junit_markdown_and_json_outputs(run_dir, tmp_path, monkeypatch, capsys):
    summary = tmp_path / "step-summary.md"
    summary.write_text("earlier step\n")
    monkeypatch.setenv("GITHUB_STEP_SUMMARY", str(summary))
    junit, md, js = tmp_path / "j.xml", tmp_path / "s.md", tmp_path / "g.json"
    code = main(
        [
            "gate",
            "--results",
            str(run_dir / "results.csv"),
            "--gates",
            _gates_file(tmp_path),
            "--junit",
            str(junit),
            "--markdown",
            str(md),
            "--json",
            str(js),
            "--baseline",
            str(run_dir),
        ]
    )
    capsys.readouterr()
    assert code == 0
    doc = json.loads(js.read_text())
    root = ET.parse(junit).getroot()
    assert root.tag == "testsuites"
    suites = {s.get("name"): s for s in root.iter("testsuite")}
    cases = suites["truestep.ci.gates"].findall("testcase")
    assert len(cases) == int(suites["truestep.ci.gates"].get("tests")) == len(doc["gates"])
    assert {c.get("classname") for c in cases} >= {"harmonic-oscillator", "restitution-sweep"}
    assert suites["truestep.ci.baseline"].get("failures") == "0"
    assert doc["passed"] is True and doc["counts"]["fail"] == 0
    assert doc["baseline"]["compared"] > 0 and doc["baseline"]["findings"] == []
    assert md.read_text().startswith("### truestep gate: passed")
    assert summary.read_text().startswith("earlier step\n### truestep gate: passed")


def _json_gates(run_dir: Path, gates_file: str, out: Path, cwd: Path, monkeypatch) -> list[dict]:
    monkeypatch.chdir(cwd)
    code = main(
        ["gate", "--results", str(run_dir / "results.csv"), "--gates", gates_file, "--json", str(out)]
    )
    assert code == 0
    return json.loads(out.read_text())["gates"]


def test_json_gates_carry_numbers_stable_ids_and_relative_paths(run_dir, tmp_path, monkeypatch, capsys):
    """Numbers are JSON numbers (the measured value and the gate's limits), paths are
    relative to the working directory, and a verdict's id names what it checks: the
    same when the gates file lists its gates in another order."""
    gates = _json_gates(run_dir, _gates_file(tmp_path), tmp_path / "a.json", tmp_path, monkeypatch)
    capsys.readouterr()
    for g in gates:
        assert isinstance(g["dt"], float | None) and isinstance(g["value"], float | None)
        assert all(isinstance(v, float | int | str | list) for v in g["limits"].values())
        assert g["source"] == "gates.toml" or g["source"] == str(CASE_DIR / "harmonic-oscillator.toml")
    order = next(g for g in gates if g["kind"] == "order" and g["method"] == "rk4")
    assert order["id"] == "harmonic-oscillator/order/reference/rk4"
    assert order["limits"] == {"expect": 4.0, "tol": 0.15} and abs(order["value"] - 4.0) < 0.15
    # the order measured by another route: the slope of log error against log dt
    rows = pd.read_csv(run_dir / "results.csv").query(
        "method == 'rk4' and dt_kind == 'step' and status == 'ok'"
    )
    slope = np.polyfit(np.log(rows["dt"]), np.log(rows["error"]), 1)[0]
    assert abs(order["value"] - slope) < 0.3
    assert len({g["id"] for g in gates}) == len(gates)
    blocks = GATES.strip().split("\n\n")
    (tmp_path / "sub").mkdir()
    reordered = _gates_file(tmp_path / "sub", "\n\n".join(reversed(blocks)))
    again = _json_gates(run_dir, reordered, tmp_path / "b.json", tmp_path, monkeypatch)
    capsys.readouterr()
    assert {g["id"]: g["value"] for g in gates} == {g["id"]: g["value"] for g in again}
    assert "sub/gates.toml" in {g["source"] for g in again}


def test_a_gate_may_name_its_own_id(run_dir, tmp_path, monkeypatch, capsys):
    named = GATES.replace('method = "rk4"\nexpect = 4.0', 'method = "rk4"\nid = "rk4-order"\nexpect = 4.0', 1)
    gates = _json_gates(run_dir, _gates_file(tmp_path, named), tmp_path / "n.json", tmp_path, monkeypatch)
    capsys.readouterr()
    assert "harmonic-oscillator/rk4-order/reference/rk4" in {g["id"] for g in gates}
    bad = named.replace('id = "rk4-order"', 'id = "rk4 order!"')
    code = main(["gate", "--results", str(run_dir / "results.csv"), "--gates", _gates_file(tmp_path, bad)])
    assert code == 2 and "gates[0].id" in capsys.readouterr().err


def test_baseline_lists_worse_better_appeared_and_vanished(run_dir, copy, capsys):
    d, results = copy
    rk4 = (results["method"] == "rk4") & (results["dt"] == 1e-3)
    results.loc[rk4, "error"] *= 2.0  # worse
    heun = (results["method"] == "heun") & (results["dt"] == 1e-3)
    results.loc[heun, "error"] *= 0.5  # better
    euler = (results["method"] == "euler") & (results["dt"] == 2e-3)
    results.loc[euler, "status"] = "unstable"  # ok -> unstable: a regression
    results = results[~((results["method"] == "lecture") & (results["dt"] == 2e-3))]  # vanished
    results.to_csv(d / "results.csv", index=False)
    code = main(["gate", "--results", str(d / "results.csv"), "--baseline", str(run_dir), "-v"])
    out = capsys.readouterr().out
    assert code == 1
    assert "WORSE  results harmonic-oscillator reference rk4 dt=0.001 error:" in out
    assert "better results harmonic-oscillator reference heun dt=0.001 error:" in out
    assert "WORSE  results harmonic-oscillator reference euler dt=0.002 status: ok -> unstable" in out
    assert "GONE   results harmonic-oscillator reference lecture dt=0.002" in out
    assert "WORSE  orders harmonic-oscillator reference rk4 order:" in out
    # a tolerance wide enough for a doubled error lets that row pass
    code = main(
        [
            "gate",
            "--results",
            str(d / "results.csv"),
            "--baseline",
            str(run_dir),
            "--tolerance",
            "error=1.5",
            "-q",
        ]
    )
    out = capsys.readouterr().out
    assert "reference rk4 dt=0.001 error" not in out


def test_baseline_wall_time_only_as_a_ratio_in_the_same_run(run_dir, copy, capsys):
    d, results = copy
    base = d.parent / "base"
    shutil.copytree(d, base)
    results["wall_s"] = 0.001 * (1 + np.arange(len(results)) % 7)  # timings well above the timer's noise
    results.to_csv(base / "results.csv", index=False)
    results["wall_s"] *= 10.0  # a slower machine: every ratio is unchanged
    results.to_csv(d / "results.csv", index=False)
    args = ["gate", "--results", str(d / "results.csv"), "--baseline", str(base), "-q"]
    assert main([*args, "--time-against", "reference/rk4"]) == 0
    assert "timed on" not in capsys.readouterr().out
    for folder, cpu in ((base, "Intel(R) Xeon(R) Processor"), (d, "AMD EPYC")):  # another CPU: said
        record = json.loads((folder / "run.json").read_text())
        record["machine"] = {"cpu": cpu, "architecture": "x86_64", "cores": 2, "system": "Linux 6.1"}
        (folder / "run.json").write_text(json.dumps(record))
    assert main([*args, "--time-against", "reference/rk4"]) == 0
    assert (
        "--time-against: the baseline was timed on Intel(R) Xeon(R) Processor (x86_64), 2 cores, "
        "Linux 6.1, this run on AMD EPYC (x86_64), 2 cores, Linux 6.1"
    ) in capsys.readouterr().out
    euler = results["method"] == "euler"
    results.loc[euler, "wall_s"] *= 3.0  # euler three times slower relative to rk4
    results.to_csv(d / "results.csv", index=False)
    assert main([*args, "--time-against", "reference/rk4"]) == 1
    assert "WORSE  timing harmonic-oscillator reference euler" in capsys.readouterr().out
    assert main(args) == 0  # without --time-against wall time is not compared
    capsys.readouterr()


def test_bad_gate_inputs_exit_2(run_dir, tmp_path, capsys):
    bad = _gates_file(
        tmp_path, '[[gates]]\nkind = "order"\nengine = "nosuch"\nmethod = "x"\nexpect = 1.0\ntol = 0.1\n'
    )
    assert main(["gate", "--results", str(run_dir / "results.csv"), "--gates", bad]) == 2
    assert "gates[0].engine: unknown engine 'nosuch'" in capsys.readouterr().err
    bad = _gates_file(tmp_path, '[[gates]]\nkind = "no-worse-than"\nmethod = "x"\nthan = "rk4"\n')
    assert main(["gate", "--results", str(run_dir / "results.csv"), "--gates", bad]) == 2
    assert "gates[0].than: expected 'engine/method'" in capsys.readouterr().err
    assert (
        main(
            [
                "gate",
                "--results",
                str(run_dir / "results.csv"),
                "--baseline",
                str(run_dir),
                "--tolerance",
                "speed=2",
            ]
        )
        == 2
    )
    assert "--tolerance: expected QUANTITY=NUMBER" in capsys.readouterr().err


def test_an_exact_solution_that_does_not_fit_fails_at_load(tmp_path, capsys):
    case = tmp_path / "bent-spring.toml"
    case.write_text("""
kind = "particles"
[scene]
[[scene.particles]]
position = [[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]]
mass = 1.0
[[scene.springs]]
pairs = [[0, 1]]
stiffness = 10.0
rest = 0.5
[run]
duration = 1.0
dt = [0.01]
[reference]
exact = "linear"
""")
    assert main(["run", "--cases", str(case), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert f"{case}: reference.exact: 'linear' does not fit this case" in err
    assert "zero-rest-length springs" in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()


def test_cases_by_file_and_directory_and_the_python_api(tmp_path):
    from truestep.cases.loader import CASE_DIR

    mine = tmp_path / "my-cases"
    mine.mkdir()
    shutil.copy(CASE_DIR / "circle-field.toml", mine / "my-circle.toml")
    shutil.copy(CASE_DIR / "free-fall.toml", tmp_path / "my-fall.toml")
    cases = truestep.load_cases(f"{mine},{tmp_path / 'my-fall.toml'},harmonic-*")
    assert [c.name for c in cases] == ["my-circle", "my-fall", "harmonic-oscillator"]
    tables = truestep.run(cases[:2], ["reference"], quick=True, analyses=False, progress=lambda _: None)
    assert set(tables.results["case_source"]) == {
        str(mine / "my-circle.toml"),
        str(tmp_path / "my-fall.toml"),
    }
    verdicts = truestep.check(tables)
    assert set(verdicts["verdict"]) == {"pass"} and len(verdicts) > 5
    same = truestep.compare(tables, tables)
    assert same.empty
    with pytest.raises(truestep.SelectionError, match="no such case file"):
        truestep.load_cases(str(tmp_path / "missing.toml"))


def test_declared_orders_are_gated_on_request(run_dir, monkeypatch, capsys):
    """--declared-orders gates every fixed-step method's fit against its declared order;
    a method declaring an order it does not reach fails its gate."""
    args = ["gate", "--results", str(run_dir / "results.csv"), "--declared-orders", "-v", "-q"]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "ok   harmonic-oscillator/order/reference/rk4/declared (declared" in out
    from truestep.reference_impl.solvers import RK4

    monkeypatch.setattr(RK4, "facts", dataclasses.replace(RK4.facts, order=5))
    assert main(args) == 1
    assert (
        "FAIL harmonic-oscillator/order/reference/rk4/declared (declared): measured order 3.99"
        in capsys.readouterr().out
    )
    monkeypatch.setattr(RK4, "facts", dataclasses.replace(RK4.facts, order=3))
    assert main(args) == 0  # delivering more than it declares holds


def test_identical_names_a_changed_cell_of_a_row_that_did_not_run():
    """A restitution row of a method the sweep leaves out has no drop or bounce (NaN): a
    changed note there is one ``differs`` finding with a readable key, not a traceback."""
    from truestep.ci.baseline import identical

    row = {"engine": "scipy", "method": "RK45", "dt": np.nan, "e_set": np.nan, "bounce": np.nan}
    old = pd.DataFrame([{**row, "status": "unsupported", "note": "old words"}])
    new = pd.DataFrame([{**row, "status": "unsupported", "note": "new words"}])
    findings, cells = identical({"restitution": old}, {"restitution": new})
    assert cells > 0 and [(f.change, f.quantity) for f in findings] == [("differs", "note")]
    assert "scipy RK45" in findings[0].key and "nan" not in findings[0].key


def test_a_gate_the_baseline_evaluated_cannot_go_unevaluated(run_dir, copy, capsys):
    """A planted bug that makes rk4 converge to the wrong motion (its error stuck at one
    value at every step, as a 1 % rest-length error leaves it): alone, the declared-order
    gate cannot fit an order and is not evaluated; against a baseline that evaluated it,
    the gate fails and says what the baseline measured (issue 35: gates cannot skip a bug)."""
    d, results = copy
    rk4 = (results["method"] == "rk4") & (results["dt_kind"] == "step")
    results.loc[rk4, "error"] = results.loc[rk4, "error"].max()
    results.to_csv(d / "results.csv", index=False)
    main(["gate", "--results", str(d / "results.csv"), "--declared-orders", "-v"])
    alone = [line for line in capsys.readouterr().out.splitlines() if "declared" in line and "/rk4" in line]
    assert alone and all(line.startswith("SKIP") for line in alone), alone
    code = main(
        ["gate", "--results", str(d / "results.csv"), "--declared-orders", "--baseline", str(run_dir)]
    )
    out = capsys.readouterr().out
    assert code == 1
    failed = [line for line in out.splitlines() if "declared" in line and "/rk4" in line]
    assert failed and all(
        line.startswith("FAIL") and "where the baseline measured order" in line for line in failed
    )
    code = main(
        ["gate", "--results", str(run_dir / "results.csv"), "--declared-orders", "--baseline", str(run_dir)]
    )
    assert code == 0, capsys.readouterr().out


def test_a_run_unstable_where_its_facts_say_stable_fails_its_declared_order(copy, capsys):
    """A planted bug that makes symplectic Euler blow up on the harmonic oscillator (a
    damper's sign flipped pumps energy in): its sweep has no order to fit, and where a run
    is unstable at a step its facts make stable on this linear scene (2 / omega = 0.2 s:
    k = 100 N/m on 1 kg) the declared-order gate fails, saying so,
    without a baseline. Unstable only above that limit, the gate stays not evaluated."""
    from truestep.cases import load_case
    from truestep.cases.exact import stability_limit

    d, results = copy
    case = load_case(CASE_DIR / "harmonic-oscillator.toml")
    exact = stability_limit(case, "symplectic-euler")
    omega = np.sqrt(float(case.model.anchors.stiffness[0]) / float(case.model.mass[0]))
    assert omega == 10.0 and exact == pytest.approx(2 / omega, rel=1e-12)
    steps = results[(results["method"] == "symplectic-euler") & (results["dt_kind"] == "step")]
    assert len(steps) >= 2 and steps["dt"].max() < exact
    results.loc[steps.index, ["status", "error"]] = ["unstable", np.nan]
    results.to_csv(d / "results.csv", index=False)
    code = main(["gate", "--results", str(d / "results.csv"), "--declared-orders", "-v"])
    out = capsys.readouterr().out
    line = next(x for x in out.splitlines() if "order/reference/symplectic-euler/declared" in x)
    assert code == 1 and line.startswith("FAIL"), out
    assert f"unstable at dt {steps['dt'].min():.6g} s, where its facts say it is stable" in line
    assert f"steps up to {exact:.6g} s" in line
    results.loc[steps.index, "dt"] = steps["dt"] * 1000  # every run above the exact limit
    results.to_csv(d / "results.csv", index=False)
    main(["gate", "--results", str(d / "results.csv"), "--declared-orders", "-v"])
    line = next(x for x in capsys.readouterr().out.splitlines() if "reference/symplectic-euler/decl" in x)
    assert line.startswith("SKIP"), line


def test_declared_orders_of_an_engine_that_cannot_be_read_here_fail_and_module_class_reads_them(copy, capsys):
    """``--declared-orders`` on a run of an engine not registered here (an adapter run by
    ``module:Class``) used to make no gate for it, silently; it now fails, naming the
    engine and what to do, and ``--engines module:Class`` reads its facts."""
    d, results = copy
    results.assign(engine="mystery").to_csv(d / "results.csv", index=False)
    _record_engines(d, "mystery")
    code = main(["gate", "--results", str(d / "results.csv"), "--declared-orders", "-q"])
    out = capsys.readouterr().out
    assert code == 1
    assert "FAIL --declared-orders: engine mystery ran, but its declared orders cannot be read" in out
    assert "--engines module:Class" in out
    results.to_csv(d / "results.csv", index=False)
    _record_engines(d, "reference")
    spec = "truestep.adapters.reference:ReferenceAdapter"
    code = main(["gate", "--results", str(d / "results.csv"), "--declared-orders", "--engines", spec, "-v"])
    out = capsys.readouterr().out
    assert code == 0 and "ok   harmonic-oscillator/order/reference/rk4/declared" in out, out
    assert main(["gate", "--results", str(d / "results.csv"), "--engines", "nowhere.mod:Cls"]) == 2
    assert "--engines: engine 'nowhere.mod:Cls'" in capsys.readouterr().err


def _with_engine_of_mine(d: Path, results: pd.DataFrame) -> pd.DataFrame:
    """The run's rows, and the same rows again as engine ``mine`` (a user's engine), as
    if the run had been asked for both."""
    mine = results.assign(engine="mine")
    both = pd.concat([results, mine], ignore_index=True)
    both.to_csv(d / "results.csv", index=False)
    record = json.loads((d / "run.json").read_text())
    record["engines"] = [*record["engines"], "mine"]
    (d / "run.json").write_text(json.dumps(record))
    return both


NO_WORSE_MINE = """
[[gates]]
cases = "harmonic-oscillator"
kind = "no-worse-than"
engine = "mine"
method = "verlet"
than = "reference/symplectic-euler"
factor = 1.0
"""


def test_engines_keeps_the_rows_its_gates_compare_with(copy, tmp_path, capsys):
    """``--engines mine`` (issue 36, item 2): the verdicts are mine's, and a no-worse-than
    gate of mine still reads the reference rows it compares with (it was "not run" and
    exit 0, comparing nothing)."""
    d, results = copy
    _with_engine_of_mine(d, results)
    gates = _gates_file(tmp_path, NO_WORSE_MINE)
    code = main(["gate", "--results", str(d / "results.csv"), "--gates", gates, "--engines", "mine", "-v"])
    out = capsys.readouterr().out
    assert code == 0, out
    assert "ok   harmonic-oscillator/no-worse-than/mine/verlet/" in out
    assert "not run" not in out
    # the reference's own gates are not this scope's verdicts
    assert " reference/" not in out.replace("than reference/", "").replace("x reference/", "")


def test_time_against_an_engine_outside_engines_still_reads_its_rows(copy, run_dir, capsys):
    """``--time-against reference/rk4 --engines mine``: mine's wall times are divided by
    the reference's rk4 of the same case and step, in both runs (it compared 0 rows and
    said nothing); a time-against comparison that compares no ratio fails, saying so."""
    d, results = copy
    results["wall_s"] = 0.001 * (1 + np.arange(len(results)) % 7)  # timings well above the timer's noise
    both = _with_engine_of_mine(d, results)
    base = d.parent / "base"
    shutil.copytree(d, base)
    args = ["gate", "--results", str(d / "results.csv"), "--baseline", str(base), "--engines", "mine", "-v"]
    assert main([*args, "--time-against", "reference/rk4"]) == 0  # A/A
    capsys.readouterr()
    slower = (both["engine"] == "mine") & (both["method"] == "euler")
    both.loc[slower, "wall_s"] *= 3.0
    both.to_csv(d / "results.csv", index=False)
    assert main([*args, "--time-against", "reference/rk4"]) == 1
    assert "WORSE  timing harmonic-oscillator mine euler" in capsys.readouterr().out
    assert main([*args, "--time-against", "nobody/rk4"]) == 1
    assert "--time-against nobody/rk4: no wall-time ratio compared" in capsys.readouterr().out


def test_a_baseline_comparison_that_compares_nothing_fails(copy, run_dir, capsys):
    """A baseline none of whose rows are in this run's scope (another engine's) compared
    nothing: exit 1, saying so, even though the cases' gates held."""
    d, _ = copy
    for name in ("results", "stability", "restitution"):
        table = pd.read_csv(d / f"{name}.csv")
        table.assign(engine="other").to_csv(d / f"{name}.csv", index=False)
    _record_engines(d, "other")
    code = main(["gate", "--results", str(run_dir / "results.csv"), "--baseline", str(d), "-q"])
    out = capsys.readouterr().out
    assert code == 1, out
    assert "FAIL the baseline comparison compared nothing" in out


ID_STAR = """
[[gates]]
cases = "harmonic-oscillator"
id = "too-high"
kind = "order"
engine = "reference"
method = "*"
expect = 9.0
tol = 0.1
"""


def test_one_id_per_verdict_in_every_output_and_the_same_bytes_twice(run_dir, tmp_path, monkeypatch, capsys):
    """A gate with an ``id`` and ``method = "*"`` (issue 36, item 3): each verdict is
    ``case/id/engine/method``, the same on the console, in markdown, JUnit and JSON (it
    was ``case/id#2`` in JUnit and ``gates[0]`` on the console); two calls write the same
    bytes."""
    monkeypatch.chdir(tmp_path)
    gates = _gates_file(tmp_path, ID_STAR)
    outputs = []
    for k in (1, 2):
        args = [
            "gate",
            "--results",
            str(run_dir / "results.csv"),
            "--gates",
            gates,
            "--baseline",
            str(run_dir),
        ]
        args += ["--junit", f"j{k}.xml", "--json", f"g{k}.json", "--markdown", f"m{k}.md"]
        assert main(args) == 1
        outputs.append(capsys.readouterr().out)
    assert outputs[0] == outputs[1]
    for name in ("j", "g", "m"):
        ext = {"j": "xml", "g": "json", "m": "md"}[name]
        assert (tmp_path / f"{name}1.{ext}").read_bytes() == (tmp_path / f"{name}2.{ext}").read_bytes()
    mine = {
        g["id"] for g in json.loads((tmp_path / "g1.json").read_text())["gates"] if "/too-high/" in g["id"]
    }
    assert "harmonic-oscillator/too-high/reference/rk4" in mine and len(mine) >= 8
    junit = {c.get("name") for c in ET.parse(tmp_path / "j1.xml").iter("testcase")}
    console = {line.split()[1] for line in outputs[0].splitlines() if line.startswith("FAIL harmonic")}
    markdown = {
        line.split("|")[1].strip().replace("\\", "")
        for line in (tmp_path / "m1.md").read_text().splitlines()
        if "/too-high/" in line
    }
    assert mine <= junit and mine == {i for i in console if "/too-high/" in i} == markdown
    assert "hostname" not in (tmp_path / "j1.xml").read_text()


def test_two_gate_processes_write_the_same_bytes_whatever_the_hash_seed(run_dir, copy, tmp_path):
    """Rows gone since the baseline were listed in the order of a set of strings, which
    moves with Python's hash seed: two identical ``gate`` calls wrote 4 different JSON
    files (issue 36, item 3). Now the tables' order decides."""
    import os
    import subprocess
    import sys

    d, results = copy
    results.iloc[::2].to_csv(d / "results.csv", index=False)  # half the rows vanish
    texts = []
    for seed in ("1", "2"):
        out = tmp_path / f"g{seed}.json"
        more = ["-q", "--baseline", str(run_dir), "--json"]
        done = subprocess.run(
            [sys.executable, "-m", "truestep", "gate", "--results", str(d / "results.csv"), *more, str(out)],
            env={**os.environ, "PYTHONHASHSEED": seed},
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert done.returncode == 1, done.stderr
        texts.append((done.stdout, out.read_bytes()))
    assert texts[0] == texts[1]
    assert texts[0][0].count("GONE") >= 5


def test_timing_against_a_baseline_reads_both_runs_noise(run_dir, copy, capsys):
    """``--time-against`` (issue 36, item 6): the same solver run twice moved microsecond
    timings two-fold, and the ratios of a whole case with them (the named run timed at 5 us,
    then 2 us): a tie within both runs' noise (at least 15% and 1 us a timing), not
    "slower". A row three times slower at 10 ms is worse."""
    d, results = copy
    base = d.parent / "base"
    shutil.copytree(d, base)
    old = results.copy()
    old["wall_s"], old["wall_s_spread"] = 5e-6, np.nan
    old.to_csv(base / "results.csv", index=False)
    new = old.copy()
    new.loc[new["method"] == "rk4", "wall_s"] = 2e-6  # the named run alone got faster
    new.to_csv(d / "results.csv", index=False)
    args = ["gate", "--results", str(d / "results.csv"), "--baseline", str(base), "-q"]
    assert main([*args, "--time-against", "reference/rk4"]) == 0, capsys.readouterr().out
    old["wall_s"] = 0.01
    old.to_csv(base / "results.csv", index=False)
    new = old.copy()
    slower = (new["method"] == "euler") & (new["dt"] == new["dt"].max())
    new.loc[slower, "wall_s"] = 0.03
    new.to_csv(d / "results.csv", index=False)
    assert main([*args, "--time-against", "reference/rk4"]) == 1
    out = capsys.readouterr().out
    assert out.count("WORSE  timing") == 1 and "reference euler" in out
    # repeats spread past their median (half-IQR 1.5 s at a median 1 s): the ratio of 100 is
    # known to a factor 2.5, not to within 0 of the baseline's 1, so it is still worse
    new.loc[slower, ["wall_s", "wall_s_spread"]] = [1.0, 1.5]
    new.to_csv(d / "results.csv", index=False)
    assert main([*args, "--time-against", "reference/rk4"]) == 1
    out = capsys.readouterr().out
    assert out.count("WORSE  timing") == 1 and "reference euler" in out


def test_a_gates_file_gate_that_matches_no_case_shows_and_a_missing_property_is_refused(
    run_dir, tmp_path, capsys
):
    """Issue 37, item 10: a gates-file gate whose ``cases`` match no case of the run was
    dropped without a word (exit 0, "0 not evaluated"): it is now a verdict not evaluated,
    and alone it fails the strict check. A property gate on a case named outright that
    does not measure that property is refused (exit 2), not judged."""
    typo = _gates_file(
        tmp_path,
        '[[gates]]\ncases = "harmonic-osc"\nkind = "error"\nengine = "reference"\nmethod = "rk4"\n'
        "dt = 1e-3\nmax = 1.0\n",
    )
    args = ["gate", "--results", str(run_dir / "results.csv"), "--gates", typo]
    assert main([*args, "--cases", "harmonic-oscillator"]) == 0  # the case's own gates held
    out = capsys.readouterr().out
    assert "SKIP harmonic-osc/error/reference/rk4@0.001" in out and "no case of this run matches" in out
    lacking = _gates_file(
        tmp_path,
        '[[gates]]\ncases = "harmonic-oscillator"\nkind = "property"\nname = "max_penetration"\n'
        'engine = "reference"\nmethod = "rk4"\ndt = 1e-3\nmax = 1.0\n',
    )
    assert main(["gate", "--results", str(run_dir / "results.csv"), "--gates", lacking]) == 2
    err = capsys.readouterr().err
    assert "gates[0].name" in err and "not a property of harmonic-oscillator" in err


def test_an_energy_drift_gate_on_a_case_that_never_measures_it_says_so(tmp_path, capsys):
    """Issue 36, item 2: an ``energy_drift`` gate on bouncing-ball (dissipative contact, no
    exact energy curve) failed every run with "measured nan"; it fails saying the case never
    measures it. (Refusing it when the case loads would break gates files that loaded
    before: that comes with a deprecation first.)"""
    from pathlib import Path

    published = Path(__file__).resolve().parents[2] / "reports" / "results.csv"
    gates = _gates_file(
        tmp_path,
        '[[gates]]\ncases = "bouncing-ball"\nkind = "energy_drift"\nengine = "reference"\n'
        'method = "rk4"\ndt = 0.002\nmax = 1e-3\n',
    )
    assert (
        main(["gate", "--results", str(published), "--cases", "bouncing-ball", "--gates", gates, "-q"]) == 1
    )
    out = capsys.readouterr().out
    assert "measured nothing: energy_drift is never measured on this case" in out


def test_declared_orders_of_an_engine_not_installed_here_are_read_from_its_run(copy, capsys):
    """Issue 38, item 2: the facts a run recorded in its ``run.json`` (``method_facts``) make
    the declared-order gates of an engine the judging machine does not have: the same
    verdicts as where it is installed, and a run unstable where its recorded facts say it is
    stable still fails (the recorded name resolves to the reference method's whole facts)."""
    from truestep.measures import engine_facts

    d, results = copy
    record = json.loads((d / "run.json").read_text())
    assert record["method_facts"]["reference"]["rk4"] == {"like": "rk4"}
    record["method_facts"]["elsewhere"] = record["method_facts"]["reference"]
    record["engines"] = ["elsewhere"]
    (d / "run.json").write_text(json.dumps(record))
    results.assign(engine="elsewhere").to_csv(d / "results.csv", index=False)
    try:
        code = main(["gate", "--results", str(d / "results.csv"), "--declared-orders", "-v"])
        out = capsys.readouterr().out
        assert code == 0, out
        assert "ok   harmonic-oscillator/order/elsewhere/rk4/declared" in out
        assert "cannot be read" not in out
        steps = results[(results["method"] == "symplectic-euler") & (results["dt_kind"] == "step")]
        planted = results.assign(engine="elsewhere")
        planted.loc[steps.index, ["status", "error"]] = ["unstable", np.nan]
        planted.to_csv(d / "results.csv", index=False)
        code = main(["gate", "--results", str(d / "results.csv"), "--declared-orders", "-v"])
        out = capsys.readouterr().out
        line = next(x for x in out.splitlines() if "order/elsewhere/symplectic-euler/declared" in x)
        assert code == 1 and line.startswith("FAIL") and "where its facts say it is stable" in line, line
    finally:
        engine_facts.RECORDED_FACTS.pop("elsewhere", None)


def test_recorded_facts_values_round_trip():
    """Facts an adapter declares as values (not a reference method's name) are recorded
    and read back equal, infinities included; a damaged entry reads as no facts."""
    from truestep.measures import engine_facts
    from truestep.reference_impl.solvers import MethodFacts
    from truestep.reference_impl.solvers.facts import Stability

    facts = MethodFacts(
        order=3, evaluations_per_step=None, symplectic=False, stability=Stability(2.5, np.inf)
    )
    rec = json.loads(json.dumps(engine_facts._facts_record(facts, facts)))
    assert rec["stability"] == {"imaginary": 2.5, "real": "inf", "a_stable": False}
    back = engine_facts._facts_from(rec)
    assert back == facts and back.stability == facts.stability
    assert engine_facts._facts_from({"order": "x"}) is None
    assert engine_facts._facts_from({"like": "no-such-method"}) is None


def test_every_built_in_engine_s_recorded_facts_read_back_as_its_adapter_declares_them():
    """What ``run.json`` records of each method's facts (through JSON) is what the installed
    adapter declares, the stability region included wherever a reference method's is shared
    (``like``, with the values that differ: Newton's XPBD is implicit Euler at 2 evaluations)."""
    from truestep.adapters import get_adapter
    from truestep.adapters.base import facts_of
    from truestep.measures import engine_facts
    from truestep.reference_impl.solvers import MethodFacts
    from truestep.reference_impl.solvers.facts import NAMED

    engines = ["reference", "scipy", "pymunk", "pybullet", "mujoco", "drake", "mujoco-warp", "newton"]
    recorded = json.loads(json.dumps(engine_facts.record(engines)))
    assert set(recorded["method_facts"]) == set(engines)
    for engine in engines:
        adapter = get_adapter(engine)
        for method in adapter.methods:
            declared = facts_of(adapter, method)
            back = engine_facts._facts_from(recorded["method_facts"][engine][method])
            assert back == declared, (engine, method)
            if declared is not None and declared.stability is not None and back is not None:
                assert back.stability == declared.stability, (engine, method)
    changed = MethodFacts.like("implicit-euler", evaluations_per_step=2)
    rec = engine_facts._facts_record(changed, changed)
    assert rec == {"like": "implicit-euler", "evaluations_per_step": 2}
    back = engine_facts._facts_from(rec)
    assert back == changed and back.stability is NAMED["implicit-euler"].stability


def test_a_limit_on_a_damped_mode_is_read_from_the_run_that_recorded_values(case_named):
    """Issue 38, item 2: facts recorded as values keep no step matrix, so judged where the
    engine is not installed, the limit on a damped mode was unknown and an unstable run
    below it was let through. The run now records the exact limit on each linear case
    (``stability_limits``, from its whole facts), and the verdict reads it: a damped
    oscillator unstable at half its limit fails, as where the engine is installed. The
    limit is recomputed here from the closed form of explicit Euler's damped reach
    (``2 zeta / omega``, where its step matrix's spectral radius reaches 1)."""
    from truestep.cases.exact import linear_modes
    from truestep.ci.gates import _unstable_where_stable
    from truestep.measures import engine_facts
    from truestep.measures.declared import _order_gate
    from truestep.reference_impl.solvers.facts import NAMED, MethodFacts, Stability

    case = case_named("damped-oscillator")
    euler = NAMED["euler"].stability
    assert euler is not None
    facts = MethodFacts(
        order=1,
        evaluations_per_step=1,
        symplectic=False,
        stability=Stability(euler.imaginary, euler.real, step_matrix=euler.step_matrix),
    )
    values = json.loads(json.dumps(engine_facts._facts_record(facts, facts)))
    assert "like" not in values and "step_matrix" not in json.dumps(values)
    limits = json.loads(json.dumps(engine_facts._limits_record(facts, values, [case])))
    omega, zeta = linear_modes(case)
    assert limits == {case.name: pytest.approx(2 * zeta / omega, rel=1e-6)}
    gate = _order_gate("elsewhere-damped", "m", 1)
    rows = pd.DataFrame(
        {"dt": [limits[case.name] / 2], "status": ["unstable"], "dt_kind": ["step"], "error": [np.nan]}
    )
    try:
        engine_facts.take({"method_facts": {"elsewhere-damped": {"m": values}}})
        assert _unstable_where_stable(case, gate, rows) is None  # the values alone: no limit known
        engine_facts.take(
            {"method_facts": {"elsewhere-damped": {"m": values}}},
            {"stability_limits": {"elsewhere-damped": {"m": limits}}},
        )
        verdict = _unstable_where_stable(case, gate, rows)
        assert verdict is not None and not verdict.passed
        assert "where its facts say it is stable" in verdict.measured
    finally:
        engine_facts.RECORDED_FACTS.pop("elsewhere-damped", None)
        engine_facts.RECORDED_LIMITS.pop(("elsewhere-damped", "m", case.name), None)


def test_identical_counts_a_row_that_appeared_once(run_dir, copy, capsys):
    """A row the baseline lacks is one ``appeared`` finding with ``--identical`` as without
    it: the baseline comparison finds it, and the cell-for-cell comparison does not count
    it again (it did, and the summary said twice as many rows appeared as had)."""
    d, results = copy
    results.iloc[1:].to_csv(d / "results.csv", index=False)  # the baseline lacks the first row
    counts = []
    for extra in ([], ["--identical"]):
        main(["gate", "--results", str(run_dir / "results.csv"), "--baseline", str(d), "-v", *extra])
        out = capsys.readouterr().out
        counts.append(int(out.strip().splitlines()[-1].split(" appeared")[0].rsplit(" ", 1)[1]))
        listed = [line for line in out.splitlines() if line.startswith("new ")]
        assert len(listed) == 1 and listed[0].split()[1] == "results", out
    assert counts == [1, 1]
