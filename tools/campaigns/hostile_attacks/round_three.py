"""Round three (issue 37): each attack repeats one failure the project has since fixed,
with the input its own unit test uses (named in each docstring), against the target's
``truestep`` command as a user starts it (``python -m truestep``: the console script's
``truestep.command.main``, its supervisor and its standard-output handling included), as
every group's attacks do (:attr:`Target.cli`)."""

from __future__ import annotations

import csv
import os
import textwrap
import time
from pathlib import Path

from hostile_attacks.common import (
    RUN_TIMEOUT,
    Campaign,
    Result,
    gate,
    refused,
    shipped_tables,
    snapshot,
    user_folder,
)

DEAD_PID = 2**22 + 12345
"""A pid above any this machine hands out: the run that made a folder of it is gone."""


def _lines(result: Result) -> list[str]:
    """truestep's own lines on standard error (a run's progress left out)."""
    return [x for x in result.err.splitlines() if x.startswith("truestep:")]


def _plugin_env(c: Campaign, where: Path) -> dict[str, str]:
    """The environment with ``where`` (modules, a dist-info) first on ``PYTHONPATH``."""
    return c.env(PYTHONPATH=os.pathsep.join([str(where), str(c.adapters)]))


def _rows(folder: Path) -> list[dict[str, str]]:
    path = folder / "results.csv"
    return list(csv.DictReader(path.open())) if path.is_file() else []


def _untouched_run(c: Campaign, where: Path, folder: Path) -> tuple[bool, str]:
    """A quick run on ``rep`` beside ``folder``: held when the folder is as it was."""
    before = snapshot(folder)
    result = c.quick_run(where, "rep", cases="free-fall")
    after = snapshot(folder)
    if after != before:
        lost = sorted(set(before) - set(after))
        return False, f"{folder.name} changed (lost {lost[:4]}); {result.why()}"
    return "Traceback" not in result.err, f"{folder.name} kept; {result.why()}"


def attack_hard_link_in_the_locks_place(c: Campaign, where: Path) -> tuple[bool, str]:
    """A hard link to someone's file named ``.rep.lock`` beside ``--out rep``: the file
    keeps its bytes (tests/runtime/test_files_beside_out.py: refused, "hard link")."""
    mine = where / "thesis.txt"
    mine.write_text("years of work\n")
    os.link(mine, where / ".rep.lock")
    result = c.quick_run(where, "rep", cases="free-fall")
    kept = mine.read_text() == "years of work\n"
    return kept and "Traceback" not in result.err, f"file kept: {kept}; {result.why()}"


def attack_empty_out(c: Campaign, where: Path) -> tuple[bool, str]:
    """``--out ''`` (an unset variable) beside a ``reports`` folder of someone's files:
    exit 2, one line, ``reports`` untouched."""
    reports = user_folder(where / "reports")
    before = snapshot(reports)
    result = c.quick_run(where, "", cases="free-fall")
    if snapshot(reports) != before:
        return False, f"reports changed: {result.why()}"
    return refused(result)


def attack_users_folder_under_a_staging_name(c: Campaign, where: Path) -> tuple[bool, str]:
    """Someone's folder named ``.rep.staging-<dead pid>`` (files, no journal) beside
    ``--out rep``: the run's clean-up of dead runs' folders leaves it."""
    return _untouched_run(c, where, user_folder(where / f".rep.staging-{DEAD_PID}"))


def attack_users_folder_under_the_journals_name(c: Campaign, where: Path) -> tuple[bool, str]:
    """Someone's folder named ``.rep.partial`` (files, no journal) beside ``--out rep``:
    never deleted (the run is refused, "truestep did not make")."""
    return _untouched_run(c, where, user_folder(where / ".rep.partial"))


def attack_adapter_import_ends_its_process(c: Campaign, where: Path) -> tuple[bool, str]:
    """A package whose adapter module calls ``os._exit(0)`` when imported: ``list``
    names it in one line and goes on (exit 0); a run naming it is exit 2 with one line,
    no report (tests/runtime/test_supervisor.py KILLERS)."""
    (where / "os_exit_at_import.py").write_text("import os\nos._exit(0)\n")
    info = where / "killers-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: killers\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text("[truestep.adapters]\nos-exit-at-import = os_exit_at_import:X\n")
    said = "importing os_exit_at_import ended the process"
    listed = c.truestep(["list"], where, env=_plugin_env(c, where), timeout=RUN_TIMEOUT)
    named = [x for x in listed.out.splitlines() if x.strip().startswith("os-exit-at-import")]
    if listed.code != 0 or not named or said not in named[0] or "reference" not in listed.out:
        return False, f"list: {named[:1]}; {listed.why()}"
    result = c.quick_run(
        where, "rep", cases="free-fall", engines="os_exit_at_import:X,reference", env=_plugin_env(c, where)
    )
    lines = _lines(result)
    ok = result.code == 2 and len(lines) == 1 and said in lines[0] and "Traceback" not in result.err
    return ok and not (where / "rep").exists(), f"list names it; run: {result.why()}"


