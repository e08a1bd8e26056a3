"""``truestep baseline save DIR`` (issue 36, item 4): a run kept as a baseline, cell for
cell, with no host name or absolute path in it, and a provenance record: the truestep
that ran it, every engine's version, the project's git revision."""

from __future__ import annotations

import json
import os
import socket
import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import truestep
from truestep.cli import main


@pytest.fixture(scope="module")
def project(tmp_path_factory) -> tuple[Path, Path]:
    """A git checkout with one commit, and a quick run made from it: (root, run folder)."""
    root = tmp_path_factory.mktemp("project")
    for args in (["init", "-q"], ["config", "user.email", "t@t"], ["config", "user.name", "t"]):
        subprocess.run(["git", *args], cwd=root, check=True)
    (root / "solver.py").write_text("STEP = 1\n")
    subprocess.run(["git", "add", "solver.py"], cwd=root, check=True)
    subprocess.run(["git", "commit", "-q", "-m", "one"], cwd=root, check=True)
    out = root / "reports"
    args = ["run", "--quick", "--cases", "harmonic-oscillator", "--engines", "reference", "--out", str(out)]
    assert main(args) == 0
    return root, out


def test_a_saved_baseline_is_the_run_without_host_or_absolute_paths(project, monkeypatch, capsys):
    root, out = project
    monkeypatch.chdir(root)
    assert main(["baseline", "save", "baselines/main", "--results", str(out / "results.csv")]) == 0
    head = subprocess.run(
        ["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True
    ).stdout.strip()
    assert f"project revision {head[:12]}" in capsys.readouterr().out
    saved = root / "baselines" / "main"
    provenance = json.loads((saved / "provenance.json").read_text())
    assert provenance["project"] == {"revision": head, "dirty": False}
    assert provenance["ran_with"] == f"truestep {truestep.__version__}"
    assert provenance["engines"] == {"reference": f"truestep {truestep.__version__}"}
    assert provenance["packages"]["numpy"]
    for path in saved.iterdir():
        text = path.read_text()
        assert str(root) not in text and str(Path.home()) + "/" not in text, path.name
        assert socket.gethostname() not in text.split(","), path.name
    for name in ("results", "stability", "restitution"):
        before = pd.read_csv(out / f"{name}.csv", dtype=str, keep_default_na=False)
        after = pd.read_csv(saved / f"{name}.csv", dtype=str, keep_default_na=False)
        kept = [c for c in before if c not in ("host", "case_source")]
        pd.testing.assert_frame_equal(before[kept], after[kept])
    # the baseline is what a gate compares with, bit for bit
    args = ["gate", "--results", str(out / "results.csv"), "--baseline", str(saved), "--identical", "-q"]
    assert main(args) == 0
    assert ", 0 differ" in capsys.readouterr().out


def test_a_change_since_the_commit_is_recorded_and_a_folder_of_other_files_is_refused(
    project, monkeypatch, capsys
):
    root, out = project
    monkeypatch.chdir(root)
    (root / "solver.py").write_text("STEP = 2\n")
    try:
        assert main(["baseline", "save", "b2", "--results", str(out / "results.csv")]) == 0
        assert json.loads((root / "b2" / "provenance.json").read_text())["project"]["dirty"] is True
        assert "(with changes)" in capsys.readouterr().out
        # saved again over itself: replaced as a whole
        assert main(["baseline", "save", "b2", "--results", str(out / "results.csv")]) == 0
    finally:
        subprocess.run(["git", "checkout", "-q", "solver.py"], cwd=root, check=True)
    other = root / "notes"
    other.mkdir()
    (other / "todo.txt").write_text("keep me")
    capsys.readouterr()
    assert main(["baseline", "save", "notes", "--results", str(out / "results.csv")]) == 2
    err = capsys.readouterr().err
    assert "not a baseline truestep saved" in err and "Traceback" not in err
    assert sorted(p.name for p in other.iterdir()) == ["todo.txt"]


def _worse_rk4(out: Path, dest: Path, factor: float) -> Path:
    """A copy of the run in ``out`` whose rk4 error at its largest step is ``factor`` times
    as large (a regression of one row), in ``dest``."""
    dest.mkdir()
    for name in ("stability.csv", "restitution.csv", "run.json"):
        (dest / name).write_bytes((out / name).read_bytes())
    results = pd.read_csv(out / "results.csv")
    hit = (results["method"] == "rk4") & (results["dt"] == results["dt"].max())
    results.loc[hit, "error"] *= factor
    results.to_csv(dest / "results.csv", index=False)
    return dest


def test_each_regressed_row_is_a_junit_case_and_a_markdown_row_with_its_change(project, tmp_path, capsys):
    """Against a baseline, a row that got worse is a failing JUnit case of its own, and the
    markdown shows by how much, in percent (issue 36, item 4)."""
    import xml.etree.ElementTree as ET

    _, out = project
    worse = _worse_rk4(out, tmp_path / "worse", 1.25)
    junit, md = tmp_path / "j.xml", tmp_path / "s.md"
    args = ["gate", "--results", str(worse / "results.csv"), "--baseline", str(out), "-q"]
    assert main([*args, "--junit", str(junit), "--markdown", str(md)]) == 1
    capsys.readouterr()
    suite = next(
        s for s in ET.parse(junit).getroot().iter("testsuite") if s.get("name") == "truestep.ci.baseline"
    )
    failing = [c for c in suite.iter("testcase") if c.find("failure") is not None]
    assert [c.get("classname") for c in failing] == ["baseline.results"]
    assert failing[0].get("name").startswith("harmonic-oscillator reference rk4 dt=")
    assert suite.get("failures") == "1" and int(suite.get("tests")) == len(list(suite.iter("testcase")))
    row = next(line for line in md.read_text().splitlines() if "reference rk4" in line)
    assert row.rstrip(" |").endswith("+25%")


PLUGIN_TEST = """
import pytest


@pytest.mark.truestep(
    engines="reference",
    cases="harmonic-oscillator",
    quick=True,
    results="{results}",
    baseline="{baseline}",
)
def test_physics(truestep_gate):
    truestep_gate.check()
"""


def _pytest(folder: Path, results: Path, baseline: Path) -> subprocess.CompletedProcess:
    (folder / "test_physics.py").write_text(PLUGIN_TEST.format(results=results, baseline=baseline))
    return _session(folder, "-p", "no:randomly")


def _session(folder: Path, *options: str, env: dict | None = None) -> subprocess.CompletedProcess:
    """``pytest -q -rA`` on the test files in ``folder``, in a process of its own."""
    import sys

    return subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-rA", "-p", "no:cacheprovider", *options, str(folder)],
        cwd=folder,
        capture_output=True,
        text=True,
        timeout=600,
        env=env,
    )


