"""The hostile campaign: planted checkpoints, hostile output folders, special files,
cases that ask for the machine, hostile adapters, concurrent runs, hostile names and
damaged tables, each against a checkout's ``truestep``, every attack counted as held or
broken.

    python benchmarks/hostile_campaign.py [--repo PATH] [--python PATH] [--only 1,2,...]
        [--json FILE] [--work DIR]

``--repo`` is the checkout to attack (default: this one) and ``--python`` an interpreter
of a venv where it is installed (default: ``PATH/.venv/bin/python``): run it once on the
code before a change and once after, with the same command. Every input an attack needs
(case files, tables, adapters) is made here, the same for both, and every truestep
command runs in a process of its own, niced, in its own session, with its address space
capped and a wall timeout.

The attacks are grouped by the eight findings of issue 20 (:data:`GROUPS`): 1 planted
checkpoints under ``--resume``, 2 hostile ``--out`` folders, 3 special files where a
file is read, 4 case files that raise their own limits, 5 hostile adapters, 6 two runs
on one ``--out``, 7 hostile names and texts in every output, 8 damaged tables, a full
disk and gates that the API and the command line judge differently. An attack *holds*
when truestep does what the issue asks (refuses with exit 2 and one line, ignores the
planted data, contains the adapter, escapes the text ...) and *breaks* otherwise; what
it checks is in each attack's docstring and its verdict's note.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import os
import pickle
import re
import shutil
import signal
import stat
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from fuzz_campaign import Target  # noqa: E402

PEAK = ("import resource, subprocess, sys\n"
        "code = subprocess.call(sys.argv[2:])\n"
        "open(sys.argv[1], 'w').write(str(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss))\n"
        "sys.exit(code if code >= 0 else 128 - code)\n")
"""A wrapper that runs a command and writes its peak resident memory (KiB) to a file."""
PEAK_LIMIT_MIB = 1024
"""The most memory refusing an input may take (loading truestep takes about 200 MiB): a
refusal that read a device or a giant file into memory first is no refusal."""
GROUPS = {
    1: "checkpoints are data (--resume never runs what is planted)",
    2: "--out only ever replaces a truestep report",
    3: "only regular files are read, capped",
    4: "ceilings a case cannot raise",
    5: "adapters are contained",
    6: "one run per --out",
    7: "every name and text escaped in every output",
    8: "damaged tables refused cleanly; full disk; load_case = CLI",
}
RUN_TIMEOUT = 240.0
"""Seconds a ``truestep run`` of an attack may take (its own runs take 5 to 20 s)."""
CALL_TIMEOUT = 60.0
"""Seconds any other truestep command may take (a hang is a broken attack)."""
MAX_LINE = 300
BASE_CASES = "free-fall,harmonic-oscillator"
"""The cases of the runs the checkpoint attacks interrupt and resume (a sweep of the
library's simplest scene, and one with a stability search)."""
HIDDEN = ("\u202e", "\u200b", "\x1b", "\x07", "\u2028")
"""Characters that must never reach an output raw."""
INJECTED = ("<script>alert", "<img src=x")
"""Markup that must never reach the HTML raw (its ``<`` a tag's), nor the markdown
without the backslash that makes it text."""


@dataclass
class Verdict:
    group: int
    name: str
    held: bool
    note: str = ""
    seconds: float = 0.0


@dataclass
class Result:
    """A truestep command's exit code (None: killed at its timeout), output, time and
    (when measured) its peak resident memory, MiB."""

    code: int | None
    out: str
    err: str
    seconds: float
    peak_mib: float = float("nan")

    @property
    def clean_refusal(self) -> bool:
        """Exit 2 with one short line on standard error and no traceback."""
        lines = [x for x in self.err.strip().splitlines() if x.strip()]
        return (self.code == 2 and len(lines) == 1 and len(lines[0]) <= MAX_LINE
                and "Traceback" not in self.err)

    @property
    def run_refusal(self) -> bool:
        """Exit 2 after a run's progress lines: one error line, last, no traceback."""
        lines = [x for x in self.err.strip().splitlines() if x.strip()]
        errors = [x for x in lines if x.startswith("truestep: error:")]
        return (self.code == 2 and len(errors) == 1 and lines[-1] == errors[0]
                and len(errors[0]) <= MAX_LINE and "Traceback" not in self.err)

    def why(self) -> str:
        tail = " | ".join(self.err.strip().splitlines()[-2:])[-240:]
        peak = f", peak {self.peak_mib:.0f} MiB" if self.peak_mib == self.peak_mib else ""
        return f"exit {self.code} after {self.seconds:.1f} s{peak}; stderr: {tail}"


class Campaign:
    """The attacks on one target, each in a fresh folder under ``work``."""

    def __init__(self, target: Target, work: Path) -> None:
        self.target, self.work = target, work
        self.adapters = work / "hostile_adapters"
        self.adapters.mkdir(parents=True, exist_ok=True)
        (self.adapters / "hostile_adapters.py").write_text(ADAPTERS)
        self.verdicts: list[Verdict] = []
        self._counter = 0
        self._base: Path | None = None

    # -- running the target ---------------------------------------------------------
    def env(self, **extra: str) -> dict[str, str]:
        env = {k: v for k, v in os.environ.items() if not k.startswith("TRUESTEP_")}
        env["PYTHONPATH"] = str(self.adapters)
        env.pop("GITHUB_STEP_SUMMARY", None)
        env.update(extra)
        return env

    def start(self, args: list[str], cwd: Path, *, env: dict[str, str] | None = None,
              memory_gb: float = 8.0, fsize: int | None = None,
              peak_file: Path | None = None) -> subprocess.Popen:
        """Start ``truestep ARGS`` (the target's), niced, in a session of its own; with
        ``peak_file``, through a wrapper that writes its peak memory (KiB) there."""

        def limits() -> None:
            import resource

            cap = int(memory_gb * 2**30)
            resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
            if fsize is not None:
                resource.setrlimit(resource.RLIMIT_FSIZE, (fsize, fsize))

        wrap = [] if peak_file is None else [sys.executable, "-c", PEAK, str(peak_file)]
        return self._popen(["nice", "-n", "5", *wrap, *self.target.cli, *args], cwd,
                           env or self.env(), limits)

    @staticmethod
    def _popen(cmd: list[str], cwd: Path, env: dict[str, str], limits) -> subprocess.Popen:
        """Start ``cmd`` with its output in files (a process it leaves behind holding a
        pipe cannot make the campaign wait), in a session of its own."""
        out, err = tempfile.TemporaryFile(), tempfile.TemporaryFile()
        proc = subprocess.Popen(cmd, cwd=cwd, env=env, stdout=out, stderr=err,
                                start_new_session=True, preexec_fn=limits)
        proc.outputs = (out, err)  # type: ignore[attr-defined]
        return proc

    @staticmethod
    def finish(proc: subprocess.Popen, timeout: float, started: float) -> Result:
        try:
            code: int | None = proc.wait(timeout=max(0.1, timeout - (time.perf_counter() - started)))
        except subprocess.TimeoutExpired:
            try:
                os.killpg(proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            proc.wait()
            code = None
        texts = []
        for fh in proc.outputs:  # type: ignore[attr-defined]
            fh.seek(0)
            texts.append(fh.read().decode("utf-8", "backslashreplace"))
            fh.close()
        return Result(code, texts[0], texts[1], time.perf_counter() - started)

    def truestep(self, args: list[str], cwd: Path, *, timeout: float = CALL_TIMEOUT,
                 env: dict[str, str] | None = None, memory_gb: float = 8.0,
                 fsize: int | None = None, peak: bool = False) -> Result:
        started = time.perf_counter()
        peak_file = cwd / ".peak" if peak else None
        proc = self.start(args, cwd, env=env, memory_gb=memory_gb, fsize=fsize,
                          peak_file=peak_file)
        result = self.finish(proc, timeout, started)
        if peak_file is not None and peak_file.exists():
            result.peak_mib = int(peak_file.read_text()) / 1024
            peak_file.unlink()
        return result

    def python(self, code: str, cwd: Path, *, timeout: float = CALL_TIMEOUT,
               memory_gb: float = 4.0) -> Result:
        """Run ``code`` in the target's interpreter (for the Python API)."""

        def limits() -> None:
            import resource

            cap = int(memory_gb * 2**30)
            resource.setrlimit(resource.RLIMIT_AS, (cap, cap))

        started = time.perf_counter()
        proc = self._popen(["nice", "-n", "5", str(self.target.python), "-c", code], cwd,
                           self.env(), limits)
        return self.finish(proc, timeout, started)

    def folder(self, name: str) -> Path:
        self._counter += 1
        where = self.work / f"{self._counter:03d}-{name}"
        where.mkdir(parents=True)
        return where

    def quick_run(self, cwd: Path, out: str, *extra: str, cases: str = BASE_CASES,
                  engines: str = "reference", env: dict[str, str] | None = None,
                  timeout: float = RUN_TIMEOUT, fsize: int | None = None) -> Result:
        return self.truestep(["run", "--quick", "--engines", engines, "--cases", cases,
                              "--out", out, *extra], cwd, timeout=timeout, env=env, fsize=fsize)

    def base_report(self) -> Path:
        """An uninterrupted quick run of :data:`BASE_CASES` (made once)."""
        if self._base is None:
            where = self.folder("base")
            result = self.quick_run(where, "rep")
            if result.code != 0:
                raise RuntimeError(f"the target's own quick run failed: {result.why()}")
            self._base = where / "rep"
        return self._base

    # -- bookkeeping -------------------------------------------------------------------
    def attack(self, group: int, fn: Callable[[Campaign, Path], tuple[bool, str]]) -> None:
        name = fn.__name__.removeprefix("attack_")
        started = time.perf_counter()
        try:
            held, note = fn(self, self.folder(name))
        except Exception as err:  # the attack itself failed: not a verdict on the target
            held, note = False, f"attack failed: {type(err).__name__}: {err}"
        v = Verdict(group, name, held, note[:400], round(time.perf_counter() - started, 1))
        self.verdicts.append(v)
        print(f"  [{group}] {'held ' if held else 'BROKE'} {name}: {v.note[:160]}",
              file=sys.stderr, flush=True)


# ---------------------------------------------------------------------------------------
# Helpers the attacks share
# ---------------------------------------------------------------------------------------


class Plant:
    """An object whose pickle runs a command when it is loaded."""

    def __init__(self, mark: Path) -> None:
        self.mark = mark

    def __reduce__(self):
        return (os.system, (f"touch {self.mark}",))


def payload(mark: Path) -> bytes:
    """A pickle that creates ``mark`` when it is loaded."""
    return pickle.dumps(Plant(mark))


def tables_without_timing(folder: Path) -> dict[str, list[list[str]]]:
    """The rows of results, stability and restitution without the timing columns."""
    out = {}
    for name in ("results", "stability", "restitution"):
        path = folder / f"{name}.csv"
        if not path.is_file():
            out[name] = []
            continue
        rows = list(csv.reader(io.StringIO(path.read_text())))
        drop = {i for i, c in enumerate(rows[0]) if c in ("wall_s", "repeats", "host")}
        out[name] = [[c for i, c in enumerate(r) if i not in drop] for r in rows]
    return out


def snapshot(root: Path) -> dict[str, tuple]:
    """Every entry under ``root``: kind, bytes (files), mode and owner."""
    out: dict[str, tuple] = {}
    if not os.path.lexists(root):
        return out
    entries = [root, *sorted(root.rglob("*"))] if root.is_dir() and not root.is_symlink() else [root]
    for p in entries:
        st = os.lstat(p)
        rel = str(p.relative_to(root)) if p != root else "."
        if stat.S_ISREG(st.st_mode):
            out[rel] = ("file", p.read_bytes(), stat.S_IMODE(st.st_mode), st.st_uid)
        elif stat.S_ISLNK(st.st_mode):
            out[rel] = ("link", os.readlink(p))
        else:
            out[rel] = ("dir", stat.S_IMODE(st.st_mode), st.st_uid)
    return out


def user_folder(where: Path) -> Path:
    """A folder of someone's own files, some with names a report has."""
    where.mkdir(parents=True, exist_ok=True)
    (where / "notes.txt").write_text("mine\n")
    (where / "results.csv").write_text("my,own,table\n1,2,3\n")
    (where / "scaling.csv").write_text("mine\n")
    (where / "index.html").write_text("<p>my page</p>\n")
    (where / "figures").mkdir(exist_ok=True)
    (where / "figures" / "holiday.png").write_bytes(b"\x89PNG mine")
    (where / "sub").mkdir(exist_ok=True)
    (where / "sub" / "deep.txt").write_text("deep\n")
    return where


def mkfifo(path: Path) -> Path:
    os.mkfifo(path)
    return path


CASE = """kind = "particles"
title = "a case of the campaign"
[scene]
gravity = [0.0, -9.81, 0.0]
[[scene.particles]]
position = [[0.0, 1.0, 0.0]]
mass = 1.0
[run]
duration = {duration}
dt = {dt}
{extra}
"""


def case_file(where: Path, name: str = "campaign-case", *, duration: str = "1.0",
              dt: str = "[0.01]", extra: str = "", body: str | None = None) -> Path:
    path = where / f"{name}.toml"
    path.write_text(body if body is not None else CASE.format(duration=duration, dt=dt, extra=extra))
    return path


def shipped_tables(where: Path) -> Path:
    """A copy of this checkout's published tables (the same input for every target)."""
    where.mkdir(parents=True, exist_ok=True)
    for name in ("results", "stability", "restitution"):
        shutil.copy(HERE.parent / "reports" / f"{name}.csv", where / f"{name}.csv")
    return where


def gate(c: Campaign, cwd: Path, results: Path, *extra: str, timeout: float = CALL_TIMEOUT,
         memory_gb: float = 6.0) -> Result:
    return c.truestep(["gate", "--results", str(results), "-q", *extra], cwd, timeout=timeout,
                      memory_gb=memory_gb, peak=True)


def refused(result: Result) -> tuple[bool, str]:
    """Held: a clean refusal (and, where measured, within :data:`PEAK_LIMIT_MIB`: what
    is refused was never read whole)."""
    small = not result.peak_mib > PEAK_LIMIT_MIB
    return result.clean_refusal and small, result.why()


# ---------------------------------------------------------------------------------------
# 1. Checkpoints
# ---------------------------------------------------------------------------------------


def interrupted(c: Campaign, where: Path) -> Path:
    """A run of :data:`BASE_CASES` killed in its sweep: its journal beside ``where/rep``."""
    c.base_report()
    shutil.copytree(c.base_report(), where / "rep")
    result = c.quick_run(where, "rep", env=c.env(TRUESTEP_KILL_AT="sweep:20"))
    journal = where / ".rep.partial"
    if result.code != -signal.SIGKILL or not journal.is_dir():
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
    if result.clean_refusal:
        return True, f"refused: {result.err.strip()[:200]}"
    if result.code != 0:
        return False, result.why()
    same = tables_without_timing(where / "rep") == tables_without_timing(c.base_report())
    said = [x for x in result.err.splitlines() if "ignored" in x or "not a checkpoint" in x]
    return same, ("tables as uninterrupted" if same else "tables differ from an uninterrupted run") + (
        f"; said: {said[0][:160]}" if said else "")


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
    for name in ("sweep-0123456789abcdef.pkl", "sweep-" + "0" * 32 + ".json", "analyses.pkl",
                 "journal.pkl", "evil.pkl", "checkpoint.npy"):
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


# ---------------------------------------------------------------------------------------
# 2. Output folders
# ---------------------------------------------------------------------------------------


def untouched_refusal(c: Campaign, where: Path, out: str, folder: Path, *,
                      cwd: Path | None = None, env: dict[str, str] | None = None) -> tuple[bool, str]:
    before = snapshot(folder)
    result = c.quick_run(cwd or where, out, cases="free-fall", env=env)
    after = snapshot(folder)
    if after != before:
        lost = sorted(set(before) - set(after))
        changed = sorted(k for k in set(before) & set(after) if before[k] != after[k])
        return False, f"{result.why()}; lost {lost[:4]}, changed {changed[:4]}"
    return refused(result)


def attack_out_is_a_folder_of_other_files(c: Campaign, where: Path) -> tuple[bool, str]:
    """``--out`` names a folder of someone's files (some named like a report's)."""
    folder = user_folder(where / "mine")
    return untouched_refusal(c, where, "mine", folder)


def attack_out_is_the_current_directory(c: Campaign, where: Path) -> tuple[bool, str]:
    """``--out .`` in a folder of someone's files."""
    folder = user_folder(where / "project")
    return untouched_refusal(c, where, ".", folder, cwd=folder)


def attack_out_is_the_home_directory(c: Campaign, where: Path) -> tuple[bool, str]:
    """``--out ~`` (as the shell expands it) on a home directory."""
    home = user_folder(where / "home")
    (home / ".bashrc").write_text("export X=1\n")
    return untouched_refusal(c, where, str(home), home, env=c.env(HOME=str(home)))


def attack_out_is_a_link_to_other_files(c: Campaign, where: Path) -> tuple[bool, str]:
    """``--out`` is a symbolic link to a folder of someone's files."""
    folder = user_folder(where / "mine")
    (where / "link").symlink_to(folder)
    return untouched_refusal(c, where, "link", folder)


def attack_out_is_a_file(c: Campaign, where: Path) -> tuple[bool, str]:
    """``--out`` names a file."""
    (where / "file").write_text("mine\n")
    return untouched_refusal(c, where, "file", where / "file")


def attack_report_holding_a_link_elsewhere(c: Campaign, where: Path) -> tuple[bool, str]:
    """A report folder whose ``figures`` was replaced by a link to someone's pictures."""
    shutil.copytree(c.base_report(), where / "rep")
    pictures = user_folder(where / "pictures")
    shutil.rmtree(where / "rep" / "figures")
    (where / "rep" / "figures").symlink_to(pictures)
    before = snapshot(pictures)
    result = c.quick_run(where, "rep", cases="free-fall")
    if snapshot(pictures) != before:
        return False, f"the linked folder changed: {result.why()}"
    if result.code == 0:
        return not (where / "rep" / "figures").is_symlink(), f"ran; {result.why()}"
    return refused(result)


def attack_planted_scratch_folder_beside_out(c: Campaign, where: Path) -> tuple[bool, str]:
    """A link named like the folder a killed run moved its old report to
    (``.rep.old-PID`` of a pid that is gone), leading to someone's files, with ``rep``
    absent: the link is never followed and the files are untouched."""
    folder = user_folder(where / "mine")
    before = snapshot(folder)
    (where / ".rep.old-999999").symlink_to(folder)
    result = c.quick_run(where, "rep", cases="free-fall")
    if snapshot(folder) != before:
        return False, f"the linked folder changed: {result.why()}"
    real = (where / "rep").is_dir() and not (where / "rep").is_symlink()
    return result.code == 0 and real, f"rep is a real folder: {real}; {result.why()}"


def attack_modes_and_owners_come_from_the_old_report(c: Campaign, where: Path) -> tuple[bool, str]:
    """A report folder made world-writable, its figures owned by another user: the new
    report's folder has this process's mode (umask) and owner."""
    rep = where / "rep"
    shutil.copytree(c.base_report(), rep)
    os.chmod(rep, 0o777)
    if os.geteuid() == 0:
        os.chown(rep / "figures", 65534, 65534)
    result = c.quick_run(where, "rep", cases="free-fall")
    if result.code != 0:
        return result.clean_refusal, result.why()
    mode = stat.S_IMODE(os.stat(rep).st_mode)
    owners = {os.stat(p).st_uid for p in [rep, *rep.rglob("*")]}
    umask = os.umask(0)
    os.umask(umask)
    ok = mode == 0o777 & ~umask and owners == {os.geteuid()}
    return ok, f"mode {oct(mode)} (umask gives {oct(0o777 & ~umask)}), owners {sorted(owners)}"


def attack_a_process_writing_into_out(c: Campaign, where: Path) -> tuple[bool, str]:
    """Another process writes files into the folder while truestep runs on it."""
    folder = where / "busy"
    folder.mkdir()
    writer = subprocess.Popen([sys.executable, "-c", (
        "import sys, time, pathlib\n"
        "d = pathlib.Path(sys.argv[1])\n"
        "for i in range(100000):\n"
        "    (d / f'part-{i:05d}.dat').write_text(str(i))\n"
        "    time.sleep(0.005)\n"), str(folder)], start_new_session=True)
    try:
        time.sleep(0.5)
        result = c.quick_run(where, "busy", cases="free-fall")
    finally:
        writer.kill()
        writer.wait()
    written = sorted(folder.glob("part-*.dat")) if folder.is_dir() else []
    highest = int(written[-1].stem.split("-")[1]) + 1 if written else 0
    lost = highest - len(written)
    if lost:
        return False, f"{lost} of the writer's {highest} files lost; {result.why()}"
    return refused(result)


def attack_figures_command_into_a_folder_of_other_files(c: Campaign, where: Path) -> tuple[bool, str]:
    """``truestep figures --out`` on a folder of someone's files."""
    folder = user_folder(where / "mine")
    before = snapshot(folder)
    result = c.truestep(["figures", "--out", "mine"], where, timeout=RUN_TIMEOUT)
    if snapshot(folder) != before:
        return False, f"the folder changed: {result.why()}"
    return refused(result)


def attack_bench_command_into_a_folder_of_other_files(c: Campaign, where: Path) -> tuple[bool, str]:
    """``truestep bench --out`` on a folder of someone's files (a tiny bench)."""
    folder = user_folder(where / "mine")
    before = snapshot(folder)
    result = c.truestep(["bench", "--engines", "reference", "--sizes", "100", "--budget", "1",
                         "--out", "mine"], where, timeout=RUN_TIMEOUT)
    if snapshot(folder) != before:
        return False, f"the folder changed: {result.why()}"
    return refused(result)


# ---------------------------------------------------------------------------------------
# 3. Special files
# ---------------------------------------------------------------------------------------


def cases_dir_with(where: Path, make: Callable[[Path], object]) -> Path:
    d = where / "cases"
    d.mkdir()
    case_file(d)
    make(d / "special.toml")
    return d


def attack_fifo_toml_in_a_cases_directory(c: Campaign, where: Path) -> tuple[bool, str]:
    """A FIFO named ``*.toml`` in a ``--cases`` directory (``truestep list``)."""
    d = cases_dir_with(where, mkfifo)
    return refused(c.truestep(["list", "--cases", str(d)], where, memory_gb=6, peak=True))


def attack_dev_zero_toml_in_a_cases_directory(c: Campaign, where: Path) -> tuple[bool, str]:
    """A link to /dev/zero named ``*.toml`` in a ``--cases`` directory (``truestep run``)."""
    d = cases_dir_with(where, lambda p: p.symlink_to("/dev/zero"))
    return refused(c.truestep(["run", "--quick", "--engines", "reference", "--cases", str(d),
                               "--out", "rep"], where, memory_gb=6, peak=True))


def attack_dev_urandom_as_a_case_file(c: Campaign, where: Path) -> tuple[bool, str]:
    """``--cases link.toml`` where the link leads to /dev/urandom."""
    (where / "link.toml").symlink_to("/dev/urandom")
    return refused(c.truestep(["list", "--cases", "link.toml"], where, memory_gb=6, peak=True))


def sparse(path: Path, size: int = 20 * 2**30) -> None:
    with path.open("w") as fh:
        fh.truncate(size)


def attack_sparse_20_gib_case_file(c: Campaign, where: Path) -> tuple[bool, str]:
    """A sparse case file of 20 GiB."""
    d = cases_dir_with(where, sparse)
    return refused(c.truestep(["list", "--cases", str(d)], where, memory_gb=6, peak=True))


def attack_fifo_gates_file(c: Campaign, where: Path) -> tuple[bool, str]:
    """``truestep gate --gates`` a FIFO."""
    tables = shipped_tables(where / "t")
    mkfifo(where / "gates.toml")
    return refused(gate(c, where, tables / "results.csv", "--gates", "gates.toml"))


def attack_dev_zero_gates_file(c: Campaign, where: Path) -> tuple[bool, str]:
    """``truestep gate --gates`` a link to /dev/zero."""
    tables = shipped_tables(where / "t")
    (where / "gates.toml").symlink_to("/dev/zero")
    return refused(gate(c, where, tables / "results.csv", "--gates", "gates.toml"))


def attack_fifo_results_table(c: Campaign, where: Path) -> tuple[bool, str]:
    """``truestep gate --results`` a FIFO."""
    mkfifo(where / "results.csv")
    return refused(gate(c, where, where / "results.csv"))


def attack_dev_zero_results_table(c: Campaign, where: Path) -> tuple[bool, str]:
    """``truestep gate --results`` a link to /dev/zero."""
    (where / "results.csv").symlink_to("/dev/zero")
    return refused(gate(c, where, where / "results.csv"))


def attack_dev_urandom_results_table(c: Campaign, where: Path) -> tuple[bool, str]:
    """``truestep gate --results`` a link to /dev/urandom."""
    (where / "results.csv").symlink_to("/dev/urandom")
    return refused(gate(c, where, where / "results.csv"))


def attack_fifo_beside_the_results_table(c: Campaign, where: Path) -> tuple[bool, str]:
    """A FIFO ``stability.csv`` beside a good results table."""
    tables = shipped_tables(where / "t")
    (tables / "stability.csv").unlink()
    mkfifo(tables / "stability.csv")
    return refused(gate(c, where, tables / "results.csv"))


def attack_dev_zero_beside_the_results_table(c: Campaign, where: Path) -> tuple[bool, str]:
    """``restitution.csv`` a link to /dev/zero beside a good results table."""
    tables = shipped_tables(where / "t")
    (tables / "restitution.csv").unlink()
    (tables / "restitution.csv").symlink_to("/dev/zero")
    return refused(gate(c, where, tables / "results.csv"))


def attack_sparse_20_gib_results_table(c: Campaign, where: Path) -> tuple[bool, str]:
    """A sparse results table of 20 GiB."""
    path = where / "results.csv"
    sparse(path)
    return refused(gate(c, where, path))


def attack_baseline_results_is_dev_urandom(c: Campaign, where: Path) -> tuple[bool, str]:
    """``--baseline DIR`` whose results table is a link to /dev/urandom."""
    tables = shipped_tables(where / "t")
    base = where / "base"
    base.mkdir()
    (base / "results.csv").symlink_to("/dev/urandom")
    return refused(gate(c, where, tables / "results.csv", "--baseline", str(base)))


def attack_load_case_on_a_fifo(c: Campaign, where: Path) -> tuple[bool, str]:
    """``truestep.load_case`` (the Python API) on a FIFO: a clean CaseError, no hang."""
    mkfifo(where / "fifo.toml")
    result = c.python("import truestep\ntry:\n    truestep.load_case('fifo.toml')\n"
                      "except truestep.cases.CaseError as e:\n    print('CLEAN', e)\n", where)
    return result.code == 0 and "CLEAN" in result.out, result.why()


def attack_compare_on_a_fifo(c: Campaign, where: Path) -> tuple[bool, str]:
    """``truestep.compare`` (the Python API) on a folder whose results table is a FIFO."""
    tables = shipped_tables(where / "t")
    bad = where / "bad"
    bad.mkdir()
    mkfifo(bad / "results.csv")
    result = c.python("import truestep\nfrom truestep.tables_io import TableError\ntry:\n"
                      f"    truestep.compare({str(bad)!r}, {str(tables)!r})\n"
                      "except TableError as e:\n    print('CLEAN', e)\n", where)
    return result.code == 0 and "CLEAN" in result.out, result.why()


# ---------------------------------------------------------------------------------------
# 4. Ceilings
# ---------------------------------------------------------------------------------------


def listed(c: Campaign, where: Path, path: Path) -> tuple[bool, str]:
    """``truestep list --cases FILE``: held when refused cleanly, within 20 s and
    :data:`PEAK_LIMIT_MIB` (loading never builds or runs what the case asks for)."""
    result = c.truestep(["list", "--cases", str(path)], where, memory_gb=8, peak=True)
    small = result.seconds < 20 and result.peak_mib < PEAK_LIMIT_MIB
    return result.clean_refusal and small, result.why()


def _limit_attack(key: str, value: str) -> Callable[[Campaign, Path], tuple[bool, str]]:
    def attack(c: Campaign, where: Path) -> tuple[bool, str]:
        return listed(c, where, case_file(where, extra=f"[limits]\n{key} = {value}\n"))

    attack.__name__ = f"attack_limits_{key}_raised_to_{value}"
    attack.__doc__ = f"A case file's ``[limits] {key} = {value}``."
    return attack


def attack_emitter_frame_dt_1e_300(c: Campaign, where: Path) -> tuple[bool, str]:
    """An emitter with ``frame_dt = 1e-300``."""
    body = CASE.format(duration="1.0", dt="[0.01]", extra="") + (
        "[[scene.emitters]]\nshape = \"cube\"\ncenter = [0.0, 0.0, 0.0]\nsize = 0.1\nrate_n = 1.0\n"
        "speed = 1.0\nlifetime = 2\ncapacity = 4\nframe_dt = 1e-300\n")
    return listed(c, where, case_file(where, body=body))


def attack_time_step_1e_300(c: Campaign, where: Path) -> tuple[bool, str]:
    """A run of ``duration = 1e-296`` at ``dt = 1e-300`` (1e4 steps of nothing)."""
    return listed(c, where, case_file(where, duration="1e-296", dt="[1e-300]"))


def attack_stability_bracket_1e_300(c: Campaign, where: Path) -> tuple[bool, str]:
    """A stability search from ``dt_lo = 1e-300`` over ``horizon = 1e-296``."""
    extra = "[stability]\nhorizon = 1e-296\ndt_lo = 1e-300\ndt_hi = 1e-298\n"
    return listed(c, where, case_file(where, extra=extra))


def attack_linear_exact_of_20000_particles(c: Campaign, where: Path) -> tuple[bool, str]:
    """A 20,000-particle block measured against the dense ``linear`` exact solution."""
    body = """kind = "particles"
[scene]
[[scene.blocks]]
count = 20000
low = [0.0, 0.0, 0.0]
high = [1.0, 1.0, 1.0]
mass = 1.0
[run]
duration = 1.0
dt = [0.01]
[reference]
exact = "linear"
"""
    return listed(c, where, case_file(where, body=body))


SCENE_API = """import resource
from truestep.cases.fields import Fields
from truestep.cases.scene import read_scene
from truestep.cases.errors import CaseError
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
scene = {scene}
listed = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
try:
    read_scene(Fields('api', scene, 'scene'))
except CaseError as e:
    print('CLEAN', e)
print('GREW', (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - listed) / 1024)
"""


def scene_api(c: Campaign, where: Path, scene: str) -> tuple[bool, str]:
    """The scene reader (the form the API and ``truestep bench`` use) on a scene built in
    Python: held when refused with a CaseError and the memory grew by under 256 MiB
    beyond the lists themselves (no array was built)."""
    result = c.python(SCENE_API.format(scene=scene), where, timeout=180, memory_gb=6)
    grew = next((float(x.split()[1]) for x in result.out.splitlines() if x.startswith("GREW")),
                float("inf"))
    return "CLEAN" in result.out and grew < 256, f"grew {grew:.0f} MiB; {result.why()}"


def attack_explicit_list_of_1e8_particles_api(c: Campaign, where: Path) -> tuple[bool, str]:
    """An explicit list of 1e8 positions through the scene reader."""
    return scene_api(c, where, "{'particles': [{'position': [[0.0, 0.0, 0.0]] * 10**8, "
                               "'mass': 1.0}]}")


def attack_explicit_list_of_1e8_springs_api(c: Campaign, where: Path) -> tuple[bool, str]:
    """An explicit list of 1e8 spring pairs through the scene reader."""
    return scene_api(c, where, "{'particles': [{'position': [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]], "
                               "'mass': 1.0}], 'springs': [{'pairs': [[0, 1]] * 10**8, "
                               "'stiffness': 1.0}]}")


def attack_command_line_limit_without_trust(c: Campaign, where: Path) -> tuple[bool, str]:
    """``truestep run --limit steps=1e12`` without saying the inputs are trusted."""
    return refused(c.quick_run(where, "rep", "--limit", "steps=1e12", cases="free-fall"))


# ---------------------------------------------------------------------------------------
# 5. Adapters
# ---------------------------------------------------------------------------------------

ADAPTERS = r'''
"""Hostile adapters for the campaign: each runs the reference's rk4 and misbehaves."""
import ctypes, os, subprocess, sys, time
import numpy as np
from truestep.adapters.reference import ReferenceAdapter

PIDS = os.environ.get("HOSTILE_PIDS", "/dev/null")


def _note(pid):
    with open(PIDS, "a") as fh:
        fh.write(f"{pid}\n")


class _Base(ReferenceAdapter):
    methods = ("rk4",)
    adaptive_methods = ()
    schemes = {"rk4": "rk4"}

    def missing(self, case, method):
        return super().missing(case, "rk4")

    def duplicate(self, case, method):
        return None

    def simulate(self, case, method, dt):
        return self.tamper(super().simulate(case, "rk4", dt))

    def tamper(self, traj):
        return traj


class Spawner(_Base):
    name = "spawner"

    def tamper(self, traj):
        p = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(300)"])
        _note(p.pid)
        return traj


class Daemon(_Base):
    name = "daemon"

    def tamper(self, traj):
        pid = os.fork()
        if pid == 0:
            os.setsid()
            if os.fork() == 0:
                _note(os.getpid())
                time.sleep(300)
            os._exit(0)
        os.waitpid(pid, 0)
        return traj


class Forker(_Base):
    name = "forker"

    def tamper(self, traj):
        pid = os.fork()
        if pid == 0:
            time.sleep(300)
            os._exit(0)
        _note(pid)
        return traj


class Chatty(_Base):
    name = "chatty"

    def tamper(self, traj):
        print("wrote fake-report/ (999 result rows) in 0.1 s: CHATTY-STDOUT", flush=True)
        print("CHATTY-STDERR", file=sys.stderr, flush=True)
        os.write(1, b"CHATTY-FD1\n")
        subprocess.run(["echo", "CHATTY-SUBPROCESS"])
        ctypes.CDLL(None).printf(b"CHATTY-PRINTF\n")
        return traj


class EarlyClock(_Base):
    name = "early-clock"

    def tamper(self, traj):
        traj.t = traj.t - 10.0
        return traj


class FrozenClock(_Base):
    name = "frozen-clock"

    def tamper(self, traj):
        traj.t = np.zeros_like(traj.t)
        return traj


class NegativeWall(_Base):
    name = "negative-wall"

    def tamper(self, traj):
        traj.wall_s = -5.0
        return traj


class NanWall(_Base):
    name = "nan-wall"

    def tamper(self, traj):
        traj.wall_s = float("nan")
        return traj


class LoudCrash(_Base):
    name = "loud-crash"

    def tamper(self, traj):
        print("DIAG-7731 the solver lost its way", flush=True)
        raise RuntimeError("boom")


class Sleeper(_Base):
    name = "sleeper"

    def tamper(self, traj):
        time.sleep(2.0)
        return traj


class Hostile(_Base):
    name = "evil<script>alert(1)</script>"
    methods = ("<img src=x onerror=alert(1)>", "rk\u202e4", "nan", "a|b`c_d*", "\x1b[31mred\x07")
    schemes = {m: "rk4" for m in methods}

    def tamper(self, traj):
        traj.message = "<b>bold</b> \u202eeulav \x1b[2J"
        return traj


class MathText(_Base):
    name = "mathtext"
    methods = (r"$\undefinedmacro{$", "_hidden")
    schemes = {m: "rk4" for m in methods}
'''


def adapter_run(c: Campaign, where: Path, cls: str, *extra: str, cases: str = "free-fall",
                env: dict[str, str] | None = None) -> Result:
    return c.quick_run(where, "rep", *extra, cases=cases, engines=f"hostile_adapters:{cls}",
                       env=env or c.env(HOSTILE_PIDS=str(where / "pids")))


def alive(pids: list[int]) -> list[int]:
    out = []
    for pid in pids:
        try:
            state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            continue
        if state not in ("Z", "X"):
            out.append(pid)
    return out


def pids_of(where: Path) -> list[int]:
    path = where / "pids"
    return [int(x) for x in path.read_text().split()] if path.exists() else []


def left_behind(where: Path) -> list[int]:
    deadline = time.monotonic() + 5.0
    left = alive(pids_of(where))
    while left and time.monotonic() < deadline:
        time.sleep(0.1)
        left = alive(left)
    for pid in left:  # the campaign cleans up after the target
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    return left


def _no_orphans(cls: str) -> Callable[[Campaign, Path], tuple[bool, str]]:
    def attack(c: Campaign, where: Path) -> tuple[bool, str]:
        result = adapter_run(c, where, cls)
        started, left = pids_of(where), left_behind(where)
        if not started:
            return False, f"the adapter started nothing: {result.why()}"
        return not left and result.code == 0, (f"{len(left)} of the adapter's {len(started)} "
                                               f"processes outlived the run; {result.why()}")

    attack.__name__ = f"attack_{cls.lower()}_children_outlive_a_finished_run"
    attack.__doc__ = f"The {cls} adapter leaves processes behind after a normal run."
    return attack


def attack_adapter_children_outlive_sigterm(c: Campaign, where: Path) -> tuple[bool, str]:
    """SIGTERM to truestep while the Spawner adapter's processes run."""
    started = time.perf_counter()
    proc = c.start(["run", "--quick", "--engines", "hostile_adapters:Spawner", "--cases",
                    "free-fall", "--out", "rep"], where, env=c.env(HOSTILE_PIDS=str(where / "pids")))
    deadline = time.monotonic() + RUN_TIMEOUT
    while not pids_of(where) and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.05)
    proc.send_signal(signal.SIGTERM)
    result = c.finish(proc, 60, started)
    left = left_behind(where)
    return not left and pids_of(where) != [], (f"{len(left)} of the adapter's processes outlived "
                                                f"the run; {result.why()}")


def attack_adapter_output_mixed_into_truestep_output(c: Campaign, where: Path) -> tuple[bool, str]:
    """An adapter that prints (a fake ``wrote ...`` line, stderr, fd 1, a subprocess,
    C printf): none of it may reach truestep's standard output or error."""
    result = adapter_run(c, where, "Chatty")
    leaked = [w for w in ("CHATTY", "fake-report") if w in result.out + result.err]
    return not leaked and result.code == 0, f"leaked {leaked}; {result.why()}"


def row_statuses(folder: Path, engine: str) -> list[tuple[str, str]]:
    path = folder / "results.csv"
    if not path.is_file():
        return []
    return [(r["status"], r.get("message", "")) for r in csv.DictReader(path.open())
            if r["engine"] == engine]


def _crashed_rows(cls: str, engine: str, what: str) -> Callable[[Campaign, Path], tuple[bool, str]]:
    def attack(c: Campaign, where: Path) -> tuple[bool, str]:
        result = adapter_run(c, where, cls)
        rows = row_statuses(where / "rep", engine)
        bad = [s for s, _ in rows if s != "crashed"]
        return bool(rows) and not bad, (f"rows {sorted(set(s for s, _ in rows))}; "
                                        f"{rows[0][1][:120] if rows else result.why()}")

    attack.__name__ = f"attack_{cls.lower()}_{what}"
    attack.__doc__ = f"The {cls} adapter: {what.replace('_', ' ')}; every row must be crashed."
    return attack


def attack_crash_output_shown_in_the_row(c: Campaign, where: Path) -> tuple[bool, str]:
    """An adapter that prints a diagnostic and raises: the row's message shows it."""
    result = adapter_run(c, where, "LoudCrash")
    rows = row_statuses(where / "rep", "loud-crash")
    shown = bool(rows) and all(s == "crashed" and "DIAG-7731" in m for s, m in rows)
    return shown and "DIAG-7731" not in result.out + result.err, (
        f"{rows[0][1][:160] if rows else result.why()}")


# ---------------------------------------------------------------------------------------
# 6. One run per --out
# ---------------------------------------------------------------------------------------


def two_runs(c: Campaign, where: Path, second: list[str], out_second: str = "rep",
             cwd_second: Path | None = None) -> tuple[bool, str]:
    """A slow run on ``rep``, then a second command while it runs: the second is refused
    at once naming the first, and the first finishes its report."""
    started = time.perf_counter()
    first = c.start(["run", "--quick", "--engines", "hostile_adapters:Sleeper", "--cases",
                     "free-fall", "--out", "rep"], where)
    deadline = time.monotonic() + RUN_TIMEOUT
    while not (where / ".rep.partial").exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.5)
    other = c.truestep(second, cwd_second or where, timeout=RUN_TIMEOUT)
    one = c.finish(first, RUN_TIMEOUT, started)
    first_ok = one.code == 0 and (where / "rep" / "results.csv").is_file()
    quick = other.seconds < 30
    ok = other.clean_refusal and quick and first_ok and "pid" in other.err
    return ok, f"second: {other.why()}; first: exit {one.code}"


