"""What ``truestep gate`` writes for CI: JUnit XML, a markdown summary, JSON.

JUnit: one test case per gate verdict (suite ``truestep.ci.gates``, class name the case,
name the verdict's id, :func:`truestep.ci.gates.gate_id`; file relative to the working
directory) and, with a baseline (suite ``truestep.ci.baseline``), one failing case per
row that got worse or vanished (class name ``baseline.<table>``) and one passing case per
compared table where none did. Markdown: the counts, then tables of the failed gates and
of what got worse (with the change in percent), for a pull request page (and
``$GITHUB_STEP_SUMMARY``). JSON: everything, for other tools: numbers as JSON numbers
(``null`` for one that is not finite or not measured), each gate with its ``id``, its
measured ``value`` and its ``limits`` (the gate's own numbers).
"""

from __future__ import annotations

import errno
import json
import math
import os
import stat
import xml.etree.ElementTree as ET
from pathlib import Path

from truestep.ci.baseline import Comparison
from truestep.ci.gates import GateResult
from truestep.reporting.markdown import text
from truestep.runtime.visible import visible


def shown_path(path: str) -> str:
    """``path`` as CI output shows it: relative to the working directory when it lies
    under it (a checkout's own case files), else as given (an installed package's)."""
    if not path:
        return ""
    try:
        rel = Path(path).resolve().relative_to(Path.cwd().resolve())
    except (ValueError, OSError):
        return path
    return rel.as_posix()


def _counts(verdicts: list[GateResult]) -> dict[str, int]:
    out = {"pass": 0, "fail": 0, "skip": 0}
    for v in verdicts:
        out[v.verdict] += 1
    return out


def junit(verdicts: list[GateResult], comparison: Comparison | None, reasons: list[str]) -> str:
    """The JUnit XML document (as text)."""
    suites = ET.Element("testsuites", name="truestep")
    counts = _counts(verdicts)
    gates = ET.SubElement(
        suites,
        "testsuite",
        name="truestep.ci.gates",
        tests=str(len(verdicts)),
        failures=str(counts["fail"]),
        skipped=str(counts["skip"]),
        errors="0",
    )
    for v in verdicts:
        case = ET.SubElement(
            gates,
            "testcase",
            classname=visible(v.case),
            name=visible(v.row()["id"]),
            file=visible(shown_path(v.gate.file or "")),
        )
        text = visible(f"measured {v.measured}, required {v.required}")
        if v.verdict == "fail":
            ET.SubElement(case, "failure", message=text, type="GateFailed").text = visible(v.line())
        elif v.verdict == "skip":
            ET.SubElement(case, "skipped", message=text)
        else:
            ET.SubElement(case, "system-out").text = text
    if reasons:
        strict = ET.SubElement(
            suites, "testsuite", name="truestep.strict", tests="1", failures="1", skipped="0", errors="0"
        )
        case = ET.SubElement(strict, "testcase", classname="truestep", name="something was checked")
        ET.SubElement(case, "failure", message=visible(reasons[0]), type="NothingChecked").text = "\n".join(
            visible(r) for r in reasons
        )
    if comparison is not None:
        tables = ["results", "orders", "stability", "restitution"] + (
            ["timing"] if comparison.time_against else []
        )
        worse = comparison.worse()
        base = ET.SubElement(suites, "testsuite", name="truestep.ci.baseline", skipped="0", errors="0")
        for table in tables:
            bad = [f for f in worse if f.table == table]
            if not bad:  # the table held: one passing case
                ET.SubElement(base, "testcase", classname="baseline", name=table)
            for f in bad:  # one failing case per row that got worse or vanished
                case = ET.SubElement(
                    base,
                    "testcase",
                    classname=f"baseline.{table}",
                    name=visible(f"{f.key} {f.quantity}".strip()),
                )
                ET.SubElement(case, "failure", message=visible(f.line()), type="Regression").text = visible(
                    f.line()
                )
        base.set("tests", str(sum(1 for _ in base.iter("testcase"))))
        base.set("failures", str(len(worse)))
    ET.indent(suites)
    return ET.tostring(suites, encoding="unicode", xml_declaration=True) + "\n"


def _cell(value: object) -> str:
    """A table cell of the markdown summary: its text shown as written, never as markup
    (:func:`truestep.reporting.markdown.text`)."""
    return text(value)


