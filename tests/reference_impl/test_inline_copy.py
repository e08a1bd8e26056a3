"""numba's inliner copies a callee's IR with one memo per inlining
(:mod:`truestep.reference_impl.inline_copy`): the code it makes is the code numba makes
without it, and nothing of one inlining is kept for the next."""

from __future__ import annotations

import copy

import numpy as np
from numba import njit
from numba.core import inline_closurecall

import truestep.reference_impl  # noqa: F401  (installs the memo)
from truestep.reference_impl import inline_copy


@njit(inline="always")
def _branchy(x: float, n: int) -> float:
    total = 0.0
    for k in range(n):
        if k % 3 == 0:
            total += x / (k + 1.0)
        elif k % 3 == 1:
            total -= x * x / (k + 2.0)
        else:
            total = total * 0.5 + x
    return total


@njit
def _twice(x: float, n: int) -> float:
    return _branchy(x, n) + _branchy(x + 1.0, n)


def test_a_function_inlined_twice_computes_what_python_computes_bit_for_bit():
    for x, n in [(0.3, 7), (1.7, 50), (-2.5, 1)]:
        expected = _branchy.py_func(x, n) + _branchy.py_func(x + 1.0, n)
        assert np.float64(_twice(x, n)).tobytes() == np.float64(expected).tobytes()


def test_the_memo_lives_only_while_one_inlining_runs():
    assert inline_closurecall.InlineWorker._truestep_one_memo
    _twice(0.5, 3)
    assert getattr(inline_copy._LOCAL, "memo", None) is None
    # outside an inlining, the stand-in copies as copy.deepcopy does: a fresh copy each time
    data = {"a": [1, 2]}
    first, second = inline_closurecall.copy.deepcopy(data), inline_closurecall.copy.deepcopy(data)
    assert first == data and first["a"] is not second["a"]
    assert inline_closurecall.copy.copy is copy.copy
