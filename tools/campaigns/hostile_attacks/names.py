"""Hostile names and texts in every output."""

from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ET
from pathlib import Path

from hostile_attacks.adapters import adapter_run
from hostile_attacks.common import (
    CASE,
    HIDDEN,
    INJECTED,
    Campaign,
    Result,
    case_file,
)


def hostile_run(c: Campaign) -> tuple[Path, Result]:
    """A run of the Hostile adapter (names and messages of markup, bidi and escapes) with
    a case whose title and description hold the same, and a stability search (whose lines
    name the engine and methods too), made once."""
    if not hasattr(c, "_hostile"):
        where = c.folder("hostile-run")
        cases = where / "cases"
        cases.mkdir()
        case_file(
            cases,
            "hostile-text",
            extra="",
            body=CASE.format(
                duration="1.0",
                dt="[0.01, 0.005]",
                extra='[reference]\nexact = "uniform-gravity"\n'
                "[stability]\nhorizon = 0.5\ndt_lo = 1e-3\ndt_hi = 0.2\nquick = true\n",
            ).replace(
                'title = "a case of the campaign"',
                'title = "T<script>alert(1)</script>\\u202eeltit"\n'
                'description = "D<img src=x onerror=alert(1)> \\u200b\\u001b[31m"',
            ),
        )
        result = adapter_run(c, where, "Hostile", cases=str(cases / "hostile-text.toml"))
        c._hostile = (where, result)  # type: ignore[attr-defined]
    return c._hostile  # type: ignore[attr-defined]


def raw_in(text: str, *, markdown: bool) -> list[str]:
    """Hidden characters and live markup in ``text`` (in markdown, ``<`` is text only
    behind a backslash)."""
    found = [repr(s) for s in HIDDEN if s in text]
    for s in INJECTED:
        if re.search(r"(?<!\\)" + re.escape(s), text) if markdown else s in text:
            found.append(repr(s))
    return found


def _names_in_page(c: Campaign, name: str) -> tuple[bool, str]:
    """Whether a hostile run's report page ``name`` shows every hostile name escaped."""
    run, result = hostile_run(c)
    page = run / "rep" / name
    if not page.is_file():
        return False, f"no report: {result.why()}"
    found = raw_in(page.read_text(), markdown=name.endswith(".md"))
    return not found, f"raw in {name}: {found}"


def attack_names_in_index_md(c: Campaign, where: Path) -> tuple[bool, str]:
    """Engine, method, message, title and description in ``index.md``."""
    return _names_in_page(c, "index.md")


def attack_names_in_index_html(c: Campaign, where: Path) -> tuple[bool, str]:
    """The same in ``index.html``."""
    return _names_in_page(c, "index.html")


def attack_names_on_the_console_of_run(c: Campaign, where: Path) -> tuple[bool, str]:
    """The same on ``truestep run``'s standard output and error."""
    _, result = hostile_run(c)
    found = [repr(s) for s in HIDDEN if s in result.out + result.err]
    return not found and result.code == 0, f"raw on the console: {found}; {result.why()}"


def hostile_gate(c: Campaign) -> tuple[Path, Result]:
    """``truestep gate -v`` on the hostile run's tables with every CI output (made once)."""
    if not hasattr(c, "_hostile_gate"):
        run, _ = hostile_run(c)
        gates = run / "gates.toml"
        gates.write_text(
            '[[gates]]\ncases = "*"\nkind = "error"\nengine = "*"\nmethod = "*"\ndt = 0.01\nmax = 0.0\n'
        )
        result = c.truestep(
            [
                "gate",
                "--results",
                str(run / "rep" / "results.csv"),
                "--cases",
                str(run / "cases"),
                "--gates",
                str(gates),
                "-v",
                "--junit",
                "j.xml",
                "--markdown",
                "m.md",
                "--json",
                "j.json",
            ],
            run,
        )
        c._hostile_gate = (run, result)  # type: ignore[attr-defined]
    return c._hostile_gate  # type: ignore[attr-defined]


def attack_names_in_junit(c: Campaign, where: Path) -> tuple[bool, str]:
    """The JUnit file parses as XML and holds no hidden character."""
    run, result = hostile_gate(c)
    path = run / "j.xml"
    if not path.is_file():
        return False, f"no JUnit file: {result.why()}"
    text = path.read_text(errors="replace")
    try:
        ET.fromstring(text.encode())
        parses = True
    except ET.ParseError as err:
        parses = False
        text += f" (does not parse: {err})"
    found = [repr(s) for s in HIDDEN if s in text]
    return parses and not found, f"parses: {parses}; raw: {found}"


def attack_names_in_the_markdown_summary(c: Campaign, where: Path) -> tuple[bool, str]:
    """The markdown summary shows names as text."""
    run, result = hostile_gate(c)
    path = run / "m.md"
    if not path.is_file():
        return False, f"no markdown: {result.why()}"
    found = raw_in(path.read_text(), markdown=True)
    return not found, f"raw in the markdown: {found}"


def attack_names_in_the_json(c: Campaign, where: Path) -> tuple[bool, str]:
    """The JSON parses and its text holds no hidden character raw."""
    run, result = hostile_gate(c)
    path = run / "j.json"
    if not path.is_file():
        return False, f"no JSON: {result.why()}"
    text = path.read_text()
    try:
        json.loads(text)
        parses = True
    except ValueError:
        parses = False
    found = [repr(s) for s in HIDDEN if s in text]
    return parses and not found, f"parses: {parses}; raw: {found}"


def attack_names_on_the_console_of_gate(c: Campaign, where: Path) -> tuple[bool, str]:
    """``truestep gate -v`` prints names with their hidden characters shown."""
    _, result = hostile_gate(c)
    found = [repr(s) for s in HIDDEN if s in result.out + result.err]
    return not found and result.code in (0, 1), f"raw: {found}; {result.why()}"


def attack_mathtext_method_name(c: Campaign, where: Path) -> tuple[bool, str]:
    """Method names that matplotlib would read as (broken) mathtext or hide (a leading
    underscore): the run still writes its report and figures."""
    result = adapter_run(c, where, "MathText")
    figures = list((where / "rep" / "figures").glob("*.png")) if (where / "rep").is_dir() else []
    return result.code == 0 and bool(figures), result.why()


ATTACKS = [
    attack_names_in_index_md,
    attack_names_in_index_html,
    attack_names_on_the_console_of_run,
    attack_names_in_junit,
    attack_names_in_the_markdown_summary,
    attack_names_in_the_json,
    attack_names_on_the_console_of_gate,
    attack_mathtext_method_name,
]
