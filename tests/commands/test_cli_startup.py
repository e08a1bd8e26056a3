"""``truestep --version`` and ``--help`` (``truestep/cli.py``) answer without loading
the engines, pandas, scipy, numba or matplotlib (their time is measured in
``benchmarks/cli_startup.py``)."""

from __future__ import annotations

import subprocess
import sys

import pytest

HEAVY = ("pandas", "scipy", "numba", "matplotlib", "pymunk", "pybullet", "mujoco", "dask")


@pytest.mark.parametrize("argv", [["--version"], ["--help"], ["run", "--help"], ["gate", "--help"]])
def test_answering_loads_nothing_heavy(argv):
    code = (
        "import sys\n"
        "from truestep.cli import main\n"
        "try:\n"
        f"    main({argv!r})\n"
        "except SystemExit:\n"
        "    pass\n"
        f"print(sorted({{m.split('.')[0] for m in sys.modules}} & {set(HEAVY)!r}))\n"
    )
    argv = [sys.executable, "-c", code]
    done = subprocess.run(argv, capture_output=True, text=True, check=True, timeout=120)
    assert done.stdout.splitlines()[-1] == "[]"


def test_the_api_loads_none_of_scipy_s_heavy_parts():
    """Importing :mod:`truestep.api` (what ``truestep gate`` and a user's CI import) loads
    none of scipy's optimize, linalg, sparse or integrate: the implicit solver's linear
    algebra, the stability facts' root finder and the particle Jacobian's sparse matrix
    import them where they are used (a fifth of a second a process)."""
    heavy = ("scipy.optimize", "scipy.linalg", "scipy.sparse", "scipy.integrate")
    code = f"import sys\nimport truestep.api\nprint(sorted(set({heavy!r}) & set(sys.modules)))\n"
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120
    )
    assert done.stdout.splitlines()[-1] == "[]"
