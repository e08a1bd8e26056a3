"""Names and texts from outside are shown as what they are in every output: markup as
text, and every control, bidirectional or zero-width character spelt out."""

from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ET

import pandas as pd
import pytest

from truestep.cases.case import Gate
from truestep.ci import outputs as ci_outputs
from truestep.ci.baseline import compare
from truestep.ci.gates import GateResult
from truestep.reporting.html import markdown_to_html
from truestep.reporting.markdown import md_table, text
from truestep.runtime.visible import visible

HIDDEN = [
    "\u202e",
    "\u202d",
    "\u2066",
    "\u200b",
    "\u200f",
    "\ufeff",
    "\x1b",
    "\x07",
    "\x00",
    "\x7f",
    "\u2028",
    "\u2029",
    "\ud800",
    "\ue000",
    "\U000e0041",
]
ENGINE = "evil<script>alert(1)</script>\u202e"
METHOD = "<img src=x onerror=alert(1)>|`nan`\x1b[2J"


@pytest.mark.parametrize("ch", HIDDEN)
def test_every_hidden_character_is_spelt_out(ch):
    shown = visible(f"a{ch}b")
    assert ch not in shown and shown.startswith("a\\") and shown.endswith("b")


def test_visible_keeps_printable_text_of_any_script():
    assert visible("verlet é 中文 Ω a|b <x>") == "verlet é 中文 Ω a|b <x>"
    assert visible("a\nb\tc") == "a\\nb\\tc"


def _unescaped_tags(md: str) -> list[str]:
    return re.findall(r"(?<!\\)<(?:script|img)", md)


def test_markdown_and_html_show_names_as_text():
    md = md_table(pd.DataFrame({"engine": [ENGINE], "method": [METHOD]}))
    md += f"\n- {text(ENGINE)} / {text(METHOD)}\n"
    assert not _unescaped_tags(md) and not any(ch in md for ch in HIDDEN)
    page = markdown_to_html(md, base=__import__("pathlib").Path("."))
    assert "<script>" not in page and "<img" not in page
    assert "\\u202e" in page and "\u202e" not in page


def _verdicts() -> list[GateResult]:
    gate = Gate("error", ENGINE, METHOD, 0.01, {"max": 0.0}, "gates[0]", file="g\u202e.toml")
    return [
        GateResult("free-fall\x1b", gate, False, "1e-3 \u202e", "<= 0"),
        GateResult("free-fall", gate, True, "0", "<= 1", evaluated=False),
    ]


def test_ci_outputs_show_names_as_text():
    verdicts = _verdicts()
    base = pd.DataFrame(
        {
            "case": ["c"],
            "engine": [ENGINE],
            "method": [METHOD],
            "dt": [0.01],
            "dt_kind": ["step"],
            "status": ["ok"],
            "error": [1.0],
            "energy_drift": [0.0],
            "nfev": [10.0],
        }
    )
    worse = base.assign(error=2.0)
    comparison = compare({"results": base}, {"results": worse})
    xml = ci_outputs.junit(verdicts, comparison, ["nothing \u202e"])
    ET.fromstring(xml.encode())
    assert not any(ch in xml for ch in HIDDEN)
    md = ci_outputs.markdown(verdicts, comparison, ["nothing \u202e"], passed=False)
    assert not _unescaped_tags(md) and not any(ch in md for ch in HIDDEN)
    doc = ci_outputs.as_json(verdicts, comparison, [], passed=False)
    assert not any(ch in doc for ch in HIDDEN)
    assert json.loads(doc)["gates"][0]["engine"] == ENGINE  # the name itself, for tools


def test_console_lines_show_hidden_characters(capsys):
    from truestep.cli import main

    assert main(["run", "--engines", "no\u202esuch\x1b[2J"]) == 2
    err = capsys.readouterr().err
    assert "\\u202e" in err and not any(ch in err for ch in HIDDEN)


def test_the_pytest_plugin_s_verdict_lines_show_hidden_characters():
    """The pytest plugin's failed and skipped gates say what the CLI's console says, hidden
    characters spelt out (the same ``GateResult.line`` through :func:`visible`)."""
    from truestep.pytest_plugin import GateCheck

    gate = Gate("error", ENGINE, METHOD, 0.01, {"max": 0.0}, "gates[0]")
    verdicts = [
        GateResult("free-fall\x1b", gate, False, "1e-3 \u202e", "<= 0"),
        GateResult("free-fall\x1b", gate, True, "\u202e", "<= 1", evaluated=False),
    ]
    for verdict, outcome in zip(verdicts, (pytest.fail.Exception, pytest.skip.Exception), strict=True):

        class Fixed(GateCheck):
            def result(self, verdict=verdict):
                return verdict

        with pytest.raises(outcome) as said:
            Fixed(None, None, gate).check()
        assert "\\u202e" in str(said.value) and not any(ch in str(said.value) for ch in HIDDEN)
        assert visible(verdict.line()) in str(said.value)
