"""``truestep compile`` compiles each engine's kernels (its ``warm`` hook) in a forked
process beside the reference's loops (:func:`truestep.execution.build_step.warm_apart`)."""

from __future__ import annotations

import multiprocessing
import os

from truestep.execution.build_step import warm_apart


def _say(line: str) -> None:
    print(line, flush=True)


def _raises(cases, say):
    raise RuntimeError("no compiler")


def _builds(cases, say):
    say(f"built {len(cases)}")
    return len(cases)


def _run(warm, parent: int | None = None) -> multiprocessing.Process:
    proc = multiprocessing.get_context("fork").Process(
        target=warm_apart, args=("some-engine", warm, ["a", "b"], parent or os.getpid(), _say)
    )
    proc.start()
    proc.join(60)
    return proc


def test_an_engine_s_compile_apart_says_what_it_built(capfd):
    assert _run(_builds).exitcode == 0
    out = capfd.readouterr().out.splitlines()
    assert out[0] == "built 2" and out[1].startswith("some-engine kernels ready in ")


def test_a_compile_that_raises_is_exit_1_and_one_line(capfd):
    assert _run(_raises).exitcode == 1
    out = capfd.readouterr()
    assert out.out.strip() == "truestep: some-engine kernels: RuntimeError: no compiler"
    assert "Traceback" not in out.err


def test_a_compile_whose_parent_is_gone_does_not_start():
    """After a SIGKILL of ``truestep compile``, an engine's compile stops with it (issue
    37): here its parent is this process, not the pid it was given."""
    assert _run(_builds, parent=os.getppid()).exitcode == 1


def _interrupted_helper(parent: int) -> None:
    import signal

    from truestep.runtime.interrupts import Interrupted

    def raising(signum, frame):  # truestep's own handler, as a forked helper inherits it
        raise Interrupted(signum)

    signal.signal(signal.SIGTERM, raising)
    from truestep.runtime.oscalls import helper_of

    helper_of(parent)
    os.kill(os.getpid(), signal.SIGTERM)
    raise AssertionError("still running after SIGTERM")


def test_a_helper_ends_on_sigterm_without_a_word(capfd):
    """Issue 37: SIGTERM of a run while its loops compile ahead: the compile helpers end at
    once, printing nothing (before, each printed the traceback of the handler it had
    inherited after the run's one line)."""
    import signal

    proc = multiprocessing.get_context("fork").Process(target=_interrupted_helper, args=(os.getpid(),))
    proc.start()
    proc.join(60)
    assert proc.exitcode == -signal.SIGTERM
    out = capfd.readouterr()
    assert out.out == "" and out.err == ""
