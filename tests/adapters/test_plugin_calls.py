"""Calls truestep makes to an adapter in its own process (construction, ``missing``,
``prepare_all``) are plugin code (issue 37, items 5 and 11): one that raises is one line
naming the engine, or ``crashed`` rows with the reason, and the rest of the run goes on."""

from __future__ import annotations

import numpy as np
import pandas as pd

from truestep import adapters
from truestep.adapters.reference import ReferenceAdapter
from truestep.cli import main


class InitRaises(ReferenceAdapter):
    name = "init-raises-test"

    def __init__(self) -> None:
        raise RuntimeError("no licence server")


class MissingRaises(ReferenceAdapter):
    name = "missing-raises-test"
    methods = ("rk4", "euler")
    adaptive_methods = ()

    def missing(self, case, method):
        raise RuntimeError("missing() broke")


class MissingHangs(ReferenceAdapter):
    name = "missing-hangs-test"
    methods = ("rk4",)
    adaptive_methods = ()

    def missing(self, case, method):
        import time

        time.sleep(3600)  # a licence server that never answers
        return frozenset()


class PrepareHangs(ReferenceAdapter):
    name = "prepare-hangs-test"
    methods = ("rk4", "euler")
    adaptive_methods = ()
    asked: list[tuple[str, str]] = []  # noqa: RUF012 (the calls made in this process)

    def prepare(self, case, method):
        import os
        import time

        PrepareHangs.asked.append((case.name, method))
        if "PREPARE_ASKED" in os.environ:  # asked in a forked process: written down there
            with open(os.environ["PREPARE_ASKED"], "a") as said:
                said.write(f"{case.name} {method}\n")
        time.sleep(3600)  # a kernel cache on a network disk that never answers


class PrepareLives(ReferenceAdapter):
    name = "prepare-lives-test"
    methods = ("rk4",)
    adaptive_methods = ()
    asked: list[tuple[str, str]] = []  # noqa: RUF012 (the calls made in this process)

    def prepare(self, case, method):
        import os

        PrepareLives.asked.append((case.name, method))
        with open(os.environ["PREPARE_ASKED"], "a") as said:
            said.write(f"{case.name} {method}\n")


class PreparesApart(ReferenceAdapter):
    name = "prepares-apart-test"
    methods = ("rk4",)
    adaptive_methods = ()
    prepares_apart = True

    def prepare_all(self, pairs, workers=1):
        _said("apart: started")

    def prepared(self):
        _said("apart: awaited")


class PreparesHere(ReferenceAdapter):
    name = "prepares-here-test"
    methods = ("rk4",)
    adaptive_methods = ()

    def prepare_all(self, pairs, workers=1):
        _said("here: done")


def _said(line: str) -> None:
    import os

    with open(os.environ["PREPARE_ASKED"], "a") as said:
        said.write(line + "\n")


class PrepareAllRaises(ReferenceAdapter):
    name = "prepare-all-raises-test"
    methods = ("rk4",)
    adaptive_methods = ()

    def prepare_all(self, pairs, workers=1):
        raise RuntimeError("prepare_all broke")


def _run(tmp_path, engines: str, cases: str = "free-fall") -> int:
    out = tmp_path / "rep"
    return main(["run", "--quick", "--cases", cases, "--engines", engines, "--out", str(out)])


def test_an_adapter_that_cannot_be_made_is_one_line(tmp_path, capsys):
    assert _run(tmp_path, "test_plugin_calls:InitRaises,reference") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1] == (
        "truestep: error: engine 'init-raises-test': its adapter test_plugin_calls.InitRaises could not "
        "be made: RuntimeError: no licence server"
    )
    assert "Traceback" not in "\n".join(err) and not (tmp_path / "rep").exists()


def test_list_shows_it_unusable_and_goes_on(monkeypatch, capsys):
    known = {**adapters.registered(), "init-raises-test": "test_plugin_calls:InitRaises"}
    monkeypatch.setattr(adapters, "registered", lambda: known)
    assert main(["list", "--cases", "free-fall"]) == 0
    out = capsys.readouterr().out
    assert "init-raises-test unusable: engine 'init-raises-test': its adapter" in out
    assert "no licence server" in out and "reference  methods:" in out


