"""The report's markdown as one self-contained HTML page (figures inlined).

A small conversion for the subset the report writes: headings (with anchors), images,
pipe tables, bullet lists, links, bold and code, ``<details>`` blocks, rules.
"""

from __future__ import annotations

import base64
import html
import re
from pathlib import Path

from truestep.reporting.markdown import ESCAPED, slug

_PRIVATE = 0xE000
"""Escaped characters are held as private-use code points while markup is read."""


def _protect(text: str) -> str:
    """Backslash-escaped characters (:func:`~truestep.reporting.markdown.text`) out of the
    way of the markup rules."""
    return re.sub("\\\\([" + re.escape(ESCAPED) + "])", lambda m: chr(_PRIVATE + ord(m.group(1))), text)


def _restore(text: str) -> str:
    """The protected characters back, as HTML text (escaped)."""
    return re.sub("[\ue000-\ue07f]", lambda m: html.escape(chr(ord(m.group()) - _PRIVATE)), text)


def _own_figure(base: Path, target: str) -> Path | None:
    """``base / target`` if it is a PNG the report drew (directly under ``base/figures``),
    else ``None``: an image line from case text can name any path, and none is read."""
    if not re.fullmatch(r"figures/[\w.-]+\.png", target) or ".." in target:
        return None
    path = base / target
    return path if path.is_file() and not path.is_symlink() else None


def markdown_to_html(md: str, base: Path) -> str:
    """A small Markdown-to-HTML conversion for the report's own subset, images inlined;
    headings get the anchors :func:`~truestep.reporting.markdown.slug` gives them."""
    out: list[str] = []
    lines = md.splitlines()
    i = 0

    def inline(text: str) -> str:
        text = html.escape(_protect(text))
        text = re.sub(r"\*\*(.+?)\*\*", r"<strong>\1</strong>", text)
        text = re.sub(r"`(.+?)`", r"<code>\1</code>", text)
        text = re.sub(r"\[([^\]]+)\]\((#[\w-]+)\)", r'<a href="\2">\1</a>', text)
        text = _restore(text)
        return text.replace("  ", "<br>") if text.endswith("  ") else text

    while i < len(lines):
        line = lines[i]
        if line.startswith("#"):
            level = len(line) - len(line.lstrip("#"))
            title = line[level:].strip()
            out.append(f'<h{level} id="{slug(title)}">{inline(title)}</h{level}>')
        elif line.startswith(("<details", "</details")):
            m = re.match(r"<details><summary>(.*)</summary>", line)
            out.append(f"<details><summary>{inline(m.group(1))}</summary>" if m else line)
        elif line.startswith("!["):
            m = re.match(r"!\[(.*?)\]\((.*?)\)", line)
            figure = _own_figure(base, m.group(2)) if m else None
            if m is not None and figure is not None:
                data = base64.b64encode(figure.read_bytes()).decode()
                out.append(
                    f'<figure><img alt="{html.escape(m.group(1))}" '
                    f'src="data:image/png;base64,{data}"></figure>'
                )
            else:
                out.append(f"<p>{inline(line)}</p>")  # text, as written: nothing is read
        elif line.startswith("|"):
            rows = []
            while i < len(lines) and lines[i].startswith("|"):
                rows.append([c.strip() for c in _protect(lines[i]).strip("|").split("|")])
                i += 1
            head, body = rows[0], rows[2:]
            out.append(
                "<table><thead><tr>" + "".join(f"<th>{inline(c)}</th>" for c in head) + "</tr></thead><tbody>"
            )
            out.extend("<tr>" + "".join(f"<td>{inline(c)}</td>" for c in r) + "</tr>" for r in body)
            out.append("</tbody></table>")
            continue
        elif line.startswith("- "):
            out.append("<ul>")
            while i < len(lines) and lines[i].startswith("- "):
                out.append(f"<li>{inline(lines[i][2:])}</li>")
                i += 1
            out.append("</ul>")
            continue
        elif line.strip() == "---":
            out.append("<hr>")
        elif line.strip():
            out.append(f"<p>{inline(line)}</p>")
        i += 1
    style = (
        "body{font-family:system-ui,sans-serif;max-width:1320px;margin:2em auto;"
        "padding:0 1em;color:#222}table{border-collapse:collapse;font-size:12px;"
        "margin:1em 0}td,th{border:1px solid #ccc;padding:2px 6px;text-align:right}"
        "th{background:#f3f3f3}img{max-width:100%}code{background:#f3f3f3}"
        "details{margin:.5em 0}summary{cursor:pointer;color:#1f5fa8}"
    )
    return (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        f"<title>truestep report</title><style>{style}</style></head><body>\n"
        + "\n".join(out)
        + "\n</body></html>\n"
    )
