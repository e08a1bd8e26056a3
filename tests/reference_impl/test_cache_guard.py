"""A damaged numba cache file is compiled again, not raised (issue 37, item 11): numba
read a cut-short ``.nbi`` index or ``.nbc`` data file with ``pickle`` and raised
``UnpicklingError`` out of the first call, on every run, until the folder was deleted."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

MODULE = """
from numba import njit

@njit(cache=True)
def twice(x):
    return 2.0 * x
"""

CALL = """
import sys
sys.path.insert(0, {where!r})
{guard}
import cached_twice
print(cached_twice.twice(21.0))
"""


def _call(where: Path, guarded: bool) -> subprocess.CompletedProcess:
    guard = "import truestep.reference_impl" if guarded else ""
    code = textwrap.dedent(CALL.format(where=str(where), guard=guard))
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env={"PATH": ""})


@pytest.mark.parametrize("suffix", [".nbi", ".nbc"])
def test_a_cut_short_cache_file_is_compiled_again(tmp_path, suffix):
    (tmp_path / "cached_twice.py").write_text(textwrap.dedent(MODULE))
    first = _call(tmp_path, guarded=True)
    assert first.returncode == 0 and first.stdout.strip() == "42.0", first.stderr
    (damaged,) = (tmp_path / "__pycache__").glob(f"cached_twice.twice-*{suffix}")
    damaged.write_bytes(damaged.read_bytes()[:40])
    if suffix == ".nbi":  # numba alone raises (the failure this guards against)
        bare = _call(tmp_path, guarded=False)
        assert bare.returncode != 0 and "UnpicklingError" in bare.stderr
        damaged.write_bytes(damaged.read_bytes()[:40])
    again = _call(tmp_path, guarded=True)
    assert again.returncode == 0 and again.stdout.strip() == "42.0", again.stderr
    assert "Traceback" not in again.stderr
    assert len(damaged.read_bytes()) > 40  # written afresh
