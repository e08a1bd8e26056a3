"""Hostile adapters for the campaign: each runs the reference's rk4 and misbehaves.

The campaign copies this file into its work folder and names the adapters by
``hostile_adapters:CLASS`` (``HOSTILE_PIDS``: a file where they note the processes they
start). It is never imported by the campaign itself.
"""

from __future__ import annotations

import ctypes
import os
import subprocess
import sys
import time
from types import MappingProxyType

import numpy as np

from truestep.adapters.reference import ReferenceAdapter

PIDS = os.environ.get("HOSTILE_PIDS", "/dev/null")


def _note(pid):
    with open(PIDS, "a") as fh:
        fh.write(f"{pid}\n")


class _Base(ReferenceAdapter):
    """The reference's rk4 under every method name; :meth:`tamper` misbehaves."""

    methods = ("rk4",)
    adaptive_methods = ()
    schemes = MappingProxyType({"rk4": "rk4"})

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
    schemes = MappingProxyType(dict.fromkeys(methods, "rk4"))

    def tamper(self, traj):
        traj.message = "<b>bold</b> \u202eeulav \x1b[2J"
        return traj


class MathText(_Base):
    name = "mathtext"
    methods = (r"$\undefinedmacro{$", "_hidden")
    schemes = MappingProxyType(dict.fromkeys(methods, "rk4"))
