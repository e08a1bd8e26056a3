"""Planted checkpoints under ``--resume``: never loaded, never run."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

from hostile_attacks.common import (
    Campaign,
    Plant,
    mkfifo,
    payload,
    tables_without_timing,
)


def interrupted(c: Campaign, where: Path) -> Path:
    """A run of :data:`BASE_CASES` killed in its sweep: its journal beside ``where/rep``."""
    c.base_report()
    shutil.copytree(c.base_report(), where / "rep")
    result = c.quick_run(where, "rep", env=c.env(TRUESTEP_KILL_AT="sweep:20"))
    journal = where / ".rep.partial"
    if not result.killed or not journal.is_dir():
        raise RuntimeError(f"the interrupted run did not leave a journal: {result.why()}")
    return journal


def resumed(c: Campaign, where: Path, mark: Path) -> tuple[bool, str]:
    """``--resume`` after planting: held when the payload never ran and the run either
    refused cleanly or wrote the tables an uninterrupted run writes."""
    result = c.quick_run(where, "rep", "--resume")
    if mark.exists():
        return False, f"the planted payload ran ({result.why()})"
    if result.code is None:
        return False, f"hung: {result.why()}"
    if "Traceback" in result.err:
        return False, f"traceback: {result.why()}"
    if result.clean_refusal or result.run_refusal:  # the latter after saying it took over the dead run's lock
        return True, f"refused: {result.err.strip()[:200]}"
    if result.code != 0:
        return False, result.why()
    same = tables_without_timing(where / "rep") == tables_without_timing(c.base_report())
    said = [x for x in result.err.splitlines() if "ignored" in x or "not a checkpoint" in x]
    return same, ("tables as uninterrupted" if same else "tables differ from an uninterrupted run") + (
        f"; said: {said[0][:160]}" if said else ""
    )


def attack_sweep_checkpoints_replaced_by_a_payload(c: Campaign, where: Path) -> tuple[bool, str]:
    """Every finished sweep's checkpoint replaced by a pickle that runs a command."""
    journal, mark = interrupted(c, where), where / "PAYLOAD-RAN"
    for p in journal.iterdir():
        if p.name.startswith("sweep-"):
            p.write_bytes(payload(mark))
    return resumed(c, where, mark)


def attack_analyses_checkpoint_planted(c: Campaign, where: Path) -> tuple[bool, str]:
    """A planted analyses checkpoint, under every name one may have."""
    journal, mark = interrupted(c, where), where / "PAYLOAD-RAN"
    for name in ("analyses.pkl", "analyses.json", "analyses.npz"):
        (journal / name).write_bytes(payload(mark))
    return resumed(c, where, mark)


def attack_whole_journal_planted(c: Campaign, where: Path) -> tuple[bool, str]:
    """A journal planted whole: the run's own fingerprint kept, every checkpoint a payload,
    and payloads under plausible names of every format."""
    journal, mark = interrupted(c, where), where / "PAYLOAD-RAN"
    for p in list(journal.iterdir()):
        if p.name not in ("fingerprint.json", "journal.json"):
            p.unlink()
    for name in (
        "sweep-0123456789abcdef.pkl",
        "sweep-" + "0" * 32 + ".json",
        "analyses.pkl",
        "journal.pkl",
        "evil.pkl",
        "checkpoint.npy",
    ):
        (journal / name).write_bytes(payload(mark))
    import numpy as np

    with open(journal / "traces.npz", "wb") as fh:
        np.savez(fh, t=np.array([Plant(mark)], dtype=object))
    return resumed(c, where, mark)


def attack_a_checkpoint_damaged_by_one_byte(c: Campaign, where: Path) -> tuple[bool, str]:
    """One byte of every sweep checkpoint flipped (a cache restored badly): the resumed
    tables must still equal an uninterrupted run's."""
    journal, mark = interrupted(c, where), where / "PAYLOAD-RAN"
    for p in journal.iterdir():
        if p.name.startswith("sweep-"):
            data = bytearray(p.read_bytes())
            at = len(data) * 2 // 3
            data[at] = ord("7") if data[at] != ord("7") else ord("3")
            p.write_bytes(bytes(data))
    return resumed(c, where, mark)


def attack_special_files_named_as_checkpoints(c: Campaign, where: Path) -> tuple[bool, str]:
    """Checkpoint names that lead to /dev/zero, /dev/urandom and a FIFO."""
    journal, mark = interrupted(c, where), where / "PAYLOAD-RAN"
    names = sorted(p.name for p in journal.iterdir() if p.name.startswith("sweep-"))
    for name, target in zip(names, ("/dev/zero", "/dev/urandom"), strict=False):
        (journal / name).unlink()
        (journal / name).symlink_to(target)
    if len(names) > 2:
        (journal / names[2]).unlink()
        mkfifo(journal / names[2])
    mkfifo(journal / "analyses.pkl")
    (journal / "analyses.json").symlink_to("/dev/zero")
    return resumed(c, where, mark)


def attack_journal_folder_is_a_link_elsewhere(c: Campaign, where: Path) -> tuple[bool, str]:
    """``.rep.partial`` is a symbolic link to a folder of payloads."""
    journal, mark = interrupted(c, where), where / "PAYLOAD-RAN"
    elsewhere = where / "elsewhere"
    shutil.move(str(journal), elsewhere)
    for p in elsewhere.iterdir():
        if p.name.startswith("sweep-"):
            p.write_bytes(payload(mark))
    journal.symlink_to(elsewhere)
    return resumed(c, where, mark)


def attack_forged_checkpoint_out_of_schema(c: Campaign, where: Path) -> tuple[bool, str]:
    """Checkpoints rewritten with a valid checksum but rows no run writes (another
    sweep's names, an unknown status, a 1 MB message): never taken as rows."""
    import hashlib

    journal, mark = interrupted(c, where), where / "PAYLOAD-RAN"
    for p in journal.iterdir():
        if not (p.name.startswith("sweep-") and p.name.endswith(".json")):
            continue
        head, _, body = p.read_bytes().partition(b"\n")
        try:
            header, data = json.loads(head), json.loads(body)
        except ValueError:
            continue
        for row in data.get("rows", []):
            row.update(status="splendid", case="other", message="x" * 1_000_000)
        new = json.dumps(data, sort_keys=True, separators=(",", ":")).encode()
        header.update(sha256=hashlib.sha256(new).hexdigest(), size=len(new))
        p.write_bytes(json.dumps(header, sort_keys=True).encode() + b"\n" + new)
    return resumed(c, where, mark)


ATTACKS = [
    attack_sweep_checkpoints_replaced_by_a_payload,
    attack_analyses_checkpoint_planted,
    attack_whole_journal_planted,
    attack_a_checkpoint_damaged_by_one_byte,
    attack_special_files_named_as_checkpoints,
    attack_journal_folder_is_a_link_elsewhere,
    attack_forged_checkpoint_out_of_schema,
]
