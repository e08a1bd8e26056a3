"""Case text is text: a hostile title, description or note can neither embed a file,
nor inject markup into ``index.md`` or ``index.html``, nor stop a figure; a case's name
cannot make truestep write outside ``--out``; nothing in a case file is evaluated.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from truestep.cases.errors import CaseError
from truestep.cases.loader import CASE_DIR, load_case
from truestep.cli import main

HOSTILE_TEXT = (
    "<script>alert(1)</script> ![x](/etc/hostname) <details open> | a | b | "
    "[link](javascript:alert(1)) **bold** `code` $\\frac{1$ # not a heading "
    "__import__('os').system('touch PWNED') {{7*7}} &amp;"
)


def _hostile_case(folder: Path) -> Path:
    text = (CASE_DIR / "free-fall.toml").read_text()
    title = "title = " + _toml_string(HOSTILE_TEXT[:190])
    text = re.sub(r"^title = .*$", lambda m: title, text, count=1, flags=re.M)
    description = "description = " + _toml_string(
        "\n# heading?\n" + HOSTILE_TEXT + "\n<img src=x onerror=alert(1)>"
    )
    text = re.sub(r'^description = """(.|\n)*?"""', lambda m: description, text, count=1, flags=re.M)
    text = text.replace('family = "particles"', 'family = "particles"\nhard = ' + _toml_string(HOSTILE_TEXT))
    path = folder / "hostile-text.toml"
    path.write_text(text)
    return path


def _toml_string(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'


@pytest.fixture(scope="module")
def report(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("hostile")
    case = _hostile_case(folder)
    out = folder / "out"
    code = main(["run", "--quick", "--cases", str(case), "--engines", "reference", "--out", str(out)])
    assert code == 0
    return out


def test_case_text_reaches_index_md_escaped(report: Path) -> None:
    md = (report / "index.md").read_text()
    raw_tags = re.findall(r"(?<!\\)<(?!/?details>|/?summary>|details><summary>)[a-zA-Z/!][^\n]{0,20}", md)
    assert raw_tags == []  # every '<' but the report's own folds is escaped
    assert "\\<script\\>" in md
    assert "![x](/etc/hostname)" not in md
    assert "\n# heading?" not in md and "\n# not a heading" not in md


def test_case_text_reaches_index_html_as_text(report: Path) -> None:
    page = (report / "index.html").read_text()
    assert "<script>" not in page and "<img src=x" not in page and "<details open>" not in page
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in page  # shown, as written
    assert "javascript:" not in re.sub(r"\[link\]\(javascript:alert\(1\)\)", "", page)
    assert 'href="javascript' not in page
    hostname = Path("/etc/hostname")
    if hostname.is_file() and hostname.read_text().strip():
        import base64

        assert base64.b64encode(hostname.read_bytes()).decode()[:12] not in page


def test_nothing_in_a_case_file_is_evaluated(report: Path) -> None:
    """TOML is data: no value is ever passed to eval, exec, a template or a shell."""
    assert not Path("PWNED").exists() and not (report / "PWNED").exists()
    assert "49" not in (report / "index.md").read_text().split("{{7*7}}")[0][-5:]
    sources = [p.read_text() for p in Path(__file__).resolve().parents[2].glob("cases/*.py")]
    root = Path(__file__).resolve().parents[2]
    harness = [*root.glob("truestep/*.py"), *root.glob("truestep/*/*.py")]
    sources += [p.read_text() for p in harness if not p.parent.is_symlink()]
    for src in sources:
        assert not re.search(r"\b(eval|exec)\(", src)


def test_a_title_with_an_unbalanced_dollar_still_draws_its_figure(report: Path) -> None:
    assert (report / "figures" / "hostile-text-work-precision.png").is_file()


@pytest.mark.parametrize(
    "name", ["..", "...", "a..b", "Upper", "dots.in.name", "ümlaut", "a_b", "-lead", "x" * 81]
)
def test_a_case_name_that_could_leave_out_is_refused(tmp_path: Path, name: str) -> None:
    """Figure files are named after the case: only lower-case ASCII words joined by dashes
    can be names, so no name can hold a path separator or a parent reference."""
    path = tmp_path / f"{name}.toml"
    path.write_text((CASE_DIR / "free-fall.toml").read_text())
    with pytest.raises(CaseError, match="<name>"):
        load_case(path)
