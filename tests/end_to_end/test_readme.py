"""The README's Python examples run as written."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from truestep.adapters.reference import ReferenceAdapter

README = (Path(__file__).resolve().parents[2] / "README.md").read_text()
BLOCKS = re.findall(r"```python\n(.*?)```", README, re.S)


def _block(marker: str) -> str:
    (block,) = [b for b in BLOCKS if marker in b]
    return block


def test_the_adapter_example_is_the_reference_symplectic_euler(case_named):
    """Its loop is v' = v + h a(x), x' = x + h v': the reference's symplectic Euler, to
    round-off (1e-12 m over 2000 steps of a 0.1 m oscillation)."""
    namespace: dict = {}
    exec(_block("class MyEuler"), namespace)
    case = case_named("harmonic-oscillator")
    mine = namespace["MyEuler"]().simulate(case, "semi-implicit", 1e-3)
    ref = ReferenceAdapter().simulate(case, "symplectic-euler", 1e-3)
    assert mine.status == "ok" and mine.nfev == mine.steps == 2000
    np.testing.assert_allclose(mine.x, ref.x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(mine.energy, ref.energy, rtol=1e-9)


def test_the_api_example_runs():
    exec(_block("truestep.load_cases"), {})