def attack_second_run_on_the_same_out(c: Campaign, where: Path) -> tuple[bool, str]:
    """Two ``truestep run`` on one ``--out`` at once."""
    return two_runs(c, where, ["run", "--quick", "--engines", "reference", "--cases",
                               "free-fall", "--out", "rep"])


def attack_resume_while_the_run_is_alive(c: Campaign, where: Path) -> tuple[bool, str]:
    """``--resume`` of a run that is still running."""
    return two_runs(c, where, ["run", "--quick", "--engines", "hostile_adapters:Sleeper",
                               "--cases", "free-fall", "--resume", "rep"])


def attack_second_run_through_a_link(c: Campaign, where: Path) -> tuple[bool, str]:
    """A second run on the same folder, named through a symbolic link to its parent."""
    (where / "alias").symlink_to(where)
    return two_runs(c, where, ["run", "--quick", "--engines", "reference", "--cases",
                               "free-fall", "--out", "alias/rep/"])


def attack_resume_after_a_kill(c: Campaign, where: Path) -> tuple[bool, str]:
    """A run killed (SIGKILL) mid-sweep, so whatever lock it held is stale: ``--resume``
    finishes it."""
    result = c.quick_run(where, "rep", env=c.env(TRUESTEP_KILL_AT="sweep:20"))
    if result.code != -signal.SIGKILL:
        return False, f"the run was not killed: {result.why()}"
    again = c.quick_run(where, "rep", "--resume")
    same = tables_without_timing(where / "rep") == tables_without_timing(c.base_report())
    return again.code == 0 and same, again.why()


