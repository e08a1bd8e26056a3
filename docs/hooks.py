"""MkDocs hook: pages that are generated from the code they document.

``<!-- truestep:tables -->`` becomes the tables' column documentation
(:func:`truestep.tables.spec.markdown`, the same text as the README's), and
``<!-- truestep:cli COMMAND -->`` the ``--help`` of that ``truestep`` command. In the
rendered docstrings, Sphinx roles (``:func:`name```) are shown as the code they name.
"""

from __future__ import annotations

import contextlib
import io
import re

from truestep.cli import build_parser
from truestep.tables.spec import markdown

CLI = re.compile(r"<!-- truestep:cli ?([a-z]*) -->")
ROLE = re.compile(r":(?:meth|func|class|mod|data|attr|exc|obj):(?=<code)")


def _help(command: str) -> str:
    argv = [command, "--help"] if command else ["--help"]
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.suppress(SystemExit):
        build_parser().parse_args(argv)
    return "```text\n" + out.getvalue().rstrip() + "\n```"


def on_page_markdown(text: str, **_: object) -> str:
    text = text.replace("<!-- truestep:tables -->", markdown())
    return CLI.sub(lambda m: _help(m.group(1)), text)


def on_page_content(html: str, **_: object) -> str:
    return ROLE.sub("", html)
