"""The long fuzz campaign: generated case files through the loader and ``truestep run``,
damaged tables through ``truestep gate``, every outcome counted.

    python tools/campaigns/fuzz_campaign.py --loader 10000 --run 200 --gate 100 --seed 1 \\
        [--repo PATH] [--python PATH] [--json FILE]

``--repo`` is the checkout to attack (default: this one); its ``cases/*.toml`` and
``reports/*.csv`` are what gets mutated, so the same ``--seed`` makes the same mutations
of each checkout's own files. ``--python`` is the interpreter of a venv where that
checkout is installed (default: ``PATH/.venv/bin/python``, else this interpreter). Both
layouts are handled: ``truestep.cases`` (now) and the top-level ``cases`` package of the
first commits.

Outcomes (``classify_load``, ``classify_run``, ``classify_gate``):

* loader: ``accepted``; ``clean`` (a ``CaseError`` / ``SelectionError`` of one line of at
  most 300 characters naming the file); ``long-error`` (such an error, but longer, on
  several lines or not naming the file); ``traceback`` (any other exception: its type and
  where it was raised are kept); ``hang`` (no answer within ``--load-timeout`` s: the
  worker is killed and restarted); ``memory`` (``MemoryError``, or the worker killed).
  Files go through a long-lived worker process (one per target, restarted when it dies
  or hangs), with its address space capped (``--memory-gb``).
* run (loader-accepted mutants only): ``truestep run --quick --engines reference --cases
  FILE --out DIR`` with a wall timeout: ``ok`` (exit 0, rows counted by status),
  ``clean`` (exit 2, one short line), ``long-error`` (exit 2, longer), ``traceback``
  (``Traceback`` on stderr), ``hang``, ``memory`` (killed by a signal), and
  ``accepted-then-failed`` (any other non-zero exit, or exit 0 with every row crashed or
  timed out).
* gate: one of the shipped tables damaged (``tests/fuzz/fuzz_strategies.table_mutant``), the
  others as shipped, ``truestep gate --results DIR/results.csv``: ``clean`` (exit 2, one
  line), ``long-error``, ``traceback``, ``hang``, ``accepted`` (exit 0 on garbage) and
  ``judged`` (exit 1: garbage read as a table whose gates fail).

The JSON summary (``--json``) holds the counts, every bad outcome with the mutant's
recipe, and for traceback classes the exception type and the innermost frame.
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import random
import select
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[1] / "tests" / "fuzz"))  # fuzz_strategies lives beside the fuzz tests

import fuzz_strategies as fs  # noqa: E402

MAX_LINE = 300
"""The longest error line that counts as clean."""

LOAD_OUTCOMES = ("accepted", "clean", "long-error", "traceback", "hang", "memory")
RUN_OUTCOMES = ("ok", "clean", "long-error", "traceback", "hang", "memory", "accepted-then-failed")
GATE_OUTCOMES = ("clean", "long-error", "traceback", "hang", "memory", "accepted", "judged")
BAD = {"long-error", "traceback", "hang", "memory", "accepted-then-failed"}
"""Outcomes that are findings (for ``gate`` also ``accepted`` and ``judged``: garbage read)."""
GATE_BAD = BAD | {"accepted", "judged"}

WORKER = r"""
import json, os, resource, sys, traceback
try:
    from truestep.cases.loader import load_case
    from truestep.cases.errors import CaseError, SelectionError
    CLEAN = (CaseError, SelectionError)
except ImportError:
    from cases.loader import load_case
    from cases.errors import CaseError
    CLEAN = (CaseError,)
