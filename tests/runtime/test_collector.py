"""The cyclic collector around a run (:mod:`truestep.runtime.collector`): what a run
changes of it is put back, in the caller's process, once the run returns."""

from __future__ import annotations

import gc

import pytest

import truestep
from truestep.runtime import collector


@pytest.fixture
def clean_collector():
    """The collector on and nothing frozen, before and after the test."""
    was_on = gc.isenabled()
    gc.unfreeze()
    gc.enable()
    yield
    gc.unfreeze()
    if not was_on:
        gc.disable()


def test_paused_turns_the_collector_off_and_back_as_it_was(clean_collector):
    with collector.paused() as was_on:
        assert was_on and not gc.isenabled()
    assert gc.isenabled()
    gc.disable()
    with collector.paused() as was_on:
        assert not was_on and not gc.isenabled()
    assert not gc.isenabled()


def test_frozen_hides_what_lives_on_entry_and_gives_it_back(clean_collector):
    kept = []  # a container the collector tracks
    with collector.paused() as collecting, collector.frozen(collecting=collecting):
        made = []
        assert gc.isenabled() and gc.get_freeze_count() > 0
        tracked = {id(o) for o in gc.get_objects()}
        assert id(kept) not in tracked and id(made) in tracked
    assert gc.isenabled() and gc.get_freeze_count() == 0
    assert id(kept) in {id(o) for o in gc.get_objects()}


def test_frozen_leaves_a_freeze_the_program_made(clean_collector):
    gc.freeze()
    count = gc.get_freeze_count()
    with collector.frozen():
        pass
    assert gc.get_freeze_count() == count  # not given back: the program froze them


def test_a_frozen_object_still_goes_once_nothing_refers_to_it(clean_collector):
    """Freezing leaves reference counting alone: only cycles wait for the thaw."""
    import weakref

    class Thing:
        pass

    thing = Thing()
    gone = weakref.ref(thing)
    with collector.frozen():
        del thing
        assert gone() is None


def test_a_run_leaves_the_caller_s_collector_as_it_found_it(clean_collector):
    """`truestep.run` pauses the collector for the engines' imports and freezes what they
    made for the run's time; its caller gets its collector back as it was, on or off."""
    truestep.run("free-fall", ["reference"], quick=True, analyses=False, progress=lambda _: None)
    assert gc.isenabled() and gc.get_freeze_count() == 0
    gc.disable()
    truestep.run("free-fall", ["reference"], quick=True, analyses=False, progress=lambda _: None)
    assert not gc.isenabled() and gc.get_freeze_count() == 0


def _inherited_frozen() -> bool:
    return gc.get_freeze_count() > 0 and not any(o is _MARK for o in gc.get_objects())


_MARK: list = []


def test_an_isolated_call_s_collector_never_walks_what_it_inherited(clean_collector):
    from truestep.runtime.isolation import run_isolated

    out = run_isolated(_inherited_frozen, (), timeout=60)
    assert out.status == "ok" and out.value is True
    assert gc.get_freeze_count() == 0  # the parent's own collector is untouched