def test_a_missing_that_raises_makes_its_rows_crashed_and_the_run_goes_on(tmp_path, capsys):
    assert _run(tmp_path, "test_plugin_calls:MissingRaises,reference", "free-fall,harmonic-oscillator") == 0
    results = pd.read_csv(tmp_path / "rep" / "results.csv")
    mine = results[results.engine == "missing-raises-test"]
    assert len(mine) == 4 and set(mine.status) == {"crashed"}
    said = "missing-raises-test: missing() raised RuntimeError: missing() broke at test_plugin_calls.py:"
    assert all(m.startswith(said) for m in mine.message), set(mine.message)  # where it raised, too
    assert (results[results.engine == "reference"].status == "ok").all()
    stability = pd.read_csv(tmp_path / "rep" / "stability.csv")
    searched = stability[stability.engine == "missing-raises-test"]
    assert len(searched) == 2 and set(searched.status) == {"crashed"}
    # what run wrote, gate reads: a crashed row with no step (refused before: "column dt:
    # empty ... a run's step must be positive and finite", exit 2)
    capsys.readouterr()
    engines = "test_plugin_calls:MissingRaises,reference"
    assert main(["gate", "--results", str(tmp_path / "rep" / "results.csv"), "--engines", engines, "-q"]) == 0
    assert "error" not in capsys.readouterr().err


def test_a_missing_that_never_answers_makes_its_rows_crashed_within_the_limit(tmp_path, monkeypatch):
    """A question truestep asks an adapter in its own process has a time limit
    (:data:`truestep.adapters.ANSWER_S`, 1 s here): a ``missing()`` that never answers
    makes its rows ``crashed``, saying so, and the run goes on (issue 37, item 7); asked
    once, it is not asked again for the next case, whose rows say why at once."""
    monkeypatch.setattr(adapters, "ANSWER_S", 1.0)
    monkeypatch.setattr(adapters, "_HUNG", {})
    assert _run(tmp_path, "test_plugin_calls:MissingHangs,reference", "free-fall,harmonic-oscillator") == 0
    results = pd.read_csv(tmp_path / "rep" / "results.csv")
    mine = results[results.engine == "missing-hangs-test"]
    assert set(mine.case) == {"free-fall", "harmonic-oscillator"} and set(mine.status) == {"crashed"}
    said = (
        "missing-hangs-test: missing() gave no answer within 1 s",  # the row of the call that hung
        "missing-hangs-test: missing() not asked again: it gave no answer within 1 s before",
    )
    assert set(mine.message) <= set(said) and said[1] in set(mine.message)
    assert (results[results.engine == "reference"].status == "ok").all()


def test_a_prepare_that_never_answers_holds_up_nothing_past_its_limit(tmp_path, monkeypatch):
    """``prepare(case, method)``, which truestep calls before it forks a sweep's or a
    search's runs (a plugin's in a forked process), has a time limit too
    (:data:`truestep.adapters.PREPARE_S`, 1 s here): one that never answers is let go, and
    the runs, which prepare what they need in their own processes, give their rows and
    searches (issue 37)."""
    from truestep.execution import runner

    monkeypatch.setattr(runner, "PREPARE_S", 1.0)
    monkeypatch.setattr(adapters, "_HUNG", {})
    asked = tmp_path / "asked.txt"
    monkeypatch.setenv("PREPARE_ASKED", str(asked))
    assert _run(tmp_path, "test_plugin_calls:PrepareHangs", "harmonic-oscillator") == 0
    results = pd.read_csv(tmp_path / "rep" / "results.csv")
    assert len(results) > 0 and (results.status == "ok").all()
    stability = pd.read_csv(tmp_path / "rep" / "stability.csv")
    assert len(stability) == 2 and set(stability.status) == {"ok"}
    # a plugin's prepare runs in a forked process only: there it ran out of time for the
    # first pair and was not asked again (a call that hung is not made again), and it was
    # never called in truestep's own process
    said = [tuple(line.split()) for line in asked.read_text().splitlines()]
    assert len(said) == 1 and set(said) <= {("harmonic-oscillator", "rk4"), ("harmonic-oscillator", "euler")}
    assert PrepareHangs.asked == []