def test_the_pytest_mark_reads_results_and_compares_with_a_baseline(project, tmp_path):
    """``@pytest.mark.truestep(results=..., baseline=...)`` (issue 36, item 4): the gates
    read the run CI has already made (a doctored error shows: nothing ran again), and each
    baseline table is a test of its own, failing with the row that got worse."""
    _, out = project
    saved = tmp_path / "saved"
    assert main(["baseline", "save", str(saved), "--results", str(out / "results.csv")]) == 0
    same = _pytest(tmp_path, out / "results.csv", saved)
    assert same.returncode == 0, same.stdout[-3000:]
    for table in ("results", "orders", "stability", "restitution"):
        assert f"PASSED test_physics.py::test_physics[baseline/{table}]" in same.stdout
    assert "test_physics[harmonic-oscillator/order/reference/rk4]" in same.stdout
    worse = _worse_rk4(out, tmp_path / "worse", 4.0)
    bad = _pytest(tmp_path, worse / "results.csv", saved)
    assert bad.returncode == 1, bad.stdout[-3000:]
    failed = [line for line in bad.stdout.splitlines() if line.startswith("FAILED")]
    assert any("test_physics[baseline/results]" in line for line in failed), bad.stdout[-3000:]
    assert "WORSE  results harmonic-oscillator reference rk4 dt=" in bad.stdout


def test_a_users_folder_in_the_place_a_save_writes_through_is_never_deleted(project, tmp_path):
    """``.DIR.saving`` is where a save writes before it swaps the baseline in: a folder of
    that name that truestep did not write (no marker) is refused, not deleted; one a
    killed save left (its marker in it) is replaced."""
    from truestep.ci.saved import STAGE_MARKER, BaselineRefused, save

    run = project[1]
    theirs = tmp_path / ".kept.saving"
    theirs.mkdir()
    (theirs / "notes.txt").write_text("mine")
    with pytest.raises(BaselineRefused, match="did not write"):
        save(run / "results.csv", tmp_path / "kept")
    assert (theirs / "notes.txt").read_text() == "mine"
    left = tmp_path / ".other.saving"
    left.mkdir()
    (left / STAGE_MARKER).touch()
    save(run / "results.csv", tmp_path / "other")
    assert not left.exists() and (tmp_path / "other" / "results.csv").is_file()


def test_a_marker_item_no_system_can_look_up_is_passed_on_as_a_name(tmp_path):
    """A marker's ``cases=`` item too long for a file name (or with a NUL byte) is no
    path beside the test: it goes on as given, and the loader's one-line error names it,
    not an ``OSError`` traceback from looking for it."""
    from truestep.pytest_plugin import _paths

    assert _paths(["a" * 300, "x\0y"], tmp_path) == ("a" * 300, "x\0y")
    (tmp_path / "mine.toml").write_text("")
    assert _paths("mine.toml, harmonic-oscillator", tmp_path) == (
        str(tmp_path / "mine.toml"),
        "harmonic-oscillator",
    )


DECLARED_TEST = """
import pytest


@pytest.mark.truestep(
    engines="reference", cases="harmonic-oscillator", quick=True, results="{results}", declared_orders=True
)
def test_physics(truestep_gate):
    truestep_gate.check()
"""


