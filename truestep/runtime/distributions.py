"""Which installed distributions hold a top-level module, found without building
:func:`importlib.metadata.packages_distributions`' map of every one (slow with many
distributions installed: it turns each distribution's RECORD into path objects)."""

from __future__ import annotations

from importlib import metadata

__all__ = ["holding"]


def _tops(dist: metadata.Distribution) -> set[str]:
    """The top-level names ``dist`` declares (``top_level.txt``), else those its files
    imply (a ``.py`` file's first path part, or its stem at the top): as
    ``packages_distributions`` reads them."""
    declared = (dist.read_text("top_level.txt") or "").split()
    if declared:
        return set(declared)
    record = dist.read_text("RECORD")
    if record is None:
        files = dist.files or []
        paths = [file.as_posix() for file in files]
    else:
        paths = [line.rsplit(",", 2)[0].strip('"') for line in record.splitlines() if line]
    tops = set()
    for path in paths:
        if path.endswith(".py"):
            parts = path.split("/")
            tops.add(parts[0] if len(parts) > 1 else parts[0][: -len(".py")])
    return tops


def holding(top: str) -> list[str]:
    """The names of the installed distributions that hold the top-level module or package
    ``top``, in the order :func:`importlib.metadata.distributions` finds them
    (``packages_distributions().get(top, [])``)."""
    return [dist.metadata["Name"] for dist in metadata.distributions() if top in _tops(dist)]
