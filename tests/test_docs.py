"""The documentation site (``docs/``, built by ``mkdocs build --strict`` in ``.ci/run``):
every code example runs, every case-file key the loader reads is documented, and every
public name and engine has its place.

Examples run per page, in order, in a fresh interpreter whose working directory is an
empty folder: a ``python`` or ``toml`` block with a ``title`` is saved under that name
(a case file among them must load, a gates file must read); a ``python`` block without
one runs; a ``toml`` block without one must parse. ``sh`` blocks are commands a reader
types, shown, not run.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

import truestep

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PAGES = sorted(p for p in DOCS.rglob("*.md"))
BLOCK = re.compile(r'^```(\w+)(?: title="([^"]+)")?\n(.*?)^```\s*$', re.S | re.M)


def blocks(page: Path) -> list[tuple[str, str | None, str]]:
    """(language, title, code) of every fenced block of ``page``, in order."""
    return [(m.group(1), m.group(2), m.group(3)) for m in BLOCK.finditer(page.read_text())]


RUNNER = """
import json, os, sys, tomllib, traceback
from pathlib import Path
import truestep
from truestep.cases.loader import load_gates_file

def run_page(blocks, folder):
    os.chdir(folder)
    sys.path.insert(0, folder)
    namespace = {"__name__": "__main__"}  # one reader's session per page
    for lang, title, code in blocks:
        if title is not None:
            Path(title).write_text(code)
            if lang == "toml" and title != "pyproject.toml":
                doc = tomllib.loads(code)
                if "kind" in doc:
                    truestep.load_case(title)
                else:
                    load_gates_file(title)
            elif lang == "toml":
                tomllib.loads(code)
            elif lang == "python" and title.startswith("test_"):
                import pytest
                assert pytest.main(["-q", "-p", "no:cacheprovider", title]) == 0, "its test failed"
            continue
        if lang == "python":
            exec(compile(code, "<docs example>", "exec"), namespace)
        elif lang == "toml":
            tomllib.loads(code)

outcome = {}
for name, blocks, folder in PAGES:
    try:
        run_page(blocks, folder)
        outcome[name] = ""
    except BaseException:
        outcome[name] = traceback.format_exc()[-3000:]
print("OUTCOME " + json.dumps(outcome))
"""

RUNNABLE = [p for p in PAGES if any(lang in ("python", "toml") for lang, _, _ in blocks(p))]


@pytest.fixture(scope="module")
def outcomes(tmp_path_factory) -> dict[str, str]:
    """Every runnable page's examples, run in one fresh interpreter (a new namespace and an
    empty folder per page): page -> the traceback of what failed, or ``""``."""
    pages = []
    for page in RUNNABLE:
        folder = tmp_path_factory.mktemp(page.stem)
        pages.append((str(page.relative_to(DOCS)), blocks(page), str(folder)))
    code = f"PAGES = {pages!r}\n" + textwrap.dedent(RUNNER)
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=900)
    line = next((x for x in done.stdout.splitlines() if x.startswith("OUTCOME ")), None)
    assert line is not None, f"the examples did not finish:\n{done.stdout[-2000:]}\n{done.stderr[-3000:]}"
    return json.loads(line[len("OUTCOME ") :])


@pytest.mark.parametrize("page", RUNNABLE, ids=lambda p: str(p.relative_to(DOCS)))
def test_every_example_of_the_page_runs(page, outcomes):
    failed = outcomes[str(page.relative_to(DOCS))]
    assert not failed, f"{page.name}:\n{failed}"


def test_every_case_file_key_the_loader_reads_is_documented():
    """Each key a case file may hold (a literal the loader, the scene reader, the mesh
    and emitter readers or the limits read) is named on the case-file page."""
    page = (DOCS / "guides" / "case-files.md").read_text()
    sources = [ROOT / "cases" / name for name in ("loader.py", "scene.py", "meshes.py", "limits.py")]
    reads = re.compile(
        r"\b[a-z]+\.(?:string|number|numbers|integer|boolean|text|strings|array|indices|"
        r'vec3|raw|has|sub|subs)\(\s*"([A-Za-z_0-9]+)"'
    )
    keys = {k for src in sources for k in reads.findall(src.read_text())}
    assert len(keys) > 80
    missing = sorted(
        k
        for k in keys
        if f"`{k}`" not in page
        and f"[{k}]" not in page
        and f"[[scene.{k}]]" not in page
        and f"[scene.{k}]" not in page
        and f"[[run.{k}]]" not in page
        and f"[[{k}]]" not in page
    )
    assert not missing, f"keys the loader reads that guides/case-files.md never names: {missing}"


def test_every_property_is_listed_on_the_case_file_page():
    """The Properties table of the case-file page names every property a case may ask for
    (:data:`truestep.measures.properties.PROPERTIES`), and nothing else."""
    from truestep.measures.properties import PROPERTIES

    page = (DOCS / "guides" / "case-files.md").read_text()
    section = page.split("## Properties", 1)[1].split("\n## ", 1)[0]
    listed = set(re.findall(r"^\| `([a-z_]+)` \|", section, flags=re.M))
    assert listed == set(PROPERTIES)


def test_every_public_name_and_engine_has_its_page():
    api = (DOCS / "reference" / "api.md").read_text()
    missing = [n for n in truestep.__all__ if not n.startswith("_") and f"- {n}\n" not in api]
    assert not missing, f"public names not on reference/api.md: {missing}"
    from truestep.adapters import BUILTIN

    nav = (ROOT / "mkdocs.yml").read_text()
    for engine in BUILTIN:
        assert f"engines/{engine}.md" in nav and (DOCS / "engines" / f"{engine}.md").is_file()
