"""One vocabulary each: modelling features are :class:`~truestep.reference_impl.features.Feature`
members wherever truestep declares or reads them (an adapter's capabilities and notes, a
scene's needs), so a misspelt feature cannot silently make a case unsupported."""

from __future__ import annotations

import ast
import importlib.util
import sys
from pathlib import Path

import pytest

from truestep.adapters import adapter_class
from truestep.cases import load_cases
from truestep.reference_impl.features import Feature

ROOT = Path(__file__).resolve().parents[2]
BUILT_IN = ("reference", "scipy", "pymunk", "pybullet", "mujoco", "drake", "mujoco-warp", "newton")


@pytest.mark.parametrize("engine", BUILT_IN)
def test_every_built_in_adapter_declares_features_of_the_enumeration(engine):
    cls = adapter_class(engine)
    assert cls.capabilities and all(isinstance(f, Feature) for f in cls.capabilities), engine
    notes = getattr(cls, "unsupported_notes", None) or {}
    assert all(isinstance(f, Feature) for f in notes), sorted(map(str, notes))


def test_the_example_adapter_declares_features_of_the_enumeration(monkeypatch):
    """The worked example spells its capabilities as ``truestep.Feature`` members too."""
    monkeypatch.syspath_prepend(str(ROOT / "examples" / "leapfrog-lab"))
    spec = importlib.util.spec_from_file_location(
        "leapfrog_adapter_under_test", ROOT / "examples" / "leapfrog-lab" / "leapfrog_lab" / "adapter.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    sys.modules.pop("leapfrog_lab.world", None)
    caps = module.LeapfrogAdapter.capabilities
    assert caps and all(isinstance(f, Feature) for f in caps)


def test_every_case_of_the_library_needs_features_of_the_enumeration():
    for case in load_cases("*"):
        assert all(isinstance(f, Feature) for f in case.features), (case.name, case.features)


def test_no_adapter_spells_a_feature_as_a_string():
    """No string literal in an adapter's source equals a feature's name: each is written
    ``Feature.X`` (the check fails on the one this file plants)."""
    names = {f.value for f in Feature}

    def spelt(source: str) -> list[str]:
        tree = ast.parse(source)
        kinds = {  # a scene's kind ("ode", "particles") is another vocabulary
            id(c)
            for node in ast.walk(tree)
            if isinstance(node, ast.Compare)
            and isinstance(node.left, ast.Attribute)
            and node.left.attr == "kind"
            for c in node.comparators
        }
        return [
            node.value
            for node in ast.walk(tree)
            if isinstance(node, ast.Constant)
            and isinstance(node.value, str)
            and node.value in names
            and id(node) not in kinds
        ]

    assert sorted(spelt('caps = frozenset({"springs", Feature.DRAG}) if case.kind == "ode" else {"3d"}')) == [
        "3d",
        "springs",
    ]
    found = {p.name: spelt(p.read_text()) for p in sorted((ROOT / "adapters").glob("*.py"))}
    assert {k: v for k, v in found.items() if v} == {}


def test_the_measured_properties_are_the_cases_vocabulary():
    """Every property name a case file may name has a function, and no function registers
    a name the loader would refuse."""
    from truestep.cases.property_names import PROPERTY_KINDS
    from truestep.measures.properties import PROPERTIES, register

    assert set(PROPERTIES) == set(PROPERTY_KINDS)
    with pytest.raises(ValueError, match="not a property name"):
        register(lambda case, traj: 0.0)


def test_every_gate_kind_has_one_record_and_one_checker():
    """The loader validates with the kind's record, the checker dispatches on it: a kind
    that reads results rows has a checker of its own, the other two read their tables."""
    from truestep.cases.gate_kinds import GATE_KINDS
    from truestep.ci.gates import CHECKS

    rows = {name for name, kind in GATE_KINDS.items() if kind.reads in ("row", "sweep")}
    assert set(CHECKS) == rows
    assert {kind.reads for name, kind in GATE_KINDS.items() if name not in rows} == {
        "stability",
        "restitution",
    }
    assert len(GATE_KINDS) == 9


def test_no_harness_code_decides_by_a_gate_kind_s_name():
    """Whatever a kind of gate does differently (reads fixed steps only, names a property,
    reads wall times ...) is a field of its record: no comparison in the harness or the
    loader names a kind (the check fails on the one this file plants)."""
    from truestep.cases.gate_kinds import GATE_KINDS

    names = set(GATE_KINDS)

    def spelt(source: str) -> list[str]:
        return [
            c.value
            for node in ast.walk(ast.parse(source))
            if isinstance(node, ast.Compare)
            and isinstance(node.left, ast.Attribute)
            and node.left.attr == "kind"
            for c in node.comparators
            if isinstance(c, ast.Constant) and c.value in names
        ]

    assert spelt('if g.kind == "order" or g.kind != "speedup" or case.kind == "ode": pass') == [
        "order",
        "speedup",
    ]
    files = [*sorted((ROOT / "truestep").rglob("*.py")), *sorted((ROOT / "cases").glob("*.py"))]
    found = {str(p.relative_to(ROOT)): spelt(p.read_text()) for p in files if not p.is_symlink()}
    assert {k: v for k, v in found.items() if v} == {}
