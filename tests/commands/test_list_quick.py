"""``truestep list --quick`` (issue 36, item 9): the cases a ``--quick`` run runs and the
steps of their sweeps; and output cut short by its reader ends the command quietly."""

from __future__ import annotations

import subprocess
import sys

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
