"""Run a command and print each line of its output (standard output and error merged)
with the seconds since it started: how long a first run waits before its first row.

Usage: ``python tools/maintenance/stamp.py CMD ARGS...``, e.g.
``NUMBA_CACHE_DIR=$(mktemp -d) python tools/maintenance/stamp.py truestep run --quick --out DIR``.
Lines end at ``\\n`` or ``\\r``, so progress bars show too.
"""

from __future__ import annotations

import subprocess
import sys
import time


def main(argv: list[str]) -> int:
    began = time.perf_counter()
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    assert proc.stdout is not None
    pending = b""
    while chunk := proc.stdout.read1(4096):
        pending += chunk
        while ends := [k for k in (pending.find(b"\n"), pending.find(b"\r")) if k >= 0]:
            line, pending = pending[: min(ends)], pending[min(ends) + 1 :]
            if line.strip():
                print(f"{time.perf_counter() - began:8.2f} {line.decode(errors='replace')}", flush=True)
    code = proc.wait()
    print(f"{time.perf_counter() - began:8.2f} EXIT {code}", flush=True)
    return code


if __name__ == "__main__":
    if len(sys.argv) < 2 or sys.argv[1] in ("-h", "--help"):
        print(f"usage: stamp.py CMD [ARGS...]\n\n{__doc__}")
        sys.exit(0 if len(sys.argv) > 1 else 2)
    sys.exit(main(sys.argv[1:]))
