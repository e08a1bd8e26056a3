"""The one error a bad case file raises: file, field and reason, on one line."""

from __future__ import annotations


class CaseError(ValueError):
    """A case file that cannot be used, with where and why.

    ``str(err)`` is ``"<file>: <field>: <reason>"``, ready to print as the CLI's
    single error line.
    """

    def __init__(self, file: str, field: str, reason: str) -> None:
        self.file, self.field, self.reason = file, field, reason
        super().__init__(f"{file}: {field}: {reason}")


class SelectionError(ValueError):
    """A case selection (``--cases``) that names nothing, or names two cases alike.

    ``str(err)`` is one line for the CLI (exit code 2).
    """
