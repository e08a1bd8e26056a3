"""An engine's import banner is dropped; anything else its import prints still reaches
standard error (``adapters/quiet.py``)."""

from __future__ import annotations

import subprocess
import sys
import textwrap


def test_the_banner_is_dropped_and_the_rest_is_kept(tmp_path):
    (tmp_path / "noisy_engine.py").write_text(
        textwrap.dedent(
            """
            import os
            os.write(1, b"noisy build time: today\\n")
            os.write(2, b"noisy build time: today\\nwarning: no GPU found\\n")
            """
        )
    )
    code = (
        "from truestep.adapters.quiet import import_quietly\n"
        "m = import_quietly('noisy_engine', banner=r'^noisy build time:')\n"
        "print('imported', m.__name__)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, check=True, timeout=120
    )
    assert done.stdout == "imported noisy_engine\n"
    assert done.stderr == "warning: no GPU found\n"


def test_pybullet_says_nothing_when_truestep_loads_it():
    code = "from truestep.adapters import get_adapter; print(get_adapter('pybullet').name)"
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=300
    )
    assert done.stdout == "pybullet\n" and "build time" not in done.stderr