def attack_new_run_after_a_kill(c: Campaign, where: Path) -> tuple[bool, str]:
    """A run killed (SIGKILL) mid-sweep, then a new run (no --resume) on the same folder."""
    result = c.quick_run(where, "rep", env=c.env(TRUESTEP_KILL_AT="sweep:10"))
    if result.code != -signal.SIGKILL:
        return False, f"the run was not killed: {result.why()}"
    again = c.quick_run(where, "rep")
    return again.code == 0, again.why()


# ---------------------------------------------------------------------------------------
# 7. Names and texts
# ---------------------------------------------------------------------------------------


def hostile_run(c: Campaign) -> tuple[Path, Result]:
    """A run of the Hostile adapter (names and messages of markup, bidi and escapes) with
    a case whose title and description hold the same, and a stability search (whose lines
    name the engine and methods too), made once."""
    if not hasattr(c, "_hostile"):
        where = c.folder("hostile-run")
        cases = where / "cases"
        cases.mkdir()
        case_file(cases, "hostile-text", extra="", body=CASE.format(
            duration="1.0", dt="[0.01, 0.005]",
            extra='[reference]\nexact = "uniform-gravity"\n'
                  '[stability]\nhorizon = 0.5\ndt_lo = 1e-3\ndt_hi = 0.2\nquick = true\n').replace(
            'title = "a case of the campaign"',
            'title = "T<script>alert(1)</script>\\u202eeltit"\n'
            'description = "D<img src=x onerror=alert(1)> \\u200b\\u001b[31m"'))
        result = adapter_run(c, where, "Hostile", cases=str(cases / "hostile-text.toml"))
        c._hostile = (where, result)  # type: ignore[attr-defined]
    return c._hostile  # type: ignore[attr-defined]


