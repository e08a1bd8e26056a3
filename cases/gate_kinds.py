"""The kinds of CI gate, one record each: what a gate of the kind must give, the table it
reads, and what tells two gates of the kind apart in its id.

The loader checks a ``[[gates]]`` table against its kind's record
(:func:`truestep.cases.loader.read_gate`), the checker dispatches on the kind's ``reads``
and its own function per kind (:mod:`truestep.ci.gates`, whose table of checkers a test
holds to these names), and :func:`truestep.ci.gates.gate_id` names a gate with its kind's
``tells_apart``. A new kind is one record here and one checker there.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Literal

from truestep.cases.fields import Fields
from truestep.tables.spec import RESULTS

STATUS_VALUES = {"ok", "unstable"}
"""What a ``status`` gate may expect of its row."""
QUANTITIES = set(RESULTS.where(gate=True))
"""The results columns a ``no-worse-than`` gate may compare (:mod:`truestep.tables.spec`)."""
RESTITUTION_QUANTITIES = {"e_measured", "e_apex"}
"""What a ``restitution`` gate may read: the velocity ratio or the apex-height one."""

Reads = Literal["row", "sweep", "stability", "restitution"]


def _expect_status(g: Fields, params: dict) -> None:
    params["expect"] = g.string("expect", choices=STATUS_VALUES)


def _property_name(g: Fields, params: dict) -> None:
    params["name"] = g.string("name")


def _over(g: Fields, params: dict) -> None:
    params["over"] = g.strings("over")


def _than(g: Fields, params: dict) -> None:
    than = g.string("than")
    other_engine, sep, other_method = than.partition("/")
    if not sep or not other_engine or not other_method or "*" in than:
        raise g.error("than", f"expected 'engine/method' of one run, got {than!r}")
    params["than"] = (other_engine, other_method)
    params["quantity"] = g.string("quantity", "error", choices=QUANTITIES)
    params.setdefault("factor", 1.0)
    if not params["factor"] > 0:
        raise g.error("factor", f"must be positive, got {params['factor']:g}")


def _restitution_quantity(g: Fields, params: dict) -> None:
    params["quantity"] = g.string("quantity", "e_measured", choices=RESTITUTION_QUANTITIES)


@dataclass(frozen=True)
class GateKind:
    """One kind of gate.

    name : the ``kind`` a gates table gives
    reads : where its verdict comes from: ``row`` (the results row at its ``dt``),
        ``sweep`` (every step of its engine and method), ``stability`` (the stability
        table) or ``restitution`` (the bounce table)
    needs : numbers it must give
    needs_dt : whether it must name the ``dt`` (or tolerance) of the row it reads
    one_of : numbers of which it must give at least one, with the sentence that says so
    fields : reads its own non-number fields (``params`` holds the numbers read so far)
    words : keys of :data:`GATE_NUMBERS` that this kind reads as words, not numbers
    any_status : its row may have any status (it reads the status); else a row that is
        not ``ok`` fails the gate, saying so
    tells_apart : what else, beside case, engine, method and step, its id carries
    steps_only : with no ``dt``, it reads the rows of fixed steps only (an order is a slope
        over steps, not tolerances)
    unmeasured : why a row gate finds no row with its quantity (the verdict's words)
    names_property : it names a property (``name``) that its case must measure
    needs_energy : it reads an energy drift, which a case that is neither conservative
        nor given an exact energy curve never measures (the loader warns)
    speed : it reads wall times: the report shows the speed table it judged
    """

    name: str
    reads: Reads
    needs: tuple[str, ...] = ()
    needs_dt: bool = False
    one_of: tuple[tuple[str, ...], str] | None = None
    fields: Callable[[Fields, dict], None] | None = None
    words: tuple[str, ...] = ()
    any_status: bool = False
    tells_apart: Callable[[dict], str] | None = None
    steps_only: bool = False
    unmeasured: str = "it has no exact solution or reference run"
    names_property: bool = False
    needs_energy: bool = False
    speed: bool = False


GATE_KINDS: Mapping[str, GateKind] = MappingProxyType(
    {
        k.name: k
        for k in (
            GateKind("order", "sweep", needs=("expect", "tol"), steps_only=True),
            GateKind("error", "row", needs=("max",), needs_dt=True),
            GateKind(
                "energy_drift",
                "row",
                needs=("max",),
                needs_dt=True,
                unmeasured=(
                    "a dissipative scene whose exact solution gives no energy curve, or one without energy"
                ),
                needs_energy=True,
            ),
            GateKind(
                "status", "row", needs_dt=True, fields=_expect_status, words=("expect",), any_status=True
            ),
            GateKind(
                "property",
                "row",
                needs_dt=True,
                one_of=(("max", "min"), "a property gate needs min, max or both"),
                fields=_property_name,
                tells_apart=lambda p: str(p.get("name", "")),
                names_property=True,
            ),
            GateKind(
                "stability-limit",
                "stability",
                one_of=(
                    ("rel_tol", "min"),
                    "a stability-limit gate needs rel_tol (against the exact limit), min (s), or both",
                ),
            ),
            GateKind("speedup", "row", needs=("min",), needs_dt=True, fields=_over, speed=True),
            GateKind(
                "restitution",
                "restitution",
                needs=("tol",),
                fields=_restitution_quantity,
                tells_apart=lambda p: str(p.get("quantity", "")),
            ),
            GateKind(
                "no-worse-than",
                "sweep",
                fields=_than,
                tells_apart=lambda p: f"{p.get('quantity', '')}-vs-{'/'.join(p.get('than', ()))}",
            ),
        )
    }
)
"""Every kind of gate, by name."""
GATE_NUMBERS = {"expect", "tol", "max", "min", "rel_tol", "factor", "bounce", "e_set"}
"""The numbers any gate may give (each kind reads those it needs)."""
