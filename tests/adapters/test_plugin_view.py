"""truestep's process holds a plugin's adapter as data (issue 37, item 5): a view made from
one adapter made and read in a forked process. What the view answers must be what the
adapter itself answers: its settings, its method facts (step matrices included), its
methods' signatures, and each method's result, computed in a forked process."""

from __future__ import annotations

import inspect
import os
from types import MappingProxyType

import numpy as np
import pytest

from truestep.adapters import PluginFailed, UnknownEngine, get_adapter, plugin_answer, resolve_engine
from truestep.adapters.base import facts_of
from truestep.adapters.plugin_view import PluginView, probe
from truestep.adapters.reference import ReferenceAdapter
from truestep.reference_impl.solvers.facts import NAMED, MethodFacts, Stability
from truestep.runtime.isolation import in_isolated_child


def _own_matrix(a: float, b: float) -> np.ndarray:
    return np.array([[1.0, 1.0], [-a, 1.0 - b]])


class Plugin(ReferenceAdapter):
    """A reference subclass as a plugin declares one: facts by name, by ``like`` with a
    change, and with a step matrix of its own; a setting that is no plain data."""

    name = "view-test"
    methods = ("euler", "verlet", "mine")
    adaptive_methods = ()
    method_facts = MappingProxyType(
        {
            "euler": "euler",
            "verlet": MethodFacts.like("verlet", velocity_order=2),
            "mine": MethodFacts(
                order=1,
                evaluations_per_step=1,
                symplectic=False,
                stability=Stability(2.0, 2.0, step_matrix=_own_matrix),
            ),
        }
    )
    handle = object()
    speed_claim = False

    def made_where(self) -> tuple[int, bool]:
        return os.getpid(), in_isolated_child()

    @property
    def broken(self) -> int:
        raise RuntimeError("no licence")


def _view() -> PluginView:
    record = probe(Plugin)
    assert isinstance(record, dict)
    return PluginView("view-test", Plugin, record, ask=plugin_answer, failed=PluginFailed)


def test_the_view_answers_what_the_adapter_answers():
    view, real = _view(), Plugin()
    assert view.methods == real.methods and view.capabilities == real.capabilities
    assert view.speed_claim is False and view.method_notes == real.method_notes
    for method in ("euler", "verlet"):
        mine, theirs = facts_of(view, method), facts_of(real, method)
        assert mine == theirs and mine is not None and theirs is not None
        assert mine.stability is not None and theirs.stability is not None
        assert mine.stability.step_matrix is theirs.stability.step_matrix
        assert mine.stability.reach(0.1) == theirs.stability.reach(0.1)
    assert facts_of(view, "verlet").velocity_order == 2  # type: ignore[union-attr]
    assert facts_of(view, "euler") is NAMED["euler"]
    # a plugin's own step matrix is the class's own record, read statically
    assert facts_of(view, "mine").stability.step_matrix is _own_matrix  # type: ignore[union-attr]


def test_what_is_no_data_is_named_and_what_raised_raises_saying_so():
    view = _view()
    assert view.handle is Plugin.handle  # a class attribute, read without running code
    with pytest.raises(PluginFailed, match="reading its adapter's broken raised RuntimeError: no licence"):
        _ = view.broken
    with pytest.raises(AttributeError):
        _ = view.nothing_of_that_name


def test_a_method_runs_in_a_forked_process_with_the_plugin_s_signature():
    view = _view()
    pid, isolated = view.made_where()
    assert pid != os.getpid() and isolated
    params = inspect.signature(view.simulate).parameters
    assert list(params) == list(inspect.signature(Plugin().simulate).parameters)
    assert "monitor" in params


def test_get_adapter_holds_a_view_of_a_plugin_and_truestep_s_own_adapters_themselves():
    engine = resolve_engine(f"{__name__}:Plugin")
    assert isinstance(get_adapter(engine), PluginView)
    assert get_adapter(engine) is get_adapter(engine)  # made and read once
    assert isinstance(get_adapter("reference"), ReferenceAdapter)


class NeverMade(ReferenceAdapter):
    """An adapter whose ``__init__`` never returns (a licence server that never answers)."""

    name = "never-made-test"

    def __init__(self) -> None:
        import time

        time.sleep(3600)


def test_an_adapter_whose_making_never_ends_is_one_error_naming_the_limit(monkeypatch):
    import truestep.cases.plugins

    monkeypatch.setattr(truestep.cases.plugins, "IMPORT_S", 1.0)
    engine = resolve_engine(f"{__name__}:NeverMade")
    with pytest.raises(
        UnknownEngine, match=r"making its adapter test_plugin_view.NeverMade gave no answer within 1 s"
    ):
        get_adapter(engine)