limit = int(float(sys.argv[1]) * 2**30)
vm = int(open("/proc/self/statm").read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
resource.setrlimit(resource.RLIMIT_AS, (vm + limit, vm + limit))
root = os.path.realpath(sys.argv[2])
out = sys.stdout
sys.stdout = open(os.devnull, "w")
print(json.dumps({"ready": True}), file=out, flush=True)
for line in sys.stdin:
    path = json.loads(line)
    try:
        load_case(path)
        reply = {"outcome": "accepted"}
    except CLEAN as err:
        reply = {"outcome": "error", "type": type(err).__name__, "message": str(err)}
    except MemoryError:
        reply = {"outcome": "memory", "type": "MemoryError", "message": ""}
    except BaseException as err:
        frames = traceback.extract_tb(err.__traceback__)
        ours = [f for f in frames if os.path.realpath(f.filename).startswith(root)]
        last = frames[-1] if frames else None
        mine = ours[-1] if ours else None
        try:
            message = str(err)
        except Exception:
            message = "<unprintable>"
        reply = {"outcome": "traceback", "type": type(err).__name__, "message": message[:300],
                 "at": f"{last.filename}:{last.lineno} {last.name}" if last else "",
                 "in_repo": f"{os.path.relpath(mine.filename, root)}:{mine.lineno} {mine.name}"
                 if mine else ""}
    print(json.dumps(reply), file=out, flush=True)
"""


@dataclass
class Target:
    """A checkout to attack: its root, the interpreter that imports it, its layout and commit."""

    repo: Path
    python: Path
    layout: str = "new"
    commit: str = ""

    @classmethod
    def of(cls, repo: Path, python: Path | None = None) -> Target:
        repo = repo.resolve()
        if python is None:
            venv = repo / ".venv" / "bin" / "python"
            python = venv if venv.exists() else Path(sys.executable)
        probe = subprocess.run(
            [str(python), "-c", "import truestep.cases.loader"],
            cwd=tempfile.gettempdir(),
            capture_output=True,
            text=True,
        )
        layout = "new" if probe.returncode == 0 else "old"
        commit = subprocess.run(
            ["git", "-C", str(repo), "rev-parse", "--short", "HEAD"], capture_output=True, text=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "-C", str(repo), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
        ).stdout.strip()
        return cls(repo, python, layout, commit + ("+dirty" if dirty else ""))

    @property
    def cli(self) -> list[str]:
        """The command that runs this target's ``truestep`` as a user starts it: ``python -m
        truestep`` (the console script's entry point, with its supervisor) where the checkout
        has one, else its ``truestep.cli.main`` (a checkout older than the supervisor)."""
        if (self.repo / "truestep" / "__main__.py").is_file():
            return [str(self.python), "-m", "truestep"]
        return [str(self.python), "-c", "import sys; from truestep.cli import main; sys.exit(main())"]


def _excerpt(data: bytes, n: int = 240) -> str:
    text = data[:n].decode("utf-8", "backslashreplace")
    return text + ("..." if len(data) > n else "")


def _one_line_ok(message: str, path: str | None = None) -> tuple[bool, str]:
    """Whether an error line is clean, and if not why."""
    message = message.rstrip("\n")
    if "\n" in message:
        return False, f"{message.count(chr(10)) + 1} lines"
    if len(message) > MAX_LINE:
        return False, f"{len(message)} chars"
    if path is not None and path not in message:
        return False, "does not name the file"
    if not message.strip():
        return False, "empty"
    return True, ""


# ---------------------------------------------------------------------------------------
# Loader
# ---------------------------------------------------------------------------------------


class LoadWorker:
    """A long-lived process of the target that loads one file per request."""

    def __init__(self, target: Target, timeout: float, memory_gb: float) -> None:
        self.target, self.timeout, self.memory_gb = target, timeout, memory_gb
        self.proc: subprocess.Popen[str] | None = None
        self.restarts = 0

    def _start(self) -> None:
        self.proc = subprocess.Popen(
            [
                "nice",
                "-n",
                "10",
                str(self.target.python),
                "-c",
                WORKER,
                str(self.memory_gb),
                str(self.target.repo),
            ],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            text=True,
            cwd=tempfile.gettempdir(),
            start_new_session=True,
        )
        ready = self._read(120.0)
        if not ready or not ready.get("ready"):
            raise RuntimeError(f"the loader worker of {self.target.repo} did not start")

    def _read(self, timeout: float) -> dict[str, Any] | None:
        assert self.proc is not None and self.proc.stdout is not None
        ready, _, _ = select.select([self.proc.stdout], [], [], timeout)
        if not ready:
            return None
        line = self.proc.stdout.readline()
        return json.loads(line) if line else None

    def kill(self) -> int | None:
        if self.proc is None:
            return None
        try:
            os.killpg(self.proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        code = self.proc.wait()
        self.proc = None
        return code

    def load(self, path: Path) -> dict[str, Any]:
        """``load_case(path)`` in the worker: its reply, or a hang / death."""
        if self.proc is None:
            self._start()
        assert self.proc is not None and self.proc.stdin is not None
        start = time.perf_counter()
        try:
            self.proc.stdin.write(json.dumps(str(path)) + "\n")
            self.proc.stdin.flush()
            reply = self._read(self.timeout)
        except (BrokenPipeError, OSError, ValueError):
            reply = None
        seconds = time.perf_counter() - start
        if reply is None:
            alive = self.proc.poll() is None
            code = self.kill()
            self.restarts += 1
            if alive and seconds >= self.timeout:
                return {"outcome": "hang", "seconds": round(seconds, 2)}
            return {"outcome": "memory", "type": f"killed (exit {code})", "seconds": round(seconds, 2)}
        reply["seconds"] = round(seconds, 4)
        return reply


def classify_load(path: Path, worker: LoadWorker) -> dict[str, Any]:
    """Load ``path`` in ``worker`` and name the outcome (:data:`LOAD_OUTCOMES`)."""
    reply = worker.load(path)
    if reply["outcome"] == "error":
        ok, why = _one_line_ok(reply["message"], str(path))
        reply["outcome"] = "clean" if ok else "long-error"
        if why:
            reply["why"] = why
    return reply


def loader_phase(
    target: Target, n: int, seed: int, work: Path, timeout: float, memory_gb: float
) -> list[dict[str, Any]]:
    """``n`` generated case files through the target's loader."""
    bases = fs.load_bases(target.repo)
    schema = fs.Schema.of(b.data for b in bases)
    worker = LoadWorker(target, timeout, memory_gb)
    records = []
    try:
        for i in range(n):
            mutant = fs.case_mutant(random.Random(f"{seed}:case:{i}"), bases, schema)
            path = mutant.write(work / "cases" / f"{i:05d}")
            record = {"i": i, "file": str(path), "how": mutant.how, **classify_load(path, worker)}
            records.append(record)
            if (i + 1) % 1000 == 0:
                counts = collections.Counter(r["outcome"] for r in records)
                print(f"  loader {i + 1}/{n}: {dict(counts)}", file=sys.stderr, flush=True)
    finally:
        worker.kill()
    return records


# ---------------------------------------------------------------------------------------
# run
# ---------------------------------------------------------------------------------------


def _run(
    cmd: list[str], cwd: Path, timeout: float, env: dict[str, str] | None = None, memory_gb: float = 8.0
) -> tuple[int | None, str, str, float]:
    """Run ``cmd`` niced, in its own session, with an address-space cap; kill the whole
    group at ``timeout``. Returns (exit code or None on timeout, stdout, stderr, seconds)."""

    def limits() -> None:
        import resource

        cap = int(memory_gb * 2**30)
        resource.setrlimit(resource.RLIMIT_AS, (cap, cap))

    start = time.perf_counter()
    proc = subprocess.Popen(
        ["nice", "-n", "10", *cmd],
        cwd=cwd,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        errors="backslashreplace",
        start_new_session=True,
        preexec_fn=limits,
    )
    try:
        out, err = proc.communicate(timeout=timeout)
        code: int | None = proc.returncode
    except subprocess.TimeoutExpired:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        out, err = proc.communicate()
        code = None
    return code, out, err, time.perf_counter() - start


def _old_layout_copy(target: Target, mutant_path: Path, where: Path) -> tuple[str, dict[str, str]]:
    """The first commits find cases by name in their package directory only: a private
    copy of the packages (``cases/`` copied, the rest linked) with the mutant in it, put
    first on ``PYTHONPATH``. Returns the ``--cases`` value and the environment."""
    tree = where / "tree"
    tree.mkdir(parents=True)
    for pkg in ("truestep", "adapters", "reference_impl"):
        if (target.repo / pkg).exists():
            (tree / pkg).symlink_to(target.repo / pkg)
    shutil.copytree(target.repo / "cases", tree / "cases", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copyfile(mutant_path, tree / "cases" / mutant_path.name)
    env = {**os.environ, "PYTHONPATH": str(tree)}
    return mutant_path.stem, env


def classify_run(target: Target, path: Path, timeout: float, memory_gb: float) -> dict[str, Any]:
    """``truestep run --quick --engines reference`` on one case file; the outcome
    (:data:`RUN_OUTCOMES`) with exit code, seconds and the statuses of its rows."""
    with tempfile.TemporaryDirectory(prefix="fuzz-run-") as tmp:
        tmpdir = Path(tmp)
        env = None
        cases = str(path)
        if target.layout == "old":
            cases, env = _old_layout_copy(target, path, tmpdir)
        cmd = [
            *target.cli,
            "run",
            "--quick",
            "--engines",
            "reference",
            "--cases",
            cases,
            "--out",
            str(tmpdir / "out"),
        ]
        code, _out, err, seconds = _run(cmd, tmpdir, timeout, env, memory_gb)
        statuses: dict[str, int] = {}
        results = tmpdir / "out" / "results.csv"
        if results.is_file():
            import csv

            with results.open(newline="", errors="replace") as fh:
                rows = list(csv.DictReader(fh))
            statuses = dict(collections.Counter(r.get("status", "?") for r in rows))
    record: dict[str, Any] = {"exit": code, "seconds": round(seconds, 2), "statuses": statuses}
    tail = err.strip().splitlines()
    record["stderr_tail"] = "\n".join(tail[-4:])[-800:]
    if code is None:
        record["outcome"] = "hang"
    elif "Traceback (most recent call last)" in err:
        record["outcome"] = "traceback"
        record["type"] = tail[-1][:200] if tail else ""
    elif code < 0 or "MemoryError" in err:
        record["outcome"] = "memory"
    elif code == 0:
        bad = sum(v for k, v in statuses.items() if k in {"crashed", "timeout"})
        total = sum(statuses.values())
        record["outcome"] = "accepted-then-failed" if total and bad == total else "ok"
    elif code == 2:
        ok, why = _one_line_ok(err)
        record["outcome"] = "clean" if ok else "long-error"
        if why:
            record["why"] = why
    else:
        record["outcome"] = "accepted-then-failed"
    return record


def run_phase(
    target: Target,
    loaded: list[dict[str, Any]],
    m: int,
    seed: int,
    timeout: float,
    memory_gb: float,
    jobs: int,
    partial: Path | None = None,
) -> list[dict[str, Any]]:
    """``m`` loader-accepted mutants (chosen with ``seed``) through ``truestep run``; each
    record is appended to ``partial`` (JSON lines) as it is done."""
    accepted = [r for r in loaded if r["outcome"] == "accepted"]
    rng = random.Random(f"{seed}:run")
    chosen = rng.sample(accepted, min(m, len(accepted)))
    done: list[dict[str, Any]] = []

    def one(r: dict[str, Any]) -> dict[str, Any]:
        rec = {
            "i": r["i"],
            "file": r["file"],
            "how": r["how"],
            **classify_run(target, Path(r["file"]), timeout, memory_gb),
        }
        done.append(rec)
        if partial is not None:
            with partial.open("a") as fh:
                fh.write(json.dumps(rec, default=str) + "\n")
        if len(done) % 20 == 0:
            counts = collections.Counter(x["outcome"] for x in done)
            print(f"  run {len(done)}/{len(chosen)}: {dict(counts)}", file=sys.stderr, flush=True)
        return rec

    with ThreadPoolExecutor(max_workers=jobs) as pool:
        return list(pool.map(one, chosen))


# ---------------------------------------------------------------------------------------
# gate
# ---------------------------------------------------------------------------------------


def classify_gate(
    target: Target, mutant: fs.TableMutant, tables: dict[str, bytes], timeout: float, work: Path
) -> dict[str, Any]:
    """``truestep gate --results`` on the shipped tables with one replaced by ``mutant``."""
    work.mkdir(parents=True, exist_ok=True)
    for name, data in tables.items():
        (work / f"{name}.csv").write_bytes(mutant.data if name == mutant.table else data)
    code, out, err, seconds = _run(
        [*target.cli, "gate", "--results", str(work / "results.csv")], target.repo, timeout
    )
    record: dict[str, Any] = {"exit": code, "seconds": round(seconds, 2)}
    tail = err.strip().splitlines()
    record["stderr_tail"] = "\n".join(tail[-4:])[-800:]
    if code is None:
        record["outcome"] = "hang"
    elif "Traceback (most recent call last)" in err:
        record["outcome"] = "traceback"
        record["type"] = tail[-1][:200] if tail else ""
    elif code < 0 or "MemoryError" in err:
        record["outcome"] = "memory"
    elif code == 2:
        ok, why = _one_line_ok(err)
        record["outcome"] = "clean" if ok else "long-error"
        if why:
            record["why"] = why
    elif code == 0:
        record["outcome"] = "accepted"
        record["stdout_tail"] = out.strip().splitlines()[-1][:200] if out.strip() else ""
    else:
        record["outcome"] = "judged"
        record["stdout_tail"] = out.strip().splitlines()[-1][:200] if out.strip() else ""
    return record


def gate_phase(
    target: Target, k: int, seed: int, timeout: float, work: Path, jobs: int
) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """A control (the shipped tables as they are), then ``k`` damaged tables through ``gate``."""
    tables = fs.load_tables(target.repo)
    control = classify_gate(
        target,
        fs.TableMutant("results", tables["results"], "as shipped"),
        tables,
        timeout,
        work / "gate" / "control",
    )

    def one(i: int) -> dict[str, Any]:
        mutant = fs.table_mutant(random.Random(f"{seed}:table:{i}"), tables)
        rec = classify_gate(target, mutant, tables, timeout, work / "gate" / f"{i:04d}")
        return {"i": i, "how": mutant.how, "excerpt": _excerpt(mutant.data, 160), **rec}

    with ThreadPoolExecutor(max_workers=jobs) as pool:
        return control, list(pool.map(one, range(k)))


# ---------------------------------------------------------------------------------------
# Summary
# ---------------------------------------------------------------------------------------


@dataclass
class Summary:
    """What a campaign found."""

    target: dict[str, str]
    seed: int
    command: str
    seconds: dict[str, float] = field(default_factory=dict)
    counts: dict[str, dict[str, int]] = field(default_factory=dict)
    run_statuses: dict[str, int] = field(default_factory=dict)
    gate_control: dict[str, Any] = field(default_factory=dict)
    classes: dict[str, list[dict[str, Any]]] = field(default_factory=dict)
    bad: dict[str, list[dict[str, Any]]] = field(default_factory=dict)


def _class_key(phase: str, r: dict[str, Any]) -> str:
    if phase == "loader" and r["outcome"] == "traceback":
        return f"traceback {r.get('type')} at {r.get('in_repo') or r.get('at')}"
    if r["outcome"] in {"long-error"}:
        return f"long-error ({r.get('why', '').split(' ')[-1]})"
    if r["outcome"] == "traceback":
        return f"traceback {r.get('type', '')[:80]}"
    return r["outcome"]


def summarise(phase: str, records: list[dict[str, Any]], summary: Summary, outcomes: tuple[str, ...]) -> None:
    counts = collections.Counter(r["outcome"] for r in records)
    summary.counts[phase] = {"tried": len(records), **{o: counts.get(o, 0) for o in outcomes}}
    bad = GATE_BAD if phase == "gate" else BAD
    classes: dict[str, list[dict[str, Any]]] = {}
    for r in records:
        if r["outcome"] in bad:
            classes.setdefault(_class_key(phase, r), []).append(r)
    summary.classes[phase] = [
        {"class": key, "count": len(rs), "example": _example(rs[0])}
        for key, rs in sorted(classes.items(), key=lambda kv: -len(kv[1]))
    ]
    summary.bad[phase] = [_example(r) for r in records if r["outcome"] in bad]


def _example(r: dict[str, Any]) -> dict[str, Any]:
    out = {k: v for k, v in r.items() if k not in {"seconds"} or r.get("outcome") == "hang"}
    if "file" in r:
        try:
            out["excerpt"] = _excerpt(Path(r["file"]).read_bytes())
        except OSError:
            pass
    return out


def print_table(summary: Summary, out: Any = sys.stdout) -> None:
    """The counts, then the first examples of every bad outcome class."""
    t = summary.target
    print(f"target {t['repo']} at {t['commit']} ({t['layout']} layout), seed {summary.seed}", file=out)
    cols = (
        "tried",
        "accepted",
        "ok",
        "clean",
        "long-error",
        "traceback",
        "hang",
        "memory",
        "accepted-then-failed",
        "judged",
    )
    print("| phase | " + " | ".join(cols) + " |", file=out)
    print("|---" * (len(cols) + 1) + "|", file=out)
    for phase, counts in summary.counts.items():
        cells = [str(counts[c]) if c in counts else "-" for c in cols]
        print(f"| {phase} | " + " | ".join(cells) + " |", file=out)
    print(
        "gate: accepted = exit 0 on garbage, judged = exit 1 (garbage read, gates failed); "
        f"control (shipped tables): exit {summary.gate_control.get('exit')}",
        file=out,
    )
    if summary.run_statuses:
        print(f"run rows by status (all runs): {summary.run_statuses}", file=out)
    print(f"seconds: {summary.seconds}", file=out)
    for phase, classes in summary.classes.items():
        for c in classes[:12]:
            ex = c["example"]
            print(f"\n[{phase}] {c['count']} x {c['class']}", file=out)
            print(f"  how: {ex.get('how', '')[:300]}", file=out)
            detail = ex.get("message") or ex.get("stderr_tail") or ex.get("type") or ""
            print(f"  error: {str(detail)[:400]}", file=out)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--loader", type=int, default=1000, help="case files through the loader")
    parser.add_argument("--run", type=int, default=20, help="accepted mutants through truestep run")
    parser.add_argument("--gate", type=int, default=20, help="damaged tables through truestep gate")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--repo", type=Path, default=HERE.parents[1], help="checkout to attack")
    parser.add_argument("--python", type=Path, default=None, help="interpreter that imports that checkout")
    parser.add_argument("--json", type=Path, default=None, help="write the summary here")
    parser.add_argument("--work", type=Path, default=None, help="keep the generated files here")
    parser.add_argument("--load-timeout", type=float, default=5.0)
    parser.add_argument("--run-timeout", type=float, default=60.0)
    parser.add_argument("--gate-timeout", type=float, default=60.0)
    parser.add_argument("--memory-gb", type=float, default=4.0, help="address-space cap per process")
    parser.add_argument("--jobs", type=int, default=1, help="parallel run / gate processes")
    args = parser.parse_args(argv)

    target = Target.of(args.repo, args.python)
    work = args.work or Path(tempfile.mkdtemp(prefix="fuzz-campaign-"))
    work.mkdir(parents=True, exist_ok=True)
    summary = Summary(
        target={k: str(v) for k, v in asdict(target).items()},
        seed=args.seed,
        command=" ".join([Path(sys.executable).name, *sys.argv]),
    )
    print(
        f"fuzzing {target.repo} ({target.commit}, {target.layout} layout) with {target.python}; "
        f"files in {work}",
        file=sys.stderr,
        flush=True,
    )

    def save() -> None:
        """The summary so far (after every phase, so a campaign cut short keeps its counts)."""
        if args.json:
            args.json.write_text(json.dumps(asdict(summary), indent=1, default=str))

    start = time.perf_counter()
    loaded = loader_phase(target, args.loader, args.seed, work, args.load_timeout, args.memory_gb)
    summary.seconds["loader"] = round(time.perf_counter() - start, 1)
    summarise("loader", loaded, summary, LOAD_OUTCOMES)

    if args.run:
        start = time.perf_counter()
        save()
        ran = run_phase(
            target,
            loaded,
            args.run,
            args.seed,
            args.run_timeout,
            args.memory_gb * 2,
            args.jobs,
            work / "run-records.jsonl",
        )
        summary.seconds["run"] = round(time.perf_counter() - start, 1)
        summarise("run", ran, summary, RUN_OUTCOMES)
        statuses: collections.Counter[str] = collections.Counter()
        for r in ran:
            statuses.update(r.get("statuses", {}))
        summary.run_statuses = dict(statuses)

    save()
    if args.gate:
        start = time.perf_counter()
        control, gated = gate_phase(target, args.gate, args.seed, args.gate_timeout, work, args.jobs)
        summary.seconds["gate"] = round(time.perf_counter() - start, 1)
        summary.gate_control = control
        summarise("gate", gated, summary, GATE_OUTCOMES)

    print_table(summary)
    save()
    if args.json:
        print(f"\nwrote {args.json}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