def test_the_pytest_mark_gates_declared_orders_on_request(project, tmp_path):
    """``declared_orders=True`` gives the mark ``truestep gate --declared-orders``'s gates, one
    test each (a new user found the mark had no such option): they hold on the run, and the
    rk4 one fails where its error at the larger step is an eighth (an order of 1, not 4)."""
    _, out = project

    def session(results: Path) -> subprocess.CompletedProcess:
        (tmp_path / "test_physics.py").write_text(DECLARED_TEST.format(results=results))
        return _session(tmp_path)

    same = session(out / "results.csv")
    assert same.returncode == 0, same.stdout[-3000:]
    assert (
        "PASSED test_physics.py::test_physics[harmonic-oscillator/order/reference/rk4/declared]"
        in same.stdout
    )
    bad = session(_worse_rk4(out, tmp_path / "first-order", 1 / 8) / "results.csv")
    assert bad.returncode == 1, bad.stdout[-3000:]
    failed = [line for line in bad.stdout.splitlines() if line.startswith("FAILED")]
    assert [line.split(" - ")[0] for line in failed] == [  # the case file's own rk4 gate too
        "FAILED test_physics.py::test_physics[harmonic-oscillator/order/reference/rk4]",
        "FAILED test_physics.py::test_physics[harmonic-oscillator/order/reference/rk4/declared]",
    ], bad.stdout[-3000:]
    assert "measured order 0.995, required >= 4 - 0.25" in bad.stdout


IDENTICAL_TEST = """
import pytest


@pytest.mark.truestep(
    engines="reference", cases="harmonic-oscillator", quick=True,
    {results}baseline="{baseline}", {option}=True,
)
def test_physics(truestep_gate):
    truestep_gate.check()
"""


def _one_ulp_up(out: Path, dest: Path) -> Path:
    """A copy of the run in ``out`` whose rk4 error at its largest step is the next double up."""
    dest.mkdir()
    for name in ("stability.csv", "restitution.csv", "run.json"):
        (dest / name).write_bytes((out / name).read_bytes())
    results = pd.read_csv(out / "results.csv")
    hit = (results["method"] == "rk4") & (results["dt"] == results["dt"].max())
    results.loc[hit, "error"] = np.nextafter(results.loc[hit, "error"].to_numpy(), np.inf)
    results.to_csv(dest / "results.csv", index=False)
    return dest


def test_the_pytest_mark_compares_bit_for_bit_on_request(project, tmp_path):
    """``identical=True`` gives the mark ``truestep gate --identical``'s check as one more
    test, ``baseline/identical`` (a CI that wrote its gates as tests had no way to ask
    for it): it passes on the run the baseline was saved from, and on the same cases run
    in the test session itself (its environment set as the ``truestep`` command sets it);
    it fails on a run one cell of which is one ulp off, printing both doubles in full;
    where the baseline had another scipy it is skipped with that reason under
    ``identical``, and fails under ``require_identical``."""

    from truestep.numerics import environment

    _, out = project
    saved = tmp_path / "saved"
    assert main(["baseline", "save", str(saved), "--results", str(out / "results.csv")]) == 0
    env = {**os.environ, **environment()}

    def session(results: Path | None, baseline: Path, option: str = "identical") -> str:
        folder = tmp_path / f"s{len(list(tmp_path.glob('s*')))}"
        folder.mkdir()
        (folder / "test_physics.py").write_text(
            IDENTICAL_TEST.format(
                results="" if results is None else f'results="{results}", ', baseline=baseline, option=option
            )
        )
        done = _session(folder, "-k", "identical", env=env)
        return f"rc={done.returncode}\n{done.stdout}"

    name = "test_physics.py::test_physics[baseline/identical]"
    same = session(out / "results.csv", saved)
    assert same.startswith("rc=0") and f"PASSED {name}" in same, same[-3000:]
    here = session(None, saved)
    assert here.startswith("rc=0") and f"PASSED {name}" in here, here[-3000:]
    off = session(_one_ulp_up(out, tmp_path / "off") / "results.csv", saved)
    assert off.startswith("rc=1") and f"FAILED {name}" in off, off[-3000:]
    assert "1 of " in off and " non-timing cells differ from the baseline bit for bit" in off
    row = next(line for line in off.splitlines() if line.startswith("DIFFERS results harmonic-oscillator"))
    before, after = row.rsplit(": ", 1)[1].split(" -> ")
    assert float(after) == np.nextafter(float(before), np.inf), row
    record = json.loads((saved / "run.json").read_text())
    record["numerics"]["packages"]["scipy"] = "0.1"
    (saved / "run.json").write_text(json.dumps(record))
    other = session(out / "results.csv", saved)
    assert other.startswith("rc=0") and "SKIPPED" in other, other[-3000:]
    assert "not comparable bit for bit (scipy 0.1 -> " in other
    required = session(out / "results.csv", saved, "require_identical")
    assert required.startswith("rc=1") and f"FAILED {name}" in required, required[-3000:]
    assert "require_identical: not comparable bit for bit (scipy 0.1 -> " in required