def markdown(
    verdicts: list[GateResult],
    comparison: Comparison | None,
    reasons: list[str],
    *,
    passed: bool,
    notes: list[str] | tuple[str, ...] = (),
) -> str:
    """A markdown summary: counts, why the check fails, notes, failed gates, regressions."""
    c = _counts(verdicts)
    lines = [
        f"### truestep gate: {'passed' if passed else 'FAILED'}",
        "",
        f"{c['pass']} gates held, {c['fail']} failed, {c['skip']} not evaluated.",
    ]
    lines += [f"- **{text(r)}**" for r in reasons]
    lines += [f"- {text(n)}" for n in notes]
    failed = [v for v in verdicts if v.verdict == "fail"]
    if failed:
        lines += [
            "",
            "| gate | where | measured | required |",
            "|---|---|---|---|",
        ]
        lines += [
            f"| {_cell(v.row()['id'])} | {_cell(v.gate.where)} | {_cell(v.measured)} | {_cell(v.required)} |"
            for v in failed
        ]
    if comparison is not None:
        n = {
            k: sum(f.change == k for f in comparison.findings)
            for k in ("worse", "better", "appeared", "vanished")
        }
        lines += [
            "",
            f"Baseline: {comparison.compared} rows compared; {n['worse']} worse, "
            f"{n['better']} better, {n['appeared']} appeared, {n['vanished']} vanished.",
        ]
        worse = comparison.worse()
        if worse:
            lines += [
                "",
                "| change | table | row | quantity | baseline | now | change % |",
                "|---|---|---|---|---|---|---|",
            ]
            lines += [
                f"| {f.change} | {f.table} | {_cell(f.key)} | {_cell(f.quantity)} | "
                f"{_cell(_fmt(f.baseline))} | {_cell(_fmt(f.current))} | {_percent(f.baseline, f.current)} |"
                for f in worse[:200]
            ]
            if len(worse) > 200:
                lines.append(f"\n... and {len(worse) - 200} more (see the JSON output).")
    return "\n".join(lines) + "\n"


def _percent(old: object, new: object) -> str:
    """How far a number moved, in percent of the baseline's (``+12.5%``); empty where either
    is not a finite number or the baseline's is 0 (a status, a row gone)."""
    if not isinstance(old, int | float) or not isinstance(new, int | float) or isinstance(old, bool):
        return ""
    if not (math.isfinite(old) and math.isfinite(new)) or old == 0:
        return ""
    return f"{(new - old) / abs(old) * 100:+.3g}%"


def _fmt(x: object) -> str:
    return f"{x:.4g}" if isinstance(x, float) else str(x)


def _clean(x: object) -> object:
    """A JSON value: numbers as numbers (numpy's too), a number that is not finite as
    ``null`` (JSON has none), tuples as lists."""
    if hasattr(x, "item") and not isinstance(x, str | bytes):
        return _clean(x.item())
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, tuple | list):
        return [_clean(i) for i in x]
    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    return x


def _gate_json(v: GateResult) -> dict:
    row = {k: _clean(val) for k, val in v.row().items()}
    row["source"] = shown_path(v.gate.file or "")
    row["limits"] = {k: _clean(val) for k, val in v.gate.params.items()}
    return row


def as_json(
    verdicts: list[GateResult],
    comparison: Comparison | None,
    reasons: list[str],
    *,
    passed: bool,
    notes: list[str] | tuple[str, ...] = (),
) -> str:
    """Everything as one JSON document."""
    doc = {
        "passed": passed,
        "counts": _counts(verdicts),
        "reasons": reasons,
        "notes": list(notes),
        "gates": [_gate_json(v) for v in verdicts],
    }
    if comparison is not None:
        doc["baseline"] = {
            "compared": comparison.compared,
            "tolerances": _clean(comparison.tolerances),
            "time_against": comparison.time_against,
            "findings": [{k: _clean(val) for k, val in f.__dict__.items()} for f in comparison.findings],
        }
    return json.dumps(doc, indent=1, ensure_ascii=True, allow_nan=False) + "\n"


def write(path: str | Path, text: str, *, append: bool = False) -> None:
    """Write ``text`` to ``path`` (append for ``$GITHUB_STEP_SUMMARY``): a regular file
    or a new one; anything else (a FIFO that would block, a device, a directory) raises
    :class:`OSError` naming it, without writing."""
    path = Path(path)
    if path.parent and not path.parent.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
    flags = os.O_WRONLY | os.O_CREAT | os.O_NONBLOCK | os.O_CLOEXEC | (os.O_APPEND if append else 0)
    if os.path.lexists(path) and not stat.S_ISREG(os.stat(path).st_mode):
        raise OSError(errno.EINVAL, "not a regular file", str(path))
    fd = os.open(path, flags, 0o644)
    with os.fdopen(fd, "a" if append else "w", encoding="utf-8") as fh:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise OSError(errno.EINVAL, "not a regular file", str(path))
        if not append:
            fh.truncate(0)
        fh.write(text)