def test_a_plugins_prepare_that_answers_runs_in_a_forked_process_only(tmp_path, monkeypatch):
    """Issue 37: a plugin's ``prepare`` that answers is not called again in truestep's
    own process (where a later call could end it): it ran, once for each scene and
    method, in a forked process, and the runs give their rows."""
    asked = tmp_path / "asked.txt"
    monkeypatch.setenv("PREPARE_ASKED", str(asked))
    assert _run(tmp_path, "test_plugin_calls:PrepareLives") == 0
    assert set(asked.read_text().splitlines()) == {"free-fall rk4"}
    assert PrepareLives.asked == []
    results = pd.read_csv(tmp_path / "rep" / "results.csv")
    assert len(results) > 0 and (results.status == "ok").all()


def test_an_engine_that_prepares_apart_is_started_first_and_awaited_last(tmp_path, monkeypatch, case_named):
    """``compile_ahead``: an adapter whose ``prepares_apart`` is true (Warp's engines, whose
    ``prepare_all`` compiles in a process of its own and returns at once) is started
    before the others, so that it compiles beside them, and its ``prepared()`` is
    awaited after them, before any run."""
    from truestep.adapters import resolve_engine
    from truestep.execution.runner import compile_ahead

    asked = tmp_path / "asked.txt"
    monkeypatch.setenv("PREPARE_ASKED", str(asked))
    here = resolve_engine("test_plugin_calls:PreparesHere")
    apart = resolve_engine("test_plugin_calls:PreparesApart")
    case = case_named("free-fall")
    entries = [("rk4", 0.01, False, "")]
    compile_ahead([(case, here, "rk4", entries), (case, apart, "rk4", entries)], workers=1)
    assert asked.read_text().splitlines() == ["apart: started", "here: done", "apart: awaited"]


def test_a_prepare_all_that_raises_is_a_line_and_the_runs_prepare_themselves(tmp_path, capsys):
    assert _run(tmp_path, "test_plugin_calls:PrepareAllRaises") == 0
    err = capsys.readouterr().err
    line = next(x for x in err.splitlines() if "prepare_all()" in x)
    assert line.startswith(
        "truestep: prepare-all-raises-test: prepare_all() raised RuntimeError: prepare_all broke"
    )
    assert line.endswith("; its runs prepare what they need themselves"), line
    results = pd.read_csv(tmp_path / "rep" / "results.csv")
    assert (results.status == "ok").all() and len(results) > 0


def test_an_adapter_is_asked_about_duplicates_only_for_a_scene_it_can_model(case_named):
    """``duplicate`` and ``skip`` are asked only where ``missing`` is empty, as before they
    were plugin calls: pybullet's ``duplicate`` reads a particle scene, and an ODE case's
    rows stay ``unsupported`` (found by the quick baseline gate, not by a test)."""
    from truestep.execution.runner import plan

    reasons = {why for _, _, _, why in plan(case_named("circle-field"), "pybullet", quick=True)}
    assert reasons and all(why.startswith("unsupported:") for why in reasons), reasons


class ListsTwice(ReferenceAdapter):
    name = "lists-twice-test"
    methods = ("rk4", "euler", "rk4")
    adaptive_methods = ()


class OddFailure(ReferenceAdapter):
    """An adapter whose runs say they blew up at a time that is no time: a word, or
    before the run began."""

    name = "odd-failure-test"
    methods = ("rk4", "euler")
    adaptive_methods = ()

    def simulate(self, case, method, dt, **kw):
        traj = super().simulate(case, method, dt, **kw)
        traj.status, traj.t_fail = "unstable", "soon" if method == "rk4" else -1e300
        return traj


def test_a_method_listed_twice_is_one_line(tmp_path, capsys):
    assert _run(tmp_path, "test_plugin_calls:ListsTwice") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert (
        err[-1]
        == "truestep: error: engine 'lists-twice-test': its adapter lists the method 'rk4' twice in methods"
    )


