"""The published report as a user sees it: a page that parses, embeds its figures, names
every case, and renders in a browser."""

from __future__ import annotations

import base64
import binascii
import io
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from PIL import Image

from truestep.cases import load_cases
from truestep.cli import main
from truestep.execution.analyses import run_analyses
from truestep.execution.runner import run_matrix
from truestep.figures.lecture import FIGURES
from truestep.reporting.report import write_report

CHROMIUM = Path("/usr/bin/chromium")
VOID = {"area", "base", "br", "col", "embed", "hr", "img", "input", "link", "meta", "source", "track", "wbr"}
"""HTML elements that never have a closing tag."""


@pytest.fixture(scope="module")
def report(tmp_path_factory) -> Path:
    """A report as `truestep run` writes it, on short sweeps but with the lecture's figures
    (which `--quick` leaves out): the runner, the analyses and the writer of the CLI."""
    out = tmp_path_factory.mktemp("report")
    cases = load_cases("circle-field")
    engines = ["reference", "scipy"]
    traces: dict = {}
    results = run_matrix(cases, engines, quick=True, traces=traces, progress=lambda _: None)
    tables = run_analyses(cases, engines, results, quick=True)
    write_report(
        out, cases, results, tables, quick=True, argv=["run"], traces=traces, with_lecture_figures=True
    )
    return out


def test_the_cli_writes_the_same_files(tmp_path):
    assert (
        main(["run", "--quick", "--cases", "circle-field", "--engines", "reference", "--out", str(tmp_path)])
        == 0
    )
    page = (tmp_path / "index.html").read_text()
    assert "circle-field" in page and "Not redrawn in a <code>--quick</code> run" in page


