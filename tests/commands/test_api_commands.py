"""Every command is a call into :mod:`truestep.api` (issue 38, item 4): what the API
returns is what the command prints, read back from the command's own output."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

import truestep
from truestep.cli import main

QUICK = Path(__file__).resolve().parents[1] / "baselines" / "quick"


def test_engines_are_what_list_prints(capsys):
    names = ["reference", "pymunk", "no-such-engine"]
    assert main(["list", "--cases", "free-fall", "--engines", ",".join(names)]) == 0
    printed = capsys.readouterr().out.split("engines:\n", 1)[1].splitlines()
    infos = list(truestep.engines(names))
    assert [i.name for i in infos] == names
    assert infos[2].status == "unknown engine" and infos[2].methods == ()
    for info in infos[:2]:
        assert info.status == "installed"
        line = next(k for k, text in enumerate(printed) if text.split()[:1] == [info.name])
        assert printed[line].split("methods: ", 1)[1] == ", ".join(info.methods)
        assert printed[line + 1].split("capabilities: ", 1)[1] == ", ".join(info.capabilities)
        assert info.methods == tuple(truestep.get_adapter(info.name).methods)
    assert infos[0].devices and not infos[1].devices  # the reference takes one when named
    assert sum("devices: " in text for text in printed) == 1  # the reference's, not pymunk's


def test_the_engines_that_take_a_device_say_so_in_list(capsys):
    """``truestep list`` names a device line for the engines whose adapter takes a device
    (``--device`` can put them on a GPU: Newton, and the reference when named), and none
    for the others."""
    pytest.importorskip("newton")
    assert main(["list", "--cases", "free-fall", "--engines", "newton,reference"]) == 0
    printed = capsys.readouterr().out.split("engines:\n", 1)[1].splitlines()
    infos = {i.name: i for i in truestep.engines(["newton", "reference"])}
    assert infos["newton"].devices and infos["reference"].devices
    devices = [text.split("devices: ", 1)[1] for text in printed if "devices: " in text]
    assert devices == [f"cpu (the default), or a GPU: truestep run --device {e}=cuda:0" for e in infos]


def test_the_environment_is_what_env_exports(capsys):
    assert main(["env"]) == 0
    exported = dict(
        line.removeprefix("export ").split("=", 1) for line in capsys.readouterr().out.splitlines()
    )
    assert {k: v.strip("'") for k, v in exported.items()} == truestep.environment()


def test_a_baseline_and_a_history_through_the_api(tmp_path, monkeypatch, capsys):
    root = tmp_path / "project"
    root.mkdir()
    for args in (["init", "-q"], ["config", "user.email", "t@t"], ["config", "user.name", "t"]):
        subprocess.run(["git", *args], cwd=root, check=True)
    (root / "a.txt").write_text("a\n")
    subprocess.run(["git", "add", "a.txt"], cwd=root, check=True)
    subprocess.run(["git", "commit", "-q", "-m", "one"], cwd=root, check=True)
    monkeypatch.chdir(root)
    provenance = truestep.save_baseline(QUICK / "results.csv", root / "base")
    assert (root / "base" / "results.csv").is_file() and provenance["project"]["revision"]
    with pytest.raises(truestep.api.BaselineRefused):
        truestep.save_baseline(QUICK / "results.csv", root)  # a folder holding other files
    entry = truestep.history_add(QUICK / "results.csv", root / "store")
    assert entry["folder"]
    store = root / "store"
    kept = truestep.history("error", "harmonic-oscillator", "reference", "rk4", dt=0.002, store=store)
    assert len(kept.points) == 1 and kept.stepped == [] and kept.tolerance > 0
    assert main(["history", "export", "--results", str(QUICK / "results.csv")]) == 0
    assert json.loads(capsys.readouterr().out) == truestep.benchmark_json(QUICK / "results.csv")
    with pytest.raises(truestep.api.HistoryError):
        truestep.history_add(root / "nothing.csv", root / "store")


def test_a_report_folder_is_checked_as_run_checks_it(tmp_path, capsys):
    """``truestep.check_report_folder`` refuses what ``truestep run --out`` refuses, with
    the same line, before any work; a new folder's parent is made and its path returned."""
    from truestep.api import OutRefused

    new = tmp_path / "a" / "new"
    assert truestep.check_report_folder(new) == new.resolve() and new.parent.is_dir()
    theirs = tmp_path / "theirs"
    theirs.mkdir()
    (theirs / "notes.txt").write_text("mine")
    with pytest.raises(OutRefused) as refused:
        truestep.check_report_folder(theirs)
    assert str(refused.value).startswith("--out: ") and "not a report truestep wrote" in str(refused.value)
    with pytest.raises(OutRefused, match=r"^--dest: .* is a file"):
        truestep.check_report_folder(theirs / "notes.txt", flag="--dest")
    run = ["run", "--quick", "--cases", "free-fall", "--engines", "reference", "--out", str(theirs)]
    assert main(run) == 2
    assert str(refused.value) in capsys.readouterr().err
    assert (theirs / "notes.txt").read_text() == "mine"


def test_engines_for_a_run_are_the_installed_ones_asked():
    assert truestep.engines_for_run("reference, pymunk,reference") == ["reference", "pymunk"]
    assert "reference" in truestep.engines_for_run(None)


def test_a_signal_inside_interruptible_is_an_interruption_and_the_handler_comes_back(tmp_path):
    import os
    import signal
    import time

    from truestep.api import Interrupted

    before = signal.getsignal(signal.SIGTERM)
    with pytest.raises(Interrupted) as stopped, truestep.interruptible():
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(10)  # the handler raises at once
    assert stopped.value.signum == signal.SIGTERM and not stopped.value.published
    assert signal.getsignal(signal.SIGTERM) == before
    assert truestep.resumable(tmp_path / "never-run") is None
