"""Damaged tables, a full disk, and gates the API and the command line judge alike."""

from __future__ import annotations

import csv
import io
import shutil
from collections.abc import Callable
from pathlib import Path

from hostile_attacks.common import (
    Campaign,
    case_file,
    gate,
    mkfifo,
    refused,
    shipped_tables,
    snapshot,
)


def damaged(
    where: Path, change: Callable[[list[list[str]]], list[list[str]]], table: str = "results"
) -> Path:
    tables = shipped_tables(where / "t")
    path = tables / f"{table}.csv"
    rows = list(csv.reader(io.StringIO(path.read_text())))
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerows(change(rows))
    path.write_text(buf.getvalue())
    return tables


def column(rows: list[list[str]], name: str) -> int:
    return rows[0].index(name)


def first_ok(rows: list[list[str]]) -> int:
    k = column(rows, "status")
    return next(i for i, r in enumerate(rows) if i and r[k] == "ok")


def _set(name: str, value: str):
    def change(rows: list[list[str]]) -> list[list[str]]:
        rows[first_ok(rows)][column(rows, name)] = value
        return rows

    return change


def attack_duplicated_rows(c: Campaign, where: Path) -> tuple[bool, str]:
    """A results table with a row repeated."""
    tables = damaged(where, lambda rows: [*rows, rows[first_ok(rows)]])
    return refused(gate(c, where, tables / "results.csv"))


def attack_dt_zero(c: Campaign, where: Path) -> tuple[bool, str]:
    """An ok row with ``dt = 0``."""
    return refused(gate(c, where, damaged(where, _set("dt", "0")) / "results.csv"))


def attack_dt_negative(c: Campaign, where: Path) -> tuple[bool, str]:
    """An ok row with ``dt = -0.01``."""
    return refused(gate(c, where, damaged(where, _set("dt", "-0.01")) / "results.csv"))


def attack_all_nan_baseline(c: Campaign, where: Path) -> tuple[bool, str]:
    """``--baseline`` a results table whose every number is gone."""

    def blank(rows: list[list[str]]) -> list[list[str]]:
        numeric = [
            column(rows, n)
            for n in (
                "dt",
                "error",
                "energy_drift",
                "energy_drift_final",
                "nfev",
                "steps",
                "wall_s",
                "repeats",
                "t_fail",
            )
        ]
        for r in rows[1:]:
            for k in numeric[1:]:
                r[k] = ""
        return rows

    base = damaged(where / "b", blank)
    tables = shipped_tables(where / "current")
    return refused(gate(c, where, tables / "results.csv", "--baseline", str(base)))


def attack_a_100_mb_field(c: Campaign, where: Path) -> tuple[bool, str]:
    """A results table with a message of 100 MB."""
    return refused(
        gate(c, where, damaged(where, _set("message", "x" * 100_000_000)) / "results.csv", timeout=120)
    )


def attack_duplicated_column(c: Campaign, where: Path) -> tuple[bool, str]:
    """A results table with the ``error`` column twice."""

    def twice(rows: list[list[str]]) -> list[list[str]]:
        k = column(rows, "error")
        return [[*r, r[k]] for r in rows]

    return refused(gate(c, where, damaged(where, twice) / "results.csv"))


def attack_a_directory_beside_the_results(c: Campaign, where: Path) -> tuple[bool, str]:
    """``stability.csv`` is a directory."""
    tables = shipped_tables(where / "t")
    (tables / "stability.csv").unlink()
    (tables / "stability.csv").mkdir()
    return refused(gate(c, where, tables / "results.csv"))


def attack_compare_on_duplicated_rows(c: Campaign, where: Path) -> tuple[bool, str]:
    """``truestep.compare`` with a baseline of repeated rows: a TableError."""
    base = damaged(where / "b", lambda rows: [*rows, rows[first_ok(rows)]])
    tables = shipped_tables(where / "current")
    result = c.python(
        "import truestep\nfrom truestep.tables.io import TableError\ntry:\n"
        f"    truestep.compare({str(base)!r}, {str(tables)!r})\n"
        "except TableError as e:\n    print('CLEAN', e)\n",
        where,
    )
    return result.code == 0 and "CLEAN" in result.out, result.why()


