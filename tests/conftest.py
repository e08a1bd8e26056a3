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