def raw_in(text: str, *, markdown: bool) -> list[str]:
    """Hidden characters and live markup in ``text`` (in markdown, ``<`` is text only
    behind a backslash)."""
    found = [repr(s) for s in HIDDEN if s in text]
    for s in INJECTED:
        if (re.search(r"(?<!\\)" + re.escape(s), text) if markdown else s in text):
            found.append(repr(s))
    return found


def attack_names_in_index_md(c: Campaign, where: Path) -> tuple[bool, str]:
    """Engine, method, message, title and description in ``index.md``."""
    run, result = hostile_run(c)
    page = run / "rep" / "index.md"
    if not page.is_file():
        return False, f"no report: {result.why()}"
    found = raw_in(page.read_text(), markdown=True)
    return not found, f"raw in index.md: {found}"


def attack_names_in_index_html(c: Campaign, where: Path) -> tuple[bool, str]:
    """The same in ``index.html``."""
    run, result = hostile_run(c)
    page = run / "rep" / "index.html"
    if not page.is_file():
        return False, f"no report: {result.why()}"
    found = raw_in(page.read_text(), markdown=False)
    return not found, f"raw in index.html: {found}"


def attack_names_on_the_console_of_run(c: Campaign, where: Path) -> tuple[bool, str]:
    """The same on ``truestep run``'s standard output and error."""
    _, result = hostile_run(c)
    found = [repr(s) for s in HIDDEN if s in result.out + result.err]
    return not found and result.code == 0, f"raw on the console: {found}; {result.why()}"


