"""What every attack of the hostile campaign shares: running the target's ``truestep``
(niced, in a session of its own, its address space capped, its output in files, its
peak memory measured on request), the verdicts, and the inputs the attacks make (user
folders, case files, the published tables, snapshots of a folder)."""

from __future__ import annotations

import csv
import io
import os
import pickle
import shutil
import signal
import stat
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]
"""The ``benchmarks`` folder."""
sys.path.insert(0, str(HERE))

from fuzz_campaign import Target  # noqa: E402

PEAK = (
    "import resource, subprocess, sys\n"
    "code = subprocess.call(sys.argv[2:])\n"
    "open(sys.argv[1], 'w').write(str(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss))\n"
    "sys.exit(code if code >= 0 else 128 - code)\n"
)
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
    9: "round three: the failures of issue 37 stay fixed",
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
    def killed(self) -> bool:
        """Ended by SIGKILL: the process itself (a target run as ``truestep.cli.main``), or
        the worker of the command's supervisor, which then exits 128 + 9 as a shell would."""
        return self.code in (-signal.SIGKILL, 128 + signal.SIGKILL)

    @property
    def clean_refusal(self) -> bool:
        """Exit 2 with one short line on standard error and no traceback."""
        lines = [x for x in self.err.strip().splitlines() if x.strip()]
        return (
            self.code == 2 and len(lines) == 1 and len(lines[0]) <= MAX_LINE and "Traceback" not in self.err
        )

    @property
    def run_refusal(self) -> bool:
        """Exit 2 after a run's progress lines: one error line, last, no traceback."""
        lines = [x for x in self.err.strip().splitlines() if x.strip()]
        errors = [x for x in lines if x.startswith("truestep: error:")]
        return (
            self.code == 2
            and len(errors) == 1
            and lines[-1] == errors[0]
            and len(errors[0]) <= MAX_LINE
            and "Traceback" not in self.err
        )

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
        shutil.copy(Path(__file__).with_name("hostile_adapters.py"), self.adapters)
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

    def start(
        self,
        args: list[str],
        cwd: Path,
        *,
        env: dict[str, str] | None = None,
        memory_gb: float = 8.0,
        fsize: int | None = None,
        peak_file: Path | None = None,
    ) -> subprocess.Popen:
        """Start ``truestep ARGS`` (the target's), niced, in a session of its own; with
        ``peak_file``, through a wrapper that writes its peak memory (KiB) there."""

        def limits() -> None:
            import resource

            cap = int(memory_gb * 2**30)
            resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
            if fsize is not None:
                resource.setrlimit(resource.RLIMIT_FSIZE, (fsize, fsize))

        wrap = [] if peak_file is None else [sys.executable, "-c", PEAK, str(peak_file)]
        return self._popen(
            ["nice", "-n", "5", *wrap, *self.target.cli, *args], cwd, env or self.env(), limits
        )

    @staticmethod
    def _popen(cmd: list[str], cwd: Path, env: dict[str, str], limits) -> subprocess.Popen:
        """Start ``cmd`` with its output in files (a process it leaves behind holding a
        pipe cannot make the campaign wait), in a session of its own."""
        out, err = tempfile.TemporaryFile(), tempfile.TemporaryFile()
        proc = subprocess.Popen(
            cmd, cwd=cwd, env=env, stdout=out, stderr=err, start_new_session=True, preexec_fn=limits
        )
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

    def truestep(
        self,
        args: list[str],
        cwd: Path,
        *,
        timeout: float = CALL_TIMEOUT,
        env: dict[str, str] | None = None,
        memory_gb: float = 8.0,
        fsize: int | None = None,
        peak: bool = False,
    ) -> Result:
        started = time.perf_counter()
        peak_file = cwd / ".peak" if peak else None
        proc = self.start(args, cwd, env=env, memory_gb=memory_gb, fsize=fsize, peak_file=peak_file)
        result = self.finish(proc, timeout, started)
        if peak_file is not None and peak_file.exists():
            result.peak_mib = int(peak_file.read_text()) / 1024
            peak_file.unlink()
        return result

    def python(
        self, code: str, cwd: Path, *, timeout: float = CALL_TIMEOUT, memory_gb: float = 4.0
    ) -> Result:
        """Run ``code`` in the target's interpreter (for the Python API)."""

        def limits() -> None:
            import resource

            cap = int(memory_gb * 2**30)
            resource.setrlimit(resource.RLIMIT_AS, (cap, cap))

        started = time.perf_counter()
        proc = self._popen(["nice", "-n", "5", str(self.target.python), "-c", code], cwd, self.env(), limits)
        return self.finish(proc, timeout, started)

    def folder(self, name: str) -> Path:
        self._counter += 1
        where = self.work / f"{self._counter:03d}-{name}"
        where.mkdir(parents=True)
        return where

    def quick_run(
        self,
        cwd: Path,
        out: str,
        *extra: str,
        cases: str = BASE_CASES,
        engines: str = "reference",
        env: dict[str, str] | None = None,
        timeout: float = RUN_TIMEOUT,
        fsize: int | None = None,
    ) -> Result:
        return self.truestep(
            ["run", "--quick", "--engines", engines, "--cases", cases, "--out", out, *extra],
            cwd,
            timeout=timeout,
            env=env,
            fsize=fsize,
        )

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
        print(
            f"  [{group}] {'held ' if held else 'BROKE'} {name}: {v.note[:160]}", file=sys.stderr, flush=True
        )


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
    """The rows of results, stability and restitution without the columns that depend on the
    machine and its load (the timings, their spread and count, the host)."""
    out = {}
    for name in ("results", "stability", "restitution"):
        path = folder / f"{name}.csv"
        if not path.is_file():
            out[name] = []
            continue
        rows = list(csv.reader(io.StringIO(path.read_text())))
        drop = {i for i, c in enumerate(rows[0]) if c in ("wall_s", "wall_s_spread", "repeats", "host")}
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


def case_file(
    where: Path,
    name: str = "campaign-case",
    *,
    duration: str = "1.0",
    dt: str = "[0.01]",
    extra: str = "",
    body: str | None = None,
) -> Path:
    path = where / f"{name}.toml"
    path.write_text(body if body is not None else CASE.format(duration=duration, dt=dt, extra=extra))
    return path


def shipped_tables(where: Path) -> Path:
    """A copy of this checkout's published tables (the same input for every target)."""
    where.mkdir(parents=True, exist_ok=True)
    for name in ("results", "stability", "restitution"):
        shutil.copy(HERE.parents[1] / "reports" / f"{name}.csv", where / f"{name}.csv")
    return where


def gate(
    c: Campaign, cwd: Path, results: Path, *extra: str, timeout: float = CALL_TIMEOUT, memory_gb: float = 6.0
) -> Result:
    return c.truestep(
        ["gate", "--results", str(results), "-q", *extra],
        cwd,
        timeout=timeout,
        memory_gb=memory_gb,
        peak=True,
    )


def refused(result: Result) -> tuple[bool, str]:
    """Held: a clean refusal (and, where measured, within :data:`PEAK_LIMIT_MIB`: what
    is refused was never read whole)."""
    small = not result.peak_mib > PEAK_LIMIT_MIB
    return result.clean_refusal and small, result.why()


# ---------------------------------------------------------------------------------------
