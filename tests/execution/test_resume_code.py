"""``--resume`` after fixing an adapter (issue 37, item 8): the journal's identity covers the
engines' code, so the sweeps the buggy adapter made are never reused."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from truestep import adapters
from truestep.adapters import resolve_engine
from truestep.execution import journal
from truestep.execution.journal import Journal, JournalError, code_digest, fingerprint

ADAPTER = """
from truestep.adapters.reference import ReferenceAdapter


class Mine(ReferenceAdapter):
    name = "mine-{tag}"
    FACTOR = {factor}
"""


def test_a_fixed_adapter_does_not_resume_the_buggy_ones_sweeps(tmp_path, monkeypatch, case_named):
    module = tmp_path / "mine_adapter_for_resume.py"
    module.write_text(ADAPTER.format(tag="a", factor=1.5))
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(adapters, "_RESOLVED", dict(adapters._RESOLVED))  # mine-a leaves with the test
    engine = resolve_engine("mine_adapter_for_resume:Mine")
    cases = [case_named("free-fall")]
    before = fingerprint(cases, [engine, "reference"], quick=True)
    journal = Journal(tmp_path / "rep")
    journal.start(before)
    assert Journal(tmp_path / "rep").resume(before) == 0  # the same code resumes
    module.write_text(ADAPTER.format(tag="a", factor=1.0))  # the fix
    after = fingerprint(cases, [engine, "reference"], quick=True)
    assert after["code"][engine] != before["code"][engine]
    assert after["code"]["reference"] == before["code"]["reference"]
    with pytest.raises(JournalError, match="engine code"):
        Journal(tmp_path / "rep").resume(after)
    sys.modules.pop("mine_adapter_for_resume", None)


def test_truestep_s_own_engines_carry_its_source():
    digests = code_digest(["reference", "scipy"])
    assert len(set(digests.values())) == 2 and all(len(d) == 16 for d in digests.values())


def test_truestep_s_sources_include_the_subpackages_a_checkout_links_in():
    package = Path(journal.__file__).resolve().parents[1]
    names = {path.relative_to(package).as_posix() for path in journal.own_sources()}
    assert {"adapters/reference.py", "reference_impl/integrate.py", "cases/loader.py"} <= names
    assert "execution/journal.py" in names and not any("__pycache__" in n for n in names)


def test_truestep_s_own_engines_need_no_lookup_of_the_installed_distributions(monkeypatch):
    from importlib import metadata

    def refuse():
        raise AssertionError("looked up every installed distribution for an engine of truestep")

    monkeypatch.setattr(metadata, "packages_distributions", refuse)
    assert set(code_digest(["reference", "pymunk", "scipy"])) == {"reference", "pymunk", "scipy"}


def test_the_distributions_holding_a_module_are_those_importlib_maps_it_to():
    from importlib import metadata

    from truestep.runtime.distributions import holding

    owners = metadata.packages_distributions()
    assert {top: holding(top) for top in owners} == owners
    assert holding("no_such_module_anywhere") == []
