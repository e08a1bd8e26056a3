"""The guards' limits read from the environment (:func:`truestep.runtime.time_limit.guard_seconds`)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from truestep.runtime.time_limit import guard_seconds


@pytest.mark.parametrize(
    ("value", "seconds"),
    [
        (None, 300.0),
        ("2", 2.0),
        ("0.25", 0.25),
        ("abc", 300.0),
        ("0", 300.0),
        ("-5", 300.0),
        ("inf", 300.0),
        ("nan", 300.0),
        ("", 300.0),
    ],
)
def test_a_guard_takes_a_positive_finite_number_of_seconds_or_its_default(monkeypatch, value, seconds):
    if value is None:
        monkeypatch.delenv("TRUESTEP_SOME_GUARD_S", raising=False)
    else:
        monkeypatch.setenv("TRUESTEP_SOME_GUARD_S", value)
    assert guard_seconds("TRUESTEP_SOME_GUARD_S", 300.0) == seconds


def test_the_exact_check_answer_and_import_limits_come_from_the_environment_of_the_process():
    """The loader's exact-solution check, the adapters' answer limit and the plugins'
    import limit read their variables when imported: a command started with them set uses
    them."""
    from truestep.adapters import ANSWER_ENV
    from truestep.cases.loader import EXACT_CHECK_ENV
    from truestep.cases.plugins import IMPORT_ENV

    env = {**os.environ, ANSWER_ENV: "7", EXACT_CHECK_ENV: "9", IMPORT_ENV: "11"}
    code = (
        "import truestep.adapters as a, truestep.cases.loader as l, truestep.cases.plugins as p; "
        "print(a.ANSWER_S, l.EXACT_CHECK_S, p.IMPORT_S)"
    )
    said = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert said.stdout.split() == ["7.0", "9.0", "11.0"]