def attack_a_method_named_nan(c: Campaign, where: Path) -> tuple[bool, str]:
    """A valid table in which a method is named ``nan``: it is a name, and a gate on it
    is evaluated (and holds)."""

    def rename(rows: list[list[str]]) -> list[list[str]]:
        e, m, case = column(rows, "engine"), column(rows, "method"), column(rows, "case")
        for r in rows[1:]:
            if r[e] == "reference" and r[m] == "rk4" and r[case] == "free-fall":
                r[m] = "nan"
        return rows

    tables = damaged(where, rename)
    rows = list(csv.DictReader((tables / "results.csv").open()))
    dt = next(r["dt"] for r in rows if r["method"] == "nan" and r["status"] == "ok")
    (where / "gates.toml").write_text(
        f'[[gates]]\ncases = "free-fall"\nkind = "status"\nmethod = "nan"\ndt = {dt}\nexpect = "ok"\n'
    )
    result = c.truestep(
        [
            "gate",
            "--results",
            str(tables / "results.csv"),
            "--cases",
            "free-fall",
            "--gates",
            "gates.toml",
            "-v",
        ],
        where,
    )
    line = next((x for x in result.out.splitlines() if "reference/nan" in x), "")
    return line.startswith("ok"), f"{line[:160] or result.why()}"


def attack_full_disk_while_writing_the_report(c: Campaign, where: Path) -> tuple[bool, str]:
    """``ulimit -f 24`` (KiB): the report cannot be written; exit 2 with one line, the
    old report as it was."""
    shutil.copytree(c.base_report(), where / "rep")
    before = snapshot(where / "rep")
    result = c.quick_run(where, "rep", cases="free-fall", fsize=24 * 1024)
    same = snapshot(where / "rep") == before
    return result.run_refusal and same, f"old report kept: {same}; {result.why()}"


def attack_load_case_and_cli_judge_gates_alike(c: Campaign, where: Path) -> tuple[bool, str]:
    """Case files with a property gate on a property the case does not name, and a gate
    on an unknown engine: ``truestep.load_case`` and ``truestep list`` must agree."""
    verdicts = []
    for label, gate_text in (
        (
            "property",
            '[[gates]]\nkind = "property"\nname = "final_speed"\ndt = 0.01\nmax = 1.0\nmethod = "rk4"\n',
        ),
        (
            "engine",
            '[[gates]]\nkind = "status"\nengine = "nosuch"\nmethod = "rk4"\ndt = 0.01\nexpect = "ok"\n',
        ),
    ):
        d = where / label
        d.mkdir()
        path = case_file(d, extra=gate_text)
        api = c.python(
            f"import truestep\ntry:\n    truestep.load_case({str(path)!r})\n"
            "    print('ACCEPTED')\nexcept truestep.cases.CaseError as e:\n"
            "    print('REFUSED', e)\n",
            d,
        )
        cli = c.truestep(["list", "--cases", str(path)], d)
        api_ok, cli_ok = "ACCEPTED" in api.out, cli.code == 0
        verdicts.append((label, api_ok, cli_ok))
    alike = all(a == b for _, a, b in verdicts)
    return alike, "; ".join(
        f"{label}: load_case {'accepts' if a else 'refuses'}, CLI {'accepts' if b else 'refuses'}"
        for label, a, b in verdicts
    )


def attack_junit_into_a_fifo(c: Campaign, where: Path) -> tuple[bool, str]:
    """``truestep gate --junit`` a FIFO: refused, no hang."""
    tables = shipped_tables(where / "t")
    mkfifo(where / "j.xml")
    return refused(gate(c, where, tables / "results.csv", "--junit", "j.xml"))


def attack_json_into_a_directory(c: Campaign, where: Path) -> tuple[bool, str]:
    """``truestep gate --json`` a directory."""
    tables = shipped_tables(where / "t")
    (where / "out.json").mkdir()
    return refused(gate(c, where, tables / "results.csv", "--json", "out.json"))


ATTACKS = [
    attack_duplicated_rows,
    attack_dt_zero,
    attack_dt_negative,
    attack_all_nan_baseline,
    attack_a_100_mb_field,
    attack_duplicated_column,
    attack_a_directory_beside_the_results,
    attack_compare_on_duplicated_rows,
    attack_a_method_named_nan,
    attack_full_disk_while_writing_the_report,
    attack_load_case_and_cli_judge_gates_alike,
    attack_junit_into_a_fifo,
    attack_json_into_a_directory,
]
