"""Shared fixtures: the repository's case files, loaded once."""

from __future__ import annotations

from truestep import numerics

numerics.set_environment()  # the suite computes as the truestep command does: before numpy loads

import pytest  # noqa: E402

from truestep.cases import load_case  # noqa: E402
from truestep.cases.loader import CASE_DIR  # noqa: E402


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
def reference_loops_compiled(tmp_path_factory):
    """The reference's compiled loops for every case file (and figure case), made before
    the first test:
    each of a parallel session's workers compiles its share into numba's cache, then waits
    (up to 10 minutes) for the others to finish theirs, so that no loop is compiled twice
    (by two workers, or by a ``truestep`` a test starts) and the tests load them all."""
    import os
    import time

    from truestep.cases import load_cases
    from truestep.reference_impl.precompile import compile_all

    index = int(os.environ.get("PYTEST_XDIST_WORKER", "gw0")[2:])
    count = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    from truestep.figures.scenes import FIGURE_CASE_DIR

    cases = [*load_cases("*"), *(load_case(path) for path in sorted(FIGURE_CASE_DIR.glob("*.toml")))]
    models = [c.model for c in cases if c.model is not None]
    compile_all(models, share=(index, count), progress=lambda line: None)
    done = tmp_path_factory.getbasetemp().parent / "reference-loops-compiled"
    done.mkdir(exist_ok=True)
    (done / str(index)).touch()
    waited = time.monotonic()
    while len(list(done.iterdir())) < count and time.monotonic() - waited < 600:
        time.sleep(0.2)
