"""Calls truestep makes to an adapter in its own process (construction, ``missing``,
``prepare_all``) are plugin code (issue 37, items 5 and 11): one that raises is one line
naming the engine, or ``crashed`` rows with the reason, and the rest of the run goes on."""

from __future__ import annotations

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
    assert set(mine.message) == {"missing-raises-test: missing() raised RuntimeError: missing() broke"}
    assert (results[results.engine == "reference"].status == "ok").all()
    stability = pd.read_csv(tmp_path / "rep" / "stability.csv")
    searched = stability[stability.engine == "missing-raises-test"]
    assert len(searched) == 2 and set(searched.status) == {"crashed"}


def test_a_prepare_all_that_raises_is_a_line_and_the_runs_prepare_themselves(tmp_path, capsys):
    assert _run(tmp_path, "test_plugin_calls:PrepareAllRaises") == 0
    err = capsys.readouterr().err
    assert (
        "truestep: prepare-all-raises-test: prepare_all() raised RuntimeError: prepare_all broke; "
        "its runs prepare what they need themselves"
    ) in err
    results = pd.read_csv(tmp_path / "rep" / "results.csv")
    assert (results.status == "ok").all() and len(results) > 0


def test_an_adapter_is_asked_about_duplicates_only_for_a_scene_it_can_model(case_named):
    """``duplicate`` and ``skip`` are asked only where ``missing`` is empty, as before they
    were plugin calls: pybullet's ``duplicate`` reads a particle scene, and an ODE case's
    rows stay ``unsupported`` (found by the quick baseline gate, not by a test)."""
    from truestep.execution.runner import plan

    reasons = {why for _, _, _, why in plan(case_named("circle-field"), "pybullet", quick=True)}
    assert reasons and all(why.startswith("unsupported:") for why in reasons), reasons