def test_a_failure_time_that_is_no_time_is_a_crashed_row_that_gate_reads(tmp_path, capsys):
    assert _run(tmp_path, "test_plugin_calls:OddFailure") == 0
    results = pd.read_csv(tmp_path / "rep" / "results.csv")
    assert set(results.status) == {"crashed"}
    said = set(results.message)
    assert "adapter returned t_fail = 'soon' (a time in s, or None)" in said
    assert any(m.startswith("adapter returned t_fail = -1e+300 s, outside the run") for m in said)
    capsys.readouterr()
    assert main(["gate", "--results", str(tmp_path / "rep" / "results.csv"), "-q"]) in (0, 1)
    assert "error" not in capsys.readouterr().err


def test_a_value_no_table_holds_makes_the_row_crashed_naming_it():
    from truestep.execution.runner import unreadable

    row = {"status": "ok", "message": "", "error": -1e300, "nfev": -3, "energy_drift": 0.1}
    unreadable(row)
    assert row["status"] == "crashed" and np.isnan(row["error"]) and np.isnan(row["nfev"])
    assert "error = -1e+300" in row["message"] and "nfev = -3" in row["message"]
    assert row["energy_drift"] == 0.1


def test_a_plugin_module_or_case_library_that_never_answers_is_one_line(tmp_path, monkeypatch, capsys):
    """Importing an installed package's module (an adapter, a case library) and calling a
    case library's callable have a time limit (:data:`truestep.cases.plugins.IMPORT_S`,
    1 s here): one that never answers is an error naming it, exit 2 and no traceback, not
    a run that never starts (issue 37)."""
    from truestep.cases import plugins

    monkeypatch.setattr(plugins, "IMPORT_S", 1.0)
    monkeypatch.syspath_prepend(str(tmp_path))
    (tmp_path / "hangs_at_import.py").write_text("import time\ntime.sleep(3600)\n")
    (tmp_path / "slow_cases.py").write_text("import time\n\ndef where():\n    time.sleep(3600)\n")
    assert _run(tmp_path, "hangs_at_import:Adapter") == 2
    err = capsys.readouterr().err
    assert "importing hangs_at_import gave no answer within 1 s" in err and "Traceback" not in err
    assert "hangs_at_import" not in __import__("sys").modules
    groups = {plugins.CASES_GROUP: {"slow": "slow_cases:where"}}
    monkeypatch.setattr(plugins, "_group", lambda group: groups.get(group, {}))
    assert main(["list", "--cases", "free-fall"]) == 2
    err = capsys.readouterr().err
    assert "entry point truestep.cases slow = 'slow_cases:where': calling it gave no answer within 1 s" in err
    assert "Traceback" not in err


HANGS_IN_MISSING = """
import time

from truestep.adapters.reference import ReferenceAdapter


class Adapter(ReferenceAdapter):
    name = "hangs-in-missing"
    methods = ("rk4",)
    adaptive_methods = ()

    def missing(self, case, method):
        time.sleep(3600)  # a licence server that never answers
        return frozenset()
"""


def test_the_answer_limit_is_set_from_the_environment_for_the_command(tmp_path):
    """``TRUESTEP_ANSWER_S`` sets :data:`truestep.adapters.ANSWER_S` for a command started
    with it (a CI that would fail a hung plugin sooner than in 300 s): ``truestep run``,
    started as a user starts it, with a plugin whose ``missing()`` never answers, writes
    that engine's rows as ``crashed``, naming the limit, and the reference's as run."""
    import os
    import subprocess
    import sys

    (tmp_path / "hangs_in_missing.py").write_text(HANGS_IN_MISSING)
    out = tmp_path / "rep"
    env = {**os.environ, "PYTHONPATH": str(tmp_path), adapters.ANSWER_ENV: "1.5"}
    argv = ["run", "--quick", "--cases", "free-fall", "--engines", "hangs_in_missing:Adapter,reference"]
    done = subprocess.run(
        [sys.executable, "-m", "truestep", *argv, "--out", str(out)],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    results = pd.read_csv(out / "results.csv")
    mine = results[results.engine == "hangs-in-missing"]
    assert len(mine) > 0 and set(mine.status) == {"crashed"}
    assert any("gave no answer within 1.5 s" in m for m in mine.message)
    assert (results[results.engine == "reference"].status == "ok").all()
