"""``truestep list --quick`` (issue 36, item 9): the cases a ``--quick`` run runs and the
steps of their sweeps; and output cut short by its reader ends the command quietly."""

from __future__ import annotations

import subprocess
import sys

import pytest

from truestep.cases import load_cases
from truestep.cli import main


def test_list_quick_names_the_quick_cases_and_their_steps(capsys):
    assert main(["list", "--quick", "--engines", "reference"]) == 0
    out = capsys.readouterr().out
    quick = [c for c in load_cases("*") if c.in_quick]
    listed = [line.split()[0] for line in out.split("engines:")[0].splitlines()[1:] if "features:" in line]
    assert listed == [c.name for c in quick]
    oscillator = next(c for c in quick if c.name == "harmonic-oscillator")
    steps = ", ".join(f"{h:.4g}" for h in oscillator.quick_dts)
    assert f"steps (s): {steps};" in out
    assert main(["list", "--cases", "harmonic-oscillator", "--engines", "reference"]) == 0
    assert f"steps (s): {', '.join(f'{h:.4g}' for h in oscillator.dts)};" in capsys.readouterr().out


def test_a_reader_that_stops_early_gets_no_traceback():
    proc = subprocess.Popen(
        [sys.executable, "-m", "truestep", "list"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    assert proc.stdout is not None and proc.stderr is not None
    proc.stdout.close()  # `truestep list | head -0`: the reader is gone before the first line
    err = proc.stderr.read()
    proc.wait(timeout=120)
    assert "Traceback" not in err and "BrokenPipe" not in err


def test_the_api_selects_what_the_commands_run_and_refuses_a_bad_limit_in_one_line(capsys):
    """``truestep.api.select_cases`` is the selection ``run`` and ``list`` make: the quick
    cases of the library with ``quick``, a named case whatever ``quick`` says, every case
    without; a bad ``--limit`` item is a :class:`LimitError` from the API and exit 2 with
    its one line from a command."""
    from truestep.api import select_cases
    from truestep.cases.limits import LimitError

    library = load_cases("*")
    assert [c.name for c in select_cases()] == [c.name for c in library]
    assert [c.name for c in select_cases(quick=True)] == [c.name for c in library if c.in_quick]
    assert [c.name for c in select_cases("bouncing-ball", quick=True)] == ["bouncing-ball"]
    assert [c.name for c in select_cases("bouncing-ball", limits=["steps=1e12"], trust_limits=True)] == [
        "bouncing-ball"
    ]
    with pytest.raises(LimitError, match="over the ceiling"):
        select_cases("bouncing-ball", limits=["steps=1e12"])
    assert main(["run", "--quick", "--cases", "bouncing-ball", "--limit", "steps=x"]) == 2
    err = capsys.readouterr().err  # (a plugin another test left registered may be named first)
    assert err.strip().splitlines()[-1] == "truestep: error: --limit steps: not a number: 'x'"