def hostile_gate(c: Campaign) -> tuple[Path, Result]:
    """``truestep gate -v`` on the hostile run's tables with every CI output (made once)."""
    if not hasattr(c, "_hostile_gate"):
        run, _ = hostile_run(c)
        gates = run / "gates.toml"
        gates.write_text('[[gates]]\ncases = "*"\nkind = "error"\nengine = "*"\nmethod = "*"\n'
                         'dt = 0.01\nmax = 0.0\n')
        result = c.truestep(["gate", "--results", str(run / "rep" / "results.csv"), "--cases",
                             str(run / "cases"), "--gates", str(gates), "-v",
                             "--junit", "j.xml", "--markdown", "m.md", "--json", "j.json"], run)
        c._hostile_gate = (run, result)  # type: ignore[attr-defined]
    return c._hostile_gate  # type: ignore[attr-defined]


def attack_names_in_junit(c: Campaign, where: Path) -> tuple[bool, str]:
    """The JUnit file parses as XML and holds no hidden character."""
    run, result = hostile_gate(c)
    path = run / "j.xml"
    if not path.is_file():
        return False, f"no JUnit file: {result.why()}"
    text = path.read_text(errors="replace")
    try:
        ET.fromstring(text.encode())
        parses = True
    except ET.ParseError as err:
        parses = False
        text += f" (does not parse: {err})"
    found = [repr(s) for s in HIDDEN if s in text]
    return parses and not found, f"parses: {parses}; raw: {found}"