EXITS_IN_MISSING = """
import os
from truestep.adapters.reference import ReferenceAdapter

class X(ReferenceAdapter):
    name = "exits-in-missing"

    def missing(self, case, method):
        os._exit(0)
"""


def attack_adapter_missing_ends_its_process(c: Campaign, where: Path) -> tuple[bool, str]:
    """An adapter whose ``missing()`` calls ``os._exit(0)``: its rows are ``crashed``,
    the reference's ``ok``, exit 0 (tests/runtime/test_supervisor.py, it used to end the command:
    exit 3, no report)."""
    (where / "exits_in_missing.py").write_text(textwrap.dedent(EXITS_IN_MISSING))
    result = c.quick_run(
        where, "rep", cases="free-fall", engines="exits_in_missing:X,reference", env=_plugin_env(c, where)
    )
    rows = _rows(where / "rep")
    mine = {r["status"] for r in rows if r["engine"] == "exits-in-missing"}
    ref = {r["status"] for r in rows if r["engine"] == "reference"}
    ok = result.code == 0 and mine == {"crashed"} and ref == {"ok"}
    return ok, f"its rows {sorted(mine)}, reference {sorted(ref)}; {result.why()}"


EXITS_WHEN_MADE = """
import os
from truestep.adapters.reference import ReferenceAdapter

class X(ReferenceAdapter):
    name = "exits-when-made"

    def __init__(self):
        os._exit(0)
"""


def attack_adapter_construction_ends_its_process(c: Campaign, where: Path) -> tuple[bool, str]:
    """An adapter whose ``__init__`` calls ``os._exit(0)``: exit 2 with one line naming
    it, no report (tests/runtime/test_supervisor.py; it used to end the command: exit 3, a line
    that named no plugin)."""
    (where / "exits_when_made.py").write_text(EXITS_WHEN_MADE)
    result = c.quick_run(
        where, "rep", cases="free-fall", engines="exits_when_made:X,reference", env=_plugin_env(c, where)
    )
    lines = _lines(result)
    named = len(lines) == 1 and "making its adapter exits_when_made.X ended the process" in lines[0]
    ok = result.code == 2 and named and not (where / "rep").exists() and "Traceback" not in result.err
    return ok, result.why()


EXITS_IN_A_LATER_PREPARE = """
import os
from pathlib import Path
from truestep.adapters.reference import ReferenceAdapter

class X(ReferenceAdapter):
    name = "exits-in-a-later-prepare"

    def prepare(self, case, method):
        mark = Path("prepared-once")
        if mark.exists():
            os._exit(0)
        mark.write_text("")
"""


def attack_adapter_prepare_ends_its_process_on_a_later_call(c: Campaign, where: Path) -> tuple[bool, str]:
    """An adapter whose ``prepare()`` lives through its first call and calls
    ``os._exit(0)`` on every later one: the run goes on, exit 0, its rows and the
    reference's ``ok`` (tests/runtime/test_supervisor.py; it used to end the command, exit 3,
    no report: the first call was a forked probe, the second ran in truestep's process)."""
    (where / "exits_in_a_later_prepare.py").write_text(EXITS_IN_A_LATER_PREPARE)
    result = c.quick_run(
        where,
        "rep",
        cases="free-fall",
        engines="exits_in_a_later_prepare:X,reference",
        env=_plugin_env(c, where),
    )
    rows = _rows(where / "rep")
    mine = {r["status"] for r in rows if r["engine"] == "exits-in-a-later-prepare"}
    ref = {r["status"] for r in rows if r["engine"] == "reference"}
    ok = result.code == 0 and mine == {"ok"} and ref == {"ok"}
    return ok, f"its rows {sorted(mine)}, reference {sorted(ref)}; {result.why()}"


IMPOSTOR = """
from truestep.adapters.reference import ReferenceAdapter

class Impostor(ReferenceAdapter):
    def simulate(self, case, method, dt, **kw):
        raise RuntimeError("the impostor ran")
"""