class PageParser(HTMLParser):
    """Collects tag-balance errors, the attributes of every <img>, and external URLs."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.stack: list[tuple[str, tuple[int, int]]] = []
        self.errors: list[str] = []
        self.images: list[dict[str, str | None]] = []
        self.external: list[str] = []
        self.texts: list[str] = []
        self.doctype = False

    def handle_data(self, data: str) -> None:
        self.texts.append(data)

    def handle_decl(self, decl: str) -> None:
        self.doctype = self.doctype or decl.lower().startswith("doctype")

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        if tag == "img":
            self.images.append(a)
        for key in ("src", "href"):
            value = a.get(key) or ""
            if value.startswith(("http:", "https:", "//")) and tag in {"img", "script", "link"}:
                self.external.append(f"<{tag} {key}={value}>")
        if tag not in VOID:
            self.stack.append((tag, self.getpos()))

    def handle_startendtag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        if tag not in VOID:
            self.errors.append(f"<{tag}/> at {self.getpos()} is not a void element")
        if tag == "img":
            self.images.append(dict(attrs))

    def handle_endtag(self, tag: str) -> None:
        if tag in VOID:
            self.errors.append(f"</{tag}> at {self.getpos()} closes a void element")
            return
        if not self.stack or self.stack[-1][0] != tag:
            opened = self.stack[-1] if self.stack else None
            self.errors.append(f"</{tag}> at {self.getpos()} but the open element is {opened}")
            return
        self.stack.pop()


@pytest.fixture(scope="module")
def page(report) -> tuple[str, PageParser]:
    text = (report / "index.html").read_text(encoding="utf-8")
    parser = PageParser()
    parser.feed(text)
    parser.close()
    return text, parser


def _decode_png(data: bytes) -> np.ndarray:
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    with Image.open(io.BytesIO(data)) as img:
        assert img.format == "PNG"
        return np.asarray(img.convert("RGB"))


def _distinct_colours(pixels: np.ndarray) -> int:
    """Number of distinct RGB colours in an image (H, W, 3) of 0..255 values."""
    rgb = pixels.reshape(-1, 3).astype(np.uint32)
    return len(np.unique((rgb[:, 0] << 16) | (rgb[:, 1] << 8) | rgb[:, 2]))


def test_the_page_parses_with_balanced_tags(page):
    _, parser = page
    assert parser.doctype, "no <!DOCTYPE html>"
    assert parser.errors == []
    assert parser.stack == [], f"elements never closed: {parser.stack}"


def test_the_page_opens_offline(page):
    _, parser = page
    assert parser.external == []


def test_every_image_is_an_embedded_png_that_decodes(page):
    _, parser = page
    assert parser.images, "the report embeds no figure"
    prefix = "data:image/png;base64,"
    for img in parser.images:
        src = img.get("src") or ""
        assert src.startswith(prefix), f"not an embedded PNG: {src[:60]!r}"
        assert img.get("alt"), "an image without alt text"
        try:
            data = base64.b64decode(src[len(prefix) :], validate=True)
        except binascii.Error as err:
            pytest.fail(f"bad base64 in {img.get('alt')!r}: {err}")
        pixels = _decode_png(data)
        assert pixels.shape[0] > 100 and pixels.shape[1] > 100, img.get("alt")
        # Every figure is drawn at least 1000 pixels across, its text at a readable size.
        assert pixels.shape[1] >= 1000, (img.get("alt"), pixels.shape)


def test_every_case_section_ends_in_its_conclusion_and_the_names_are_explained(report):
    """Each case's section closes with its computed conclusion, whose most accurate run is
    the run of least error in results.csv (read here by another route); the glossary under
    the scorecard explains every engine/method of the run."""
    md = (report / "index.md").read_text()
    results = pd.read_csv(report / "results.csv")
    sections = md.split("\n### ")[1:]
    for case, rows in results.groupby("case"):
        section = next(sec for sec in sections if sec.startswith(f"{case}:"))
        assert "**In short:**" in section, case
        ok = rows[(rows["status"] == "ok") & rows["error"].notna()]
        if len(ok):
            best = ok.loc[ok["error"].idxmin()]
            line = section[section.index("**In short:**") :].splitlines()[0]
            assert f"the most accurate is {best['engine']} / {best['method']} (" in line, (case, line)
    glossary = md[md.index("What the names and numbers mean") :].split("</details>")[0]
    for engine, method in results[["engine", "method"]].drop_duplicates().itertuples(index=False):
        assert f"**{engine} / {method}**:" in glossary, (engine, method)


def test_every_case_in_the_results_appears_in_the_page(report, page):
    text, _ = page
    results = pd.read_csv(report / "results.csv")
    cases = sorted(set(results["case"]))
    assert cases, "results.csv has no rows"
    for case in cases:
        assert case in text, case
    for engine in sorted(set(results["engine"])):
        assert engine in text, engine


def test_the_lecture_figures_are_embedded_with_their_captions(page):
    _, parser = page
    lecture = [
        img for img in parser.images if (img.get("alt") or "").startswith("Reproduces the lecture slide")
    ]
    assert len(lecture) == len(FIGURES)
    shown = " ".join(parser.texts)
    for img in lecture:
        # The caption is also printed under its image, so a reader sees which slide it is.
        assert img["alt"] in shown, img["alt"][:80]


@pytest.mark.skipif(
    not CHROMIUM.exists(),
    reason=f"no headless browser: {CHROMIUM} is not installed (Debian package "
    "'chromium'); the HTML is still parsed and its images decoded above",
)
def test_the_page_renders_in_headless_chromium(report, tmp_path):
    shot = tmp_path / "page.png"
    cmd = [
        str(CHROMIUM),
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        f"--user-data-dir={tmp_path / 'profile'}",
        f"--screenshot={shot}",
        "--window-size=1200,2000",
        (report / "index.html").resolve().as_uri(),
    ]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120, check=False)
    assert shot.is_file(), f"no screenshot (exit {proc.returncode}): {proc.stderr[-2000:]}"
    pixels = _decode_png(shot.read_bytes())
    assert pixels.shape[:2] == (2000, 1200)
    # A rendered page has text and figures: many distinct colours, not one flat colour.
    assert _distinct_colours(pixels) > 50
    assert pixels.astype(float).std() > 10.0


def test_hard_case_summary_counts_tunnelling_as_failure():
    """A run that finishes but tunnels through the wall has not survived that step."""
    from truestep.reporting.report import hard_case_line, survival

    case = load_cases("high-speed-impact")[0]
    rows = [
        ("reference", "lecture", 1e-3, "ok", 1.0),
        ("reference", "lecture", 5e-5, "ok", 0.0),
        ("mujoco", "Euler", 1e-3, "unstable", np.nan),
        ("mujoco", "Euler", 5e-5, "ok", 1.0),
        ("pymunk", "default", 1e-3, "ok", 0.0),
        ("pymunk", "default", 5e-5, "ok", 0.0),
    ]
    results = pd.DataFrame(rows, columns=["engine", "method", "dt", "status", "tunnelled"]).assign(
        case=case.name, dt_kind="step"
    )
    s = survival(case, results).set_index("engine")
    assert s.loc["reference", "dt_survived"] == 5e-5 and s.loc["reference", "failure"] == "tunnelled"
    assert np.isnan(s.loc["mujoco", "dt_survived"]) and s.loc["mujoco", "failure"] == "unstable"
    assert s.loc["pymunk", "dt_survived"] == 1e-3 and s.loc["pymunk", "failure"] == ""
    line = hard_case_line(case, survival(case, results))
    assert line.index("pymunk/default") < line.index("reference/lecture")
    assert "at no step of the sweep: mujoco/Euler (unstable)" in line


def test_speed_table_gives_particle_steps_per_second_and_ratios():
    from truestep.reporting.report import speed_section, speed_table, speed_tables

    case = load_cases("particle-rain")[0]
    n = case.model.n
    rows = [
        ("reference", "lecture", 1e-3, 0.004, 1500, 2.8e-3),
        ("pymunk", "default", 1e-3, 0.4, 1500, 2.7e-3),
        ("mujoco", "Euler", 1e-3, 0.6, 1500, 9.9e-2),
    ]
    results = pd.DataFrame(rows, columns=["engine", "method", "dt", "wall_s", "steps", "error"]).assign(
        case=case.name, dt_kind="step", status="ok"
    )
    t = speed_table(case, results, "reference", "lecture").set_index("engine")
    assert t.loc["reference", "particle_steps_per_s"] == pytest.approx(n * 1500 / 0.004)
    assert t.loc["pymunk", "slower_by"] == pytest.approx(100.0)
    assert t.loc["mujoco", "slower_by"] == pytest.approx(150.0)
    text = "\n".join(speed_section([case], speed_tables([case], results)))
    # 0.4 s and 0.004 s, each known to a factor 1.15 (TIE_NOISE): (0.4 / 1.15) / (0.004 * 1.15)
    # = 75.6 to (0.4 * 1.15) / (0.004 / 1.15) = 132.25
    assert "the fastest engine, pymunk / default, takes 76 to 132 times as long" in text
    assert "(100 times by the median wall times" in text
    tied = results.assign(wall_s=results["wall_s"].where(results["engine"] != "mujoco", 0.45))
    text = "\n".join(speed_section([case], speed_tables([case], tied)))
    assert "the fastest engines, mujoco / Euler and pymunk / default (tied within timing noise)" in text
    assert "Contact law" not in text


def test_the_rain_table_names_the_contact_laws_that_miss_the_asked_restitution_at_some_phase():
    """Issue 35, item 4: under the particle-rain table, the engines and methods of the table
    whose restitution drops leave the asked e at some impact phase are named (their errors
    there are partly their contact law's); one the table does not show is not."""
    from truestep.measures.restitution import phase_contact
    from truestep.reporting.report import speed_section, speed_tables

    case = load_cases("particle-rain")[0]
    rows = [("reference", "lecture", 0.004, 2.8e-3), ("newton", "semi-implicit", 0.1, 0.38)]
    results = pd.DataFrame(rows, columns=["engine", "method", "wall_s", "error"]).assign(
        case=case.name, dt=1e-3, dt_kind="step", status="ok", steps=1500
    )
    drops = pd.DataFrame(
        [
            ("newton", "semi-implicit", 0.336, 0.525, 0.424),  # off by 0.164 at some phase
            ("mujoco", "Euler", 0.3, 0.7, 0.5),  # off, but not in this table
            ("reference", "lecture", 0.499, 0.501, 0.5),  # within the band
        ],
        columns=["engine", "method", "e_phase_min", "e_phase_max", "e_phase_median"],
    ).assign(dt=1e-3, e_set=0.5, phases=16, status="ok", bounce=1)
    text = "\n".join(speed_section([case], speed_tables([case], results), phase_contact(drops)))
    (line,) = [x for x in text.splitlines() if x.startswith("**Contact law:**")]
    assert "from newton / semi-implicit (the summary" in line
    assert "mujoco" not in line and "reference" not in line


def test_an_image_line_from_case_text_reads_nothing(tmp_path):
    from truestep.reporting.html import markdown_to_html

    secret = tmp_path / "secret.png"
    secret.write_bytes(b"not for the report")
    (tmp_path / "figures").mkdir()
    (tmp_path / "figures" / "ok.png").write_bytes(b"\x89PNG drawn")
    md = "\n".join(
        [f"![x]({secret})", "![y](../secret.png)", "![z](figures/missing.png)", "![w](figures/ok.png)"]
    )
    page = markdown_to_html(md, tmp_path)
    assert page.count("data:image/png;base64,") == 1  # only the report's own figure
    assert "bm90IGZvciB0aGUgcmVwb3J0" not in page  # base64 of the secret
    assert "figures/missing.png" in page  # shown as text, no traceback