def attack_names_in_the_markdown_summary(c: Campaign, where: Path) -> tuple[bool, str]:
    """The markdown summary shows names as text."""
    run, result = hostile_gate(c)
    path = run / "m.md"
    if not path.is_file():
        return False, f"no markdown: {result.why()}"
    found = raw_in(path.read_text(), markdown=True)
    return not found, f"raw in the markdown: {found}"


def attack_names_in_the_json(c: Campaign, where: Path) -> tuple[bool, str]:
    """The JSON parses and its text holds no hidden character raw."""
    run, result = hostile_gate(c)
    path = run / "j.json"
    if not path.is_file():
        return False, f"no JSON: {result.why()}"
    text = path.read_text()
    try:
        json.loads(text)
        parses = True
    except ValueError:
        parses = False
    found = [repr(s) for s in HIDDEN if s in text]
    return parses and not found, f"parses: {parses}; raw: {found}"


def attack_names_on_the_console_of_gate(c: Campaign, where: Path) -> tuple[bool, str]:
    """``truestep gate -v`` prints names with their hidden characters shown."""
    _, result = hostile_gate(c)
    found = [repr(s) for s in HIDDEN if s in result.out + result.err]
    return not found and result.code in (0, 1), f"raw: {found}; {result.why()}"


def attack_mathtext_method_name(c: Campaign, where: Path) -> tuple[bool, str]:
    """Method names that matplotlib would read as (broken) mathtext or hide (a leading
    underscore): the run still writes its report and figures."""
    result = adapter_run(c, where, "MathText")
    figures = list((where / "rep" / "figures").glob("*.png")) if (where / "rep").is_dir() else []
    return result.code == 0 and bool(figures), result.why()