def attack_second_package_registers_reference(c: Campaign, where: Path) -> tuple[bool, str]:
    """A package registering the built-in engine name ``reference``: ignored (the
    reference runs, no crashed row) and named on standard error
    (tests/adapters/test_shadowed_engine.py)."""
    (where / "impostor.py").write_text(IMPOSTOR)
    info = where / "impostor-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: impostor\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text("[truestep.adapters]\nreference = impostor:Impostor\n")
    result = c.quick_run(where, "rep", cases="free-fall", env=_plugin_env(c, where))
    statuses = {r["status"] for r in _rows(where / "rep")}
    named = "another package registers this built-in name" in result.err
    ok = result.code == 0 and named and statuses == {"ok"} and "the impostor ran" not in result.err
    return ok, f"named: {named}, rows {sorted(statuses)}; {result.why()}"


def attack_gates_file_gate_matching_no_case(c: Campaign, where: Path) -> tuple[bool, str]:
    """A gates file whose gate's ``cases`` is a typo (``harmonic-osc``) on the published
    tables: the gate is shown not evaluated, not dropped (tests/ci/test_gates.py)."""
    tables = shipped_tables(where / "tables")
    gates = where / "gates.toml"
    gates.write_text(
        '[[gates]]\ncases = "harmonic-osc"\nkind = "error"\nengine = "reference"\nmethod = "rk4"\n'
        "dt = 1e-3\nmax = 1.0\n"
    )
    result = c.truestep(
        [
            "gate",
            "--results",
            str(tables / "results.csv"),
            "--gates",
            str(gates),
            "--cases",
            "harmonic-oscillator",
        ],
        where,
        timeout=RUN_TIMEOUT,
        memory_gb=6.0,
    )
    shown = [x for x in result.out.splitlines() if "harmonic-osc/" in x]
    ok = result.code in (0, 1) and bool(shown) and "Traceback" not in result.err
    return ok, f"{shown[0][:120] if shown else 'the gate is not shown'}; {result.why()}"


def attack_results_table_cut_inside_its_last_row(c: Campaign, where: Path) -> tuple[bool, str]:
    """The published results.csv cut off inside a row (a full disk, a copy interrupted):
    ``truestep gate`` refuses it, exit 2, one line (tests/tables/test_io.py)."""
    whole = (shipped_tables(where / "tables") / "results.csv").read_bytes()
    half = len(whole) // 2
    if whole[half - 1 : half] == b"\n":
        half -= 1
    cut = where / "results.csv"
    cut.write_bytes(whole[:half])
    return refused(gate(c, where, cut))


def attack_list_into_a_reader_that_stops(c: Campaign, where: Path) -> tuple[bool, str]:
    """``truestep list | head -n1`` and ``truestep list | true`` (the reader gone before
    the first line): the command ends quietly, no traceback."""
    notes = []
    for reader in ("head -n1", "true"):
        started = time.perf_counter()
        proc = c._popen(
            ["sh", "-c", f'nice -n 5 "$@" | {reader}', "sh", *c.target.cli, "list"], where, c.env(), None
        )
        result = c.finish(proc, RUN_TIMEOUT, started)
        noisy = "Traceback" in result.err or "BrokenPipe" in result.err
        if noisy or result.code is None:
            return False, f"| {reader}: {result.why()}"
        notes.append(f"| {reader}: {len(result.out.splitlines())} line(s) out, exit {result.code}")
    return True, "; ".join(notes)


API_RUN = """
import truestep
truestep.run("free-fall", engines=["reference"], quick=True, analyses=False, out="run",
             progress=lambda _: None)
"""


def attack_api_run_without_analyses_then_gate(c: Campaign, where: Path) -> tuple[bool, str]:
    """``truestep.run(..., analyses=False, out=DIR)`` then ``truestep gate --results
    DIR/results.csv``: the run is read (exit 0 or 1, never 2; tests/ci/test_gate_report.py)."""
    made = c.python(API_RUN, where, timeout=RUN_TIMEOUT)
    if made.code != 0:
        return False, f"the API run failed: {made.why()}"
    result = gate(c, where, where / "run" / "results.csv", "--declared-orders")
    return result.code in (0, 1) and "Traceback" not in result.err, result.why()


ATTACKS = [
    attack_hard_link_in_the_locks_place,
    attack_empty_out,
    attack_users_folder_under_a_staging_name,
    attack_users_folder_under_the_journals_name,
    attack_adapter_import_ends_its_process,
    attack_adapter_missing_ends_its_process,
    attack_adapter_prepare_ends_its_process_on_a_later_call,
    attack_adapter_construction_ends_its_process,
    attack_second_package_registers_reference,
    attack_gates_file_gate_matching_no_case,
    attack_results_table_cut_inside_its_last_row,
    attack_list_into_a_reader_that_stops,
    attack_api_run_without_analyses_then_gate,
]
