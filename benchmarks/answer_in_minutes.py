"""How long each answer truestep gives takes, against its target (issue 34's table).

Each figure is one command, run as a user would, its wall time measured around the whole
process; where the command writes a report, the run's own phases (``run.json``'s
``seconds``) are printed beside it. Run on an idle machine; the long figures are opt-in.

    python benchmarks/answer_in_minutes.py                  # quick, reference+mujoco, cold quick,
                                                            # a user's CI run with cold caches
    python benchmarks/answer_in_minutes.py --full           # and the README's main job (~13 min)
    python benchmarks/answer_in_minutes.py --suite --ci     # and the test suite idle and under
                                                            # load, and .ci/run on a fresh clone

``--cold`` runs use empty numba and Warp caches of their own (``NUMBA_CACHE_DIR``,
``WARP_CACHE_PATH``), so the machine's caches are not touched.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent

TARGETS_S = {
    "truestep run (every engine)": 600.0,
    "truestep run --engines reference,mujoco": 90.0,
    "truestep run --quick (warm)": 20.0,
    "truestep run --quick (cold caches)": 60.0,
    "a user's CI: run --quick, own engine (cold)": 30.0,
    "README test command (idle)": 180.0,
    "README test command (both cores busy)": 180.0,
    "bash .ci/run (fresh clone)": 480.0,
}
"""The target of each figure, s."""
TRUESTEP = [str(Path(sys.executable).with_name("truestep"))]
"""The ``truestep`` command of the interpreter running this script (its environment's,
whether or not that environment is on ``PATH``)."""


def timed(argv: list[str], *, env: dict | None = None, cwd: Path = REPO) -> tuple[float, int]:
    """Run ``argv``; its wall time (s) and exit code. Its output goes to a log under /tmp."""
    log = Path(tempfile.gettempdir()) / f"answer-{int(time.time())}-{os.getpid()}.log"
    began = time.perf_counter()
    with log.open("wb") as out:
        code = subprocess.run(argv, stdout=out, stderr=subprocess.STDOUT, env=env, cwd=cwd).returncode
    return time.perf_counter() - began, code


def phases(out: Path) -> str:
    """The run's phases from its ``run.json``, ``sweep 23.4 s, analyses 6.5 s, ...``."""
    try:
        seconds = json.loads((out / "run.json").read_text()).get("seconds", {})
    except (OSError, ValueError):
        return ""
    return ", ".join(f"{k} {v:.1f} s" for k, v in seconds.items() if isinstance(v, int | float))


def run_figure(name: str, args: list[str], *, cold: bool = False) -> None:
    env = dict(os.environ)
    with tempfile.TemporaryDirectory() as tmp:
        if cold:
            env.update(NUMBA_CACHE_DIR=f"{tmp}/numba", WARP_CACHE_PATH=f"{tmp}/warp")
        out = Path(tmp) / "out"
        wall, code = timed([*TRUESTEP, "run", *args, "--out", str(out)], env=env)
        report(name, wall, code, phases(out))


USER_CASES = "free-fall,harmonic-oscillator,damped-oscillator,spring-damper-pair,bouncing-ball"
"""The lecture's cases of the example project's CI command (``examples/leapfrog-lab/README.md``)."""


def user_ci() -> None:
    """A user's CI on a fresh machine: the quick run of the example project's engine beside
    the reference on its lecture cases, with empty caches (the example is put on the path
    by ``PYTHONPATH``, not installed: its own cases, registered by its entry points, are
    left out), then ``truestep gate`` on it with the example's gates file, timed apart (the
    target is the run's)."""
    example = REPO / "examples" / "leapfrog-lab"
    paths = [str(example), *filter(None, os.environ.get("PYTHONPATH", "").split(os.pathsep))]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(paths)}
    args = ["--quick", "--engines", "leapfrog_lab.adapter:LeapfrogAdapter,reference", "--cases", USER_CASES]
    with tempfile.TemporaryDirectory() as tmp:
        env.update(NUMBA_CACHE_DIR=f"{tmp}/numba", WARP_CACHE_PATH=f"{tmp}/warp")
        out = Path(tmp) / "out"
        wall, code = timed([*TRUESTEP, "run", *args, "--out", str(out)], env=env)
        gates = str(example / "truestep-gates.toml")
        gate_wall, gate_code = timed(
            [*TRUESTEP, "gate", "--results", str(out / "results.csv"), "--gates", gates], env=env
        )
        gate = f"then its gate (the example's CI step) {gate_wall:.1f} s, rc {gate_code}"
        report("a user's CI: run --quick, own engine (cold)", wall, code, f"{phases(out)}; {gate}")


def report(name: str, wall: float, code: int, extra: str = "") -> None:
    target = TARGETS_S[name]
    verdict = "meets" if code == 0 and wall <= target else "MISSES"
    print(f"{name:42s} {wall:8.1f} s  target {target:5.0f} s  {verdict}  rc {code}  {extra}", flush=True)


def suite(busy: bool) -> None:
    spinners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2 if busy else 0)]
    try:
        wall, code = timed([sys.executable, "-m", "pytest", "-q", "-n", "auto", "--dist", "loadfile"])
    finally:
        for p in spinners:
            p.kill()
            p.wait()
    report("README test command (both cores busy)" if busy else "README test command (idle)", wall, code)


def fresh_ci() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        clone = Path(tmp) / "truestep"
        subprocess.run(["git", "clone", "-q", str(REPO), str(clone)], check=True)
        env = {k: v for k, v in os.environ.items() if k != "VIRTUAL_ENV"}
        wall, code = timed(["bash", ".ci/run"], env={**env, "CI": "true"}, cwd=clone)
        report("bash .ci/run (fresh clone)", wall, code)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--full", action="store_true", help="also the README's main job (about 13 min)")
    parser.add_argument("--suite", action="store_true", help="also the test suite, idle and under load")
    parser.add_argument("--ci", action="store_true", help="also .ci/run on a fresh clone (about 9 min)")
    args = parser.parse_args()
    run_figure("truestep run --quick (warm)", ["--quick"])
    run_figure("truestep run --engines reference,mujoco", ["--engines", "reference,mujoco"])
    run_figure("truestep run --quick (cold caches)", ["--quick"], cold=True)
    user_ci()
    if args.full:
        run_figure("truestep run (every engine)", [])
    if args.suite:
        suite(busy=False)
        suite(busy=True)
    if args.ci:
        fresh_ci()
    return 0


if __name__ == "__main__":
    sys.exit(main())
