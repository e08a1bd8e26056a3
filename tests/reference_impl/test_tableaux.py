"""The Butcher tableaux: consistency and order conditions."""

from __future__ import annotations

import numpy as np
import pytest

from truestep.reference_impl.solvers import RK4, DormandPrince54, Euler, Heun, Midpoint

TABLEAUX = [Euler, Midpoint, Heun, RK4]


@pytest.mark.parametrize("cls", [*TABLEAUX, DormandPrince54])
def test_weights_sum_to_one_and_a_is_explicit(cls):
    assert cls.B.sum() == pytest.approx(1.0, abs=1e-15)
    assert np.allclose(np.triu(cls.A), 0.0)


@pytest.mark.parametrize("cls", TABLEAUX)
def test_rows_of_a_sum_to_the_nodes(cls):
    # C is derived from A; the classical nodes must come out.
    expected = {"euler": [0], "midpoint": [0, 0.5], "heun": [0, 1], "rk4": [0, 0.5, 0.5, 1]}
    assert np.allclose(cls.nodes(), expected[cls.name])


@pytest.mark.parametrize("cls", [*TABLEAUX, DormandPrince54])
def test_order_conditions(cls):
    """The order conditions up to each method's order (Butcher, up to order 4)."""
    A, b = cls.A, cls.B
    c = A.sum(axis=1)
    conditions = {
        1: [b.sum() - 1],
        2: [b @ c - 1 / 2],
        3: [b @ c**2 - 1 / 3, b @ A @ c - 1 / 6],
        4: [b @ c**3 - 1 / 4, b @ (c * (A @ c)) - 1 / 8, b @ A @ c**2 - 1 / 12, b @ A @ A @ c - 1 / 24],
    }
    for order in range(1, min(cls.order, 4) + 1):
        assert np.allclose(conditions[order], 0.0, atol=1e-14), f"order {order} condition"


def test_dopri_error_weights_are_b_minus_embedded_b():
    # The embedded fourth-order weights must themselves satisfy the order conditions
    # up to order 4, and sum to one.
    b_hat = DormandPrince54.B - DormandPrince54.E
    c = DormandPrince54.A.sum(axis=1)
    assert b_hat.sum() == pytest.approx(1.0, abs=1e-14)
    assert b_hat @ c == pytest.approx(0.5, abs=1e-14)
    assert b_hat @ c**3 == pytest.approx(0.25, abs=1e-14)
