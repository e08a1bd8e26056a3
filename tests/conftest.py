"""Shared fixtures: the repository's case files, loaded once."""

from __future__ import annotations

import pytest

from truestep.cases import load_case
from truestep.cases.loader import CASE_DIR


@pytest.fixture(scope="session")
def case_named():
    """Load a case file of the repository by name (cached per session)."""
    cache = {}

    def load(name: str):
        if name not in cache:
            cache[name] = load_case(CASE_DIR / f"{name}.toml")
        return cache[name]

    return load


@pytest.fixture(scope="session", autouse=True)
def reference_loops_compiled():
    """The reference's compiled loops for every case file, made before the first test
    (each of a parallel session's workers compiles its share into numba's cache, the
    others load it from there), so that no two workers compile one loop at once."""
    import os

    from truestep.cases import load_cases
    from truestep.reference_impl.precompile import compile_all

    index = int(os.environ.get("PYTEST_XDIST_WORKER", "gw0")[2:])
    count = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    models = [c.model for c in load_cases("*") if c.model is not None]
    compile_all(models, share=(index, count), progress=lambda line: None)