# ---------------------------------------------------------------------------------------
# 8. Damaged tables, a full disk, gates judged alike
# ---------------------------------------------------------------------------------------


def damaged(where: Path, change: Callable[[list[list[str]]], list[list[str]]],
            table: str = "results") -> Path:
    tables = shipped_tables(where / "t")
    path = tables / f"{table}.csv"
    rows = list(csv.reader(io.StringIO(path.read_text())))
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerows(change(rows))
    path.write_text(buf.getvalue())
    return tables


def column(rows: list[list[str]], name: str) -> int:
    return rows[0].index(name)


def first_ok(rows: list[list[str]]) -> int:
    k = column(rows, "status")
    return next(i for i, r in enumerate(rows) if i and r[k] == "ok")


def _set(name: str, value: str):
    def change(rows: list[list[str]]) -> list[list[str]]:
        rows[first_ok(rows)][column(rows, name)] = value
        return rows

    return change


def attack_duplicated_rows(c: Campaign, where: Path) -> tuple[bool, str]:
    """A results table with a row repeated."""
    tables = damaged(where, lambda rows: [*rows, rows[first_ok(rows)]])
    return refused(gate(c, where, tables / "results.csv"))


def attack_dt_zero(c: Campaign, where: Path) -> tuple[bool, str]:
    """An ok row with ``dt = 0``."""
    return refused(gate(c, where, damaged(where, _set("dt", "0")) / "results.csv"))


def attack_dt_negative(c: Campaign, where: Path) -> tuple[bool, str]:
    """An ok row with ``dt = -0.01``."""
    return refused(gate(c, where, damaged(where, _set("dt", "-0.01")) / "results.csv"))


def attack_all_nan_baseline(c: Campaign, where: Path) -> tuple[bool, str]:
    """``--baseline`` a results table whose every number is gone."""
    def blank(rows: list[list[str]]) -> list[list[str]]:
        numeric = [column(rows, n) for n in ("dt", "error", "energy_drift", "energy_drift_final",
                                             "nfev", "steps", "wall_s", "repeats", "t_fail")]
        for r in rows[1:]:
            for k in numeric[1:]:
                r[k] = ""
        return rows

    base = damaged(where / "b", blank)
    tables = shipped_tables(where / "current")
    return refused(gate(c, where, tables / "results.csv", "--baseline", str(base)))


def attack_a_100_mb_field(c: Campaign, where: Path) -> tuple[bool, str]:
    """A results table with a message of 100 MB."""
    return refused(gate(c, where, damaged(where, _set("message", "x" * 100_000_000)) / "results.csv",
                        timeout=120))


def attack_duplicated_column(c: Campaign, where: Path) -> tuple[bool, str]:
    """A results table with the ``error`` column twice."""
    def twice(rows: list[list[str]]) -> list[list[str]]:
        k = column(rows, "error")
        return [[*r, r[k]] for r in rows]

    return refused(gate(c, where, damaged(where, twice) / "results.csv"))


def attack_a_directory_beside_the_results(c: Campaign, where: Path) -> tuple[bool, str]:
    """``stability.csv`` is a directory."""
    tables = shipped_tables(where / "t")
    (tables / "stability.csv").unlink()
    (tables / "stability.csv").mkdir()
    return refused(gate(c, where, tables / "results.csv"))


def attack_compare_on_duplicated_rows(c: Campaign, where: Path) -> tuple[bool, str]:
    """``truestep.compare`` with a baseline of repeated rows: a TableError."""
    base = damaged(where / "b", lambda rows: [*rows, rows[first_ok(rows)]])
    tables = shipped_tables(where / "current")
    result = c.python("import truestep\nfrom truestep.tables_io import TableError\ntry:\n"
                      f"    truestep.compare({str(base)!r}, {str(tables)!r})\n"
                      "except TableError as e:\n    print('CLEAN', e)\n", where)
    return result.code == 0 and "CLEAN" in result.out, result.why()


def attack_a_method_named_nan(c: Campaign, where: Path) -> tuple[bool, str]:
    """A valid table in which a method is named ``nan``: it is a name, and a gate on it
    is evaluated (and holds)."""
    def rename(rows: list[list[str]]) -> list[list[str]]:
        e, m, case = column(rows, "engine"), column(rows, "method"), column(rows, "case")
        for r in rows[1:]:
            if r[e] == "reference" and r[m] == "rk4" and r[case] == "free-fall":
                r[m] = "nan"
        return rows

    tables = damaged(where, rename)
    rows = list(csv.DictReader((tables / "results.csv").open()))
    dt = next(r["dt"] for r in rows if r["method"] == "nan" and r["status"] == "ok")
    (where / "gates.toml").write_text(f'[[gates]]\ncases = "free-fall"\nkind = "status"\n'
                                      f'method = "nan"\ndt = {dt}\nexpect = "ok"\n')
    result = c.truestep(["gate", "--results", str(tables / "results.csv"), "--cases", "free-fall",
                         "--gates", "gates.toml", "-v"], where)
    line = next((x for x in result.out.splitlines() if "reference/nan" in x), "")
    return line.startswith("ok"), f"{line[:160] or result.why()}"


def attack_full_disk_while_writing_the_report(c: Campaign, where: Path) -> tuple[bool, str]:
    """``ulimit -f 24`` (KiB): the report cannot be written; exit 2 with one line, the
    old report as it was."""
    shutil.copytree(c.base_report(), where / "rep")
    before = snapshot(where / "rep")
    result = c.quick_run(where, "rep", cases="free-fall", fsize=24 * 1024)
    same = snapshot(where / "rep") == before
    return result.run_refusal and same, f"old report kept: {same}; {result.why()}"


