"""A run's record, ``run.json``: its name and how it is read back.

Its own module, light to import (no figures, no engines), for what reads a run without
drawing it: ``truestep gate``, a baseline's save, the pytest plugin.
"""

from __future__ import annotations

import os
from pathlib import Path

RUN_FILE = "run.json"
"""What a run was asked for and what decided its numbers besides the code
(:func:`truestep.reporting.report.run_record`)."""


def read_run_record(directory: Path) -> dict | None:
    """The ``run.json`` of an output directory, or ``None`` when it has none (a run of an
    older truestep). One that is there but is no run record (not JSON, not an object, cut
    short, not a regular file) is a :class:`~truestep.cases.errors.CaseError` naming it:
    what it would have said (the packages, the engines asked) is not guessed."""
    import json

    from truestep.cases.errors import CaseError
    from truestep.runtime.files import read_regular

    path = Path(directory) / RUN_FILE
    if not os.path.lexists(path):
        return None
    try:
        record = json.loads(read_regular(path, 1 << 20).decode("utf-8"))
    except (OSError, ValueError) as err:  # FileRefused is an OSError
        raise CaseError(str(path), "<file>", f"not a run record truestep can read: {err}") from None
    if not isinstance(record, dict):
        kind = type(record).__name__
        raise CaseError(str(path), "<file>", f"not a run record: a JSON {kind}, not an object")
    return record
