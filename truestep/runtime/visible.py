"""Text from outside shown as what it is: every invisible or reordering character spelt out.

A name or message that an adapter, a case file or a table hands over may hold control
characters (a terminal escape, a carriage return that overwrites a line), bidirectional
controls (U+202E turns the rest of a line around), zero-width characters and line
separators. :func:`visible` writes each of them as a ``\\uXXXX`` escape (``\\n``, ``\\r``
and ``\\t`` for the common three), so what a reader sees is every character there is. It
is applied to everything truestep prints and writes that came from outside: console
lines, the report (through :func:`truestep.reporting.markdown.text`), JUnit and the
markdown summary.
"""

from __future__ import annotations

import re
import unicodedata

_SHOWN_AS = {"\n": "\\n", "\r": "\\r", "\t": "\\t"}
HIDDEN_CATEGORIES = frozenset({"Cc", "Cf", "Cs", "Co", "Cn", "Zl", "Zp"})
"""Unicode categories written as escapes: controls, format characters (bidirectional
controls, zero-width joiners), surrogates, private use, unassigned, line and paragraph
separators."""
_CANDIDATE = re.compile(r"[^\x20-\x7e]")
"""Characters that may need an escape: all but printable ASCII (a quick first pass)."""


def _escape(ch: str) -> str:
    if ch in _SHOWN_AS:
        return _SHOWN_AS[ch]
    if unicodedata.category(ch) not in HIDDEN_CATEGORIES:
        return ch
    code = ord(ch)
    return f"\\u{code:04x}" if code <= 0xFFFF else f"\\U{code:08x}"


def visible(text: object) -> str:
    """``str(text)`` with every control, format, private-use, unassigned or separator
    character written as an escape (``\\u202e``, ``\\x1b`` as ``\\u001b``, ``\\n``)."""
    return _CANDIDATE.sub(lambda m: _escape(m.group()), str(text))