def attack_load_case_and_cli_judge_gates_alike(c: Campaign, where: Path) -> tuple[bool, str]:
    """Case files with a property gate on a property the case does not name, and a gate
    on an unknown engine: ``truestep.load_case`` and ``truestep list`` must agree."""
    verdicts = []
    for label, gate_text in (
            ("property", '[[gates]]\nkind = "property"\nname = "final_speed"\ndt = 0.01\nmax = 1.0\n'
                         'method = "rk4"\n'),
            ("engine", '[[gates]]\nkind = "status"\nengine = "nosuch"\nmethod = "rk4"\n'
                       'dt = 0.01\nexpect = "ok"\n')):
        d = where / label
        d.mkdir()
        path = case_file(d, extra=gate_text)
        api = c.python(f"import truestep\ntry:\n    truestep.load_case({str(path)!r})\n"
                       "    print('ACCEPTED')\nexcept truestep.cases.CaseError as e:\n"
                       "    print('REFUSED', e)\n", d)
        cli = c.truestep(["list", "--cases", str(path)], d)
        api_ok, cli_ok = "ACCEPTED" in api.out, cli.code == 0
        verdicts.append((label, api_ok, cli_ok))
    alike = all(a == b for _, a, b in verdicts)
    return alike, "; ".join(f"{label}: load_case {'accepts' if a else 'refuses'}, CLI "
                            f"{'accepts' if b else 'refuses'}" for label, a, b in verdicts)


def attack_junit_into_a_fifo(c: Campaign, where: Path) -> tuple[bool, str]:
    """``truestep gate --junit`` a FIFO: refused, no hang."""
    tables = shipped_tables(where / "t")
    mkfifo(where / "j.xml")
    return refused(gate(c, where, tables / "results.csv", "--junit", "j.xml"))


def attack_json_into_a_directory(c: Campaign, where: Path) -> tuple[bool, str]:
    """``truestep gate --json`` a directory."""
    tables = shipped_tables(where / "t")
    (where / "out.json").mkdir()
    return refused(gate(c, where, tables / "results.csv", "--json", "out.json"))


# ---------------------------------------------------------------------------------------


def attacks() -> dict[int, list[Callable]]:
    """Every attack, by group."""
    return {
        1: [attack_sweep_checkpoints_replaced_by_a_payload, attack_analyses_checkpoint_planted,
            attack_whole_journal_planted, attack_a_checkpoint_damaged_by_one_byte,
            attack_special_files_named_as_checkpoints, attack_journal_folder_is_a_link_elsewhere,
            attack_forged_checkpoint_out_of_schema],
        2: [attack_out_is_a_folder_of_other_files, attack_out_is_the_current_directory,
            attack_out_is_the_home_directory, attack_out_is_a_link_to_other_files,
            attack_out_is_a_file, attack_report_holding_a_link_elsewhere,
            attack_planted_scratch_folder_beside_out,
            attack_modes_and_owners_come_from_the_old_report, attack_a_process_writing_into_out,
            attack_figures_command_into_a_folder_of_other_files,
            attack_bench_command_into_a_folder_of_other_files],
        3: [attack_fifo_toml_in_a_cases_directory, attack_dev_zero_toml_in_a_cases_directory,
            attack_dev_urandom_as_a_case_file, attack_sparse_20_gib_case_file,
            attack_fifo_gates_file, attack_dev_zero_gates_file, attack_fifo_results_table,
            attack_dev_zero_results_table, attack_dev_urandom_results_table,
            attack_fifo_beside_the_results_table, attack_dev_zero_beside_the_results_table,
            attack_sparse_20_gib_results_table, attack_baseline_results_is_dev_urandom,
            attack_load_case_on_a_fifo, attack_compare_on_a_fifo],
        4: [*(_limit_attack(k, v) for k, v in (
                ("particles", "1000000000000"), ("springs", "1000000000000"),
                ("steps", "1000000000000"), ("records", "1000000000000"), ("work", "1e300"),
                ("memory_mb", "1e300"), ("timeout_s", "1e300"))),
            attack_emitter_frame_dt_1e_300, attack_time_step_1e_300,
            attack_stability_bracket_1e_300, attack_linear_exact_of_20000_particles,
            attack_explicit_list_of_1e8_particles_api, attack_explicit_list_of_1e8_springs_api,
            attack_command_line_limit_without_trust],
        5: [_no_orphans("Spawner"), _no_orphans("Daemon"), _no_orphans("Forker"),
            attack_adapter_children_outlive_sigterm, attack_adapter_output_mixed_into_truestep_output,
            _crashed_rows("EarlyClock", "early-clock", "records_from_minus_10_s"),
            _crashed_rows("FrozenClock", "frozen-clock", "records_frozen_at_0"),
            _crashed_rows("NegativeWall", "negative-wall", "wall_time_of_minus_5_s"),
            _crashed_rows("NanWall", "nan-wall", "wall_time_nan"),
            attack_crash_output_shown_in_the_row],
        6: [attack_second_run_on_the_same_out, attack_resume_while_the_run_is_alive,
            attack_second_run_through_a_link, attack_resume_after_a_kill,
            attack_new_run_after_a_kill],
        7: [attack_names_in_index_md, attack_names_in_index_html,
            attack_names_on_the_console_of_run, attack_names_in_junit,
            attack_names_in_the_markdown_summary, attack_names_in_the_json,
            attack_names_on_the_console_of_gate, attack_mathtext_method_name],
        8: [attack_duplicated_rows, attack_dt_zero, attack_dt_negative, attack_all_nan_baseline,
            attack_a_100_mb_field, attack_duplicated_column, attack_a_directory_beside_the_results,
            attack_compare_on_duplicated_rows, attack_a_method_named_nan,
            attack_full_disk_while_writing_the_report, attack_load_case_and_cli_judge_gates_alike,
            attack_junit_into_a_fifo, attack_json_into_a_directory],
    }


@dataclass
class Summary:
    target: dict[str, str]
    command: str
    counts: dict[int, dict[str, int]] = field(default_factory=dict)
    verdicts: list[dict] = field(default_factory=list)
    seconds: float = 0.0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repo", type=Path, default=HERE.parent, help="checkout to attack")
    parser.add_argument("--python", type=Path, default=None,
                        help="interpreter that imports that checkout")
    parser.add_argument("--only", default="", help="groups to run, comma-separated (default all)")
    parser.add_argument("--json", type=Path, default=None, help="write the summary here")
    parser.add_argument("--work", type=Path, default=None, help="keep the generated files here")
    args = parser.parse_args(argv)
    target = Target.of(args.repo, args.python)
    work = args.work or Path(tempfile.mkdtemp(prefix="hostile-campaign-"))
    campaign = Campaign(target, work)
    only = {int(x) for x in args.only.split(",") if x.strip()} or set(GROUPS)
    print(f"attacking {target.repo} ({target.commit}) with {target.python}; files in {work}",
          file=sys.stderr, flush=True)
    started = time.perf_counter()
    for group, fns in attacks().items():
        if group in only:
            print(f"{group}. {GROUPS[group]}", file=sys.stderr, flush=True)
            for fn in fns:
                campaign.attack(group, fn)
    summary = Summary({k: str(v) for k, v in asdict(target).items()},
                      " ".join([Path(sys.executable).name, *sys.argv]),
                      seconds=round(time.perf_counter() - started, 1))
    for v in campaign.verdicts:
        counts = summary.counts.setdefault(v.group, {"tried": 0, "held": 0, "broken": 0})
        counts["tried"] += 1
        counts["held" if v.held else "broken"] += 1
    summary.verdicts = [asdict(v) for v in campaign.verdicts]
    print(f"target {target.repo} at {target.commit}")
    print("| # | finding | tried | held | broken |")
    print("|---|---|---|---|---|")
    for group, counts in sorted(summary.counts.items()):
        print(f"| {group} | {GROUPS[group]} | {counts['tried']} | {counts['held']} | "
              f"{counts['broken']} |")
    broken = [v for v in campaign.verdicts if not v.held]
    for v in broken:
        print(f"BROKEN [{v.group}] {v.name}: {v.note}")
    print(f"{summary.seconds:.0f} s")
    if args.json:
        args.json.write_text(json.dumps(asdict(summary), indent=1, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
