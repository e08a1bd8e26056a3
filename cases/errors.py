"""The one error a bad case file raises: file, field and reason, on one line."""

from __future__ import annotations

MAX_REASON = 240
"""The longest reason an error line carries (a longer one is cut, with ``...``)."""
LINE = 300
"""The longest whole line (file, field and reason) an error aims for; a file path so long
that the reason would get fewer than 60 characters is the one excess allowed."""


def _one_line(text: str, limit: int) -> str:
    text = " ".join(str(text).split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


class CaseError(ValueError):
    """A case file that cannot be used, with where and why.

    ``str(err)`` is ``"<file>: <field>: <reason>"``, ready to print as the CLI's
    single error line: one line, the field and reason cut to a few hundred characters.
    """

    def __init__(self, file: str, field: str, reason: str) -> None:
        field = _one_line(field, 80)
        reason = _one_line(reason, max(60, min(MAX_REASON, LINE - len(file) - len(field) - 4)))
        self.file, self.field, self.reason = file, field, reason
        super().__init__(f"{file}: {field}: {reason}")


class SelectionError(ValueError):
    """A case selection (``--cases``) that names nothing, or names two cases alike.

    ``str(err)`` is one line for the CLI (exit code 2).
    """
