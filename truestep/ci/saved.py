"""A baseline kept on purpose: ``truestep baseline save DIR``.

A baseline is a run's tables (``results.csv``, ``stability.csv``, ``restitution.csv``) and
its ``run.json``, copied cell for cell, with what ties them to one machine or checkout
taken out (each row's ``host``; absolute paths in ``case_source`` and the command, made
relative to the project root where they lie under it) and a provenance record beside them
(``provenance.json``): the truestep that ran them and that saved them, every engine's
distribution version, and the project's git revision when the project is a checkout.
``truestep gate --baseline DIR`` reads it as it reads any run's folder.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from importlib import metadata
from pathlib import Path

import pandas as pd

MARKER = ".truestep-baseline"
"""The file that marks a folder as a baseline truestep saved (and may replace)."""
TABLE_FILES = ("results.csv", "stability.csv", "restitution.csv")
"""The tables a baseline keeps (``scaling.csv`` is timing only, and not compared)."""
RUN_FILE = "run.json"
PROVENANCE = "provenance.json"
STAGE_MARKER = ".truestep-saving"
"""The file that marks the folder a save writes through (``.DIR.saving``) as truestep's:
a save killed before it was done leaves it, and the next save replaces it; a folder of
that name without it is the user's, and is never deleted."""
FILES = (*TABLE_FILES, RUN_FILE, PROVENANCE, MARKER)


class BaselineRefused(Exception):
    """A folder or run a baseline cannot be saved into or from; ``str()`` is one line."""


def _relative(text: str, root: Path) -> str:
    """``text`` as a path relative to ``root`` where it is an absolute path under it, an
    absolute path elsewhere as its file name, anything else as it is."""
    if not text or not os.path.isabs(text):
        return text
    try:
        return Path(text).resolve().relative_to(root.resolve()).as_posix()
    except (ValueError, OSError):
        return Path(text).name


def git_state(root: Path) -> dict[str, object] | None:
    """The project's git revision at ``root`` and whether its tracked files differ from it
    (``{"revision": ..., "dirty": ...}``), or ``None`` outside a checkout."""

    def git(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run(["git", *args], cwd=root, capture_output=True, text=True, check=False)

    try:
        head = git("rev-parse", "HEAD")
        if head.returncode != 0:
            return None
        dirty = git("status", "--porcelain", "--untracked-files=no")
    except OSError:
        return None
    return {"revision": head.stdout.strip(), "dirty": bool(dirty.stdout.strip())}


def engine_versions(engines: list[str], packages: dict[str, str]) -> dict[str, str]:
    """Each engine's distribution and version (``"name 1.2"``): a built-in engine's library
    as the run recorded it (``packages``, ``run.json``), any other's the distribution that
    holds the module its registration names (found without importing it); ``""`` where
    none does (an engine given as ``module:Class`` from a path)."""
    from truestep.adapters import LIBRARIES, registered
    from truestep.runtime.distributions import holding

    targets = registered()
    libraries = LIBRARIES
    out = {}
    for engine in engines:
        library = libraries.get(engine)
        if library is not None and library in packages:
            out[engine] = f"{library} {packages[library]}"
            continue
        target = targets.get(engine, engine if ":" in engine else "")
        top = target.partition(":")[0].split(".")[0]
        dists = holding(top) if top else []
        out[engine] = f"{dists[0]} {metadata.version(dists[0])}" if dists else ""
    return out


def _check_dest(dest: Path) -> None:
    if not os.path.lexists(dest):
        return
    if dest.is_symlink() or not dest.is_dir():
        raise BaselineRefused(f"{dest}: exists and is not a folder truestep saved a baseline in")
    entries = {p.name for p in dest.iterdir()}
    if entries and (MARKER not in entries or not entries <= set(FILES)):
        raise BaselineRefused(
            f"{dest}: holds files that are not a baseline truestep saved "
            f"({', '.join(sorted(entries - set(FILES))[:5]) or 'no ' + MARKER}): nothing written"
        )


def save(results: Path, dest: Path, *, root: Path | None = None) -> dict:
    """Save the run whose ``results.csv`` is ``results`` as a baseline in ``dest`` (a new
    or empty folder, or a baseline saved before, replaced as a whole); paths are made
    relative to ``root`` (default: the working directory, the project's root). Returns
    the provenance record."""
    from truestep import __version__
    from truestep.reporting.run_record import read_run_record

    root = Path.cwd() if root is None else root
    run_dir = results.parent
    missing = [n for n in TABLE_FILES if not (run_dir / n).is_file()]
    if missing:
        raise BaselineRefused(f"{run_dir}: no {', '.join(missing)} beside {results.name}: not a run's folder")
    _check_dest(dest)
    record = read_run_record(run_dir)
    if record is None:
        raise BaselineRefused(
            f"{run_dir}/{RUN_FILE}: missing or unreadable: a baseline needs the run's record"
        )
    stage = dest.with_name(f".{dest.name}.saving")
    if os.path.lexists(stage) and not (stage / STAGE_MARKER).is_file():
        raise BaselineRefused(
            f"{stage}: a folder truestep did not write is in the place it saves through: "
            "move it, or save under another name"
        )
    shutil.rmtree(stage, ignore_errors=True)  # a save killed before it was done
    stage.mkdir(parents=True)
    (stage / STAGE_MARKER).touch()
    try:
        for name in TABLE_FILES:
            table = pd.read_csv(run_dir / name, dtype=str, keep_default_na=False, na_filter=False)
            if "host" in table:
                table["host"] = ""
            if "case_source" in table:
                table["case_source"] = [_relative(s, root) for s in table["case_source"]]
            table.to_csv(stage / name, index=False)
        record["command"] = " ".join(
            _relative(word, root) for word in str(record.get("command", "")).split(" ")
        )
        record.pop("seconds", None)
        (stage / RUN_FILE).write_text(json.dumps(record, indent=1) + "\n")
        engines = list(
            pd.read_csv(stage / "results.csv", dtype=str, usecols=["engine"])["engine"].drop_duplicates()
        )
        packages = record.get("numerics", {}).get("packages", {})
        provenance = {
            "saved_by": f"truestep {__version__}",
            "ran_with": f"truestep {record.get('truestep', '')}",
            "truestep_revision": record.get("revision", ""),
            "quick": record.get("quick"),
            "packages": packages,
            "engines": engine_versions(engines, packages),
            "project": git_state(root),
        }
        (stage / PROVENANCE).write_text(json.dumps(provenance, indent=1, sort_keys=True) + "\n")
        (stage / MARKER).write_text('{"written_by": "truestep", "kind": "baseline", "schema": 1}\n')
        (stage / STAGE_MARKER).unlink()
        if os.path.lexists(dest):
            shutil.rmtree(dest)
        stage.rename(dest)
    finally:
        shutil.rmtree(stage, ignore_errors=True)
    return provenance
