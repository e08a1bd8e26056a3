"""The columns of truestep's tables, each declared once.

``results.csv`` (one row per case, engine, method and step), ``stability.csv`` (one row per
stability search), ``restitution.csv`` (one row per bounce of a dropped ball) and
``scaling.csv`` (``truestep bench``: one row per engine, method and particle count) and
``scorecard.csv`` (the report's scorecard: one row per engine, method and family). Each
:class:`Column` says its type, unit, meaning, the label the report shows, whether it names
the row, whether every reader needs it, whether it depends on the machine, the values a
run can write, and how a baseline compares it. The runner, the analyses, the table
readers (:mod:`truestep.tables.io`), the baseline compare (:mod:`truestep.ci.baseline`), the
case loader's gate schema, the report's labels and ``truestep gate --help`` read them from
here; :func:`markdown` documents them.

This module imports nothing of truestep: any folder may read it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import pandas as pd


@dataclass(frozen=True)
class Compared:
    """How ``truestep gate --baseline`` compares a column: a change beyond ``tolerance``
    (relative to the baseline's value when ``relative``, else absolute) that goes the
    worse way (up when ``higher_is_worse``) is ``worse``; differences below ``floor`` (of
    the case's scale) are round-off."""

    tolerance: float
    why: str
    higher_is_worse: bool = True
    relative: bool = True
    floor: float = 0.0


@dataclass(frozen=True)
class Column:
    """One column of a table.

    kind : ``name`` (a name such as an engine or a status), ``text`` (free text),
    ``number`` (float, empty where not measured) or ``count`` (a whole number)
    unit : SI unit, ``1`` for a ratio, ``""`` for text
    meaning : one sentence for the CSV documentation
    label : the report's header, unit included (default: a number's name and unit, else
    the name)
    required : every reader of the table needs it
    machine : depends on the machine, its load or where the case file lies (every other
    column is the same, bit for bit, on any machine)
    least, most : the smallest and largest values a run writes (a reader refuses others)
    whole : a count from ``least`` on (a reader refuses fractions)
    gate : a gate (``error``, ``energy_drift``) or a ``no-worse-than`` gate may read it
    compared : how a baseline compares it (``None``: not compared)
    """

    name: str
    kind: str
    unit: str
    meaning: str
    label: str = ""
    required: bool = False
    machine: bool = False
    least: float | None = None
    most: float | None = None
    whole: bool = False
    gate: bool = False
    compared: Compared | None = None

    @property
    def header(self) -> str:
        """The report's header for this column."""
        if self.label:
            return self.label
        if self.kind == "number" and self.unit not in ("", "1"):
            return f"{self.name} ({self.unit})"
        return self.name

    @property
    def numeric(self) -> bool:
        return self.kind in ("number", "count")


@dataclass(frozen=True)
class Table:
    """A table: its name (and file ``<name>.csv``), what one row is, the columns that name
    a row (no two rows share them; in the order a row's label shows them) and its columns."""

    name: str
    row: str
    keys: tuple[str, ...]
    columns: tuple[Column, ...]

    def __post_init__(self) -> None:
        missing = set(self.keys) - set(self.names)
        if missing:
            raise ValueError(f"{self.name}: keys {sorted(missing)} are not columns")

    @property
    def names(self) -> list[str]:
        return [c.name for c in self.columns]

    def where(self, **flags: object) -> tuple[str, ...]:
        """The names of the columns whose attributes equal ``flags`` (``key=True`` ...)."""
        return tuple(c.name for c in self.columns if all(getattr(c, k) == v for k, v in flags.items()))

    @property
    def numeric(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.columns if c.numeric)

    def column(self, name: str) -> Column:
        for c in self.columns:
            if c.name == name:
                return c
        raise KeyError(f"{self.name}.csv has no column {name!r}")

    def frame(self, rows: list[dict], extra: Sequence[str] = ()) -> pd.DataFrame:
        """The rows (dicts of column -> value; a column a row lacks is empty) as this table,
        its columns in order, then ``extra`` ones (a results table's properties). A row
        with a column the table does not declare is an error (a column is declared here
        first)."""
        import pandas as pd

        known = {*self.names, *extra}
        for row in rows:
            unknown = set(row) - known
            if unknown:
                raise KeyError(f"{self.name}.csv has no column {sorted(unknown)[0]!r}")
        return writable(pd.DataFrame(rows, columns=[*self.names, *extra]))


def clean_text(value: object) -> object:
    """A cell as UTF-8 can hold it: a string's lone surrogates (an adapter's message made
    from undecodable bytes) become their ``\\udcxx`` escapes; anything else as it is."""
    if isinstance(value, str):
        return value.encode("utf-8", "backslashreplace").decode("utf-8")
    return value


def writable(frame: pd.DataFrame) -> pd.DataFrame:
    """``frame`` with every text cell :func:`clean_text`: a table truestep writes is one
    its CSV writer can write and its readers read (a lone surrogate in a message stopped
    the report, and every ``--resume``, at the CSV writer)."""
    from pandas.api.types import is_object_dtype, is_string_dtype

    for column in frame.columns:
        if is_object_dtype(frame[column]) or is_string_dtype(frame[column]):
            frame[column] = frame[column].map(clean_text)
    return frame


def _name(name: str, meaning: str) -> Column:
    return Column(name, "name", "", meaning, required=True)


_CASE = _name("case", "the case's name (its file name without .toml)")
_ENGINE = _name("engine", "the engine's registered name")
_METHOD = _name("method", "the engine's method (integrator or mode)")
_STATUS = Column(
    "status",
    "name",
    "",
    "ok, unstable (blew up; t_fail says when), stalled (finished, but a particle never moved "
    "where the scene moves it: its updates were below the precision of its state; the message "
    "says which), solver-failed, crashed, timeout, unsupported (missing says which features) "
    "or skipped (the note or message says why)",
    required=True,
)
_NOTE = Column("note", "text", "", "why a row is not ok, or what to know about it")

_DEVICE = Column(
    "device",
    "text",
    "",
    "where the row computed: cpu, or the GPU its engine was put on (--device of truestep run or "
    "truestep bench, or an adapter made for one); empty for rows that did not run",
)


RESULTS = Table(
    "results",
    "one run of a case with an engine and method at one step (or tolerance)",
    ("case", "engine", "method", "dt_kind", "dt"),
    (
        _CASE,
        _ENGINE,
        _METHOD,
        Column(
            "dt",
            "number",
            "s",
            "the step, or the rtol = atol tolerance of an adaptive method (dt_kind says which)",
            label="dt (s; tol if adaptive)",
            required=True,
        ),
        Column("dt_kind", "name", "", "step or tolerance: what dt is", required=True),
        _STATUS,
        Column(
            "error",
            "number",
            "m",
            "the case's error measure against its exact solution or reference: the worst "
            "position error over the run, or at the end where the case says "
            '[reference] error = "final" (an ODE case: its state\'s units)',
            label="error (m; ODE: state units)",
            required=True,
            least=0.0,
            gate=True,
            compared=Compared(
                1e-3,
                "identical on any machine with the same versions; round-off from other "
                "library versions moves it by parts in 1e9 on smooth scenes (adaptive runs "
                "more, where an accept/reject flips); a wrong term in a method changes it by "
                "factors",
                floor=1e-12,
            ),
        ),
        Column("error_final", "number", "m", "the position error at the end of the run"),
        Column(
            "error_v",
            "number",
            "m/s",
            "the velocity error, the worst over the run (a second-order ODE: its velocity half)",
        ),
        Column(
            "energy_drift",
            "number",
            "1",
            "the largest change of the total energy over the run, relative to the case's energy scale",
            label="energy drift (relative)",
            least=0.0,
            gate=True,
            compared=Compared(
                1e-3, "as error: identical with the same versions, factors when wrong", floor=1e-12
            ),
        ),
        Column(
            "energy_drift_final",
            "number",
            "1",
            "the change of the total energy at the end, relative to the case's energy scale",
            label="final energy drift (relative)",
            least=0.0,
            gate=True,
        ),
        Column(
            "nfev",
            "count",
            "evaluations",
            "evaluations of the forces (the derivative) the run made",
            label="nfev (evaluations)",
            least=0.0,
            gate=True,
            compared=Compared(
                0.02,
                "a fixed-step method's count is exact; an adaptive method's accept/reject "
                "decisions can flip on round-off near a tolerance boundary, by a step or two "
                "in a hundred",
            ),
        ),
        Column("steps", "count", "steps", "the steps the run took", least=0.0),
        Column(
            "wall_s",
            "number",
            "s",
            "the median wall time of the timed runs (building the scene and the warm-up are not timed)",
            label="wall (s)",
            machine=True,
        ),
        Column(
            "wall_s_spread",
            "number",
            "s",
            "half the interquartile range of the timed runs' wall times",
            machine=True,
        ),
        Column("repeats", "count", "runs", "how many runs were timed", machine=True, least=0.0),
        Column("t_fail", "number", "s", "the simulated time at which an unstable run blew up"),
        Column("missing", "text", "", "the features an unsupported engine lacks, comma-separated"),
        Column(
            "message",
            "text",
            "",
            "what the engine or the harness said: why a run did not end ok, and notes on the row "
            "(its device, its evaluations per step, a contact law that misses the asked "
            "restitution at some impact phase)",
        ),
        Column(
            "case_source",
            "text",
            "",
            "the case's name when the case library holds it, else its file (so that "
            "truestep gate finds it again)",
            machine=True,
        ),
        Column(
            "path",
            "text",
            "",
            "the engine's code path (the reference: compiled, numpy, or warp: its kernel on a GPU)",
        ),
        _DEVICE,
        Column(
            "host",
            "text",
            "",
            "the machine the row was timed on (empty for rows that did not run)",
            machine=True,
        ),
    ),
)
"""``results.csv``; one column per property the cases name follows these."""

STABILITY = Table(
    "stability",
    "one search for the largest stable step of a case with an engine and method",
    ("case", "engine", "method"),
    (
        _CASE,
        _ENGINE,
        _METHOD,
        Column(
            "dt_limit",
            "number",
            "s",
            "the largest step found stable over the case's horizon (bisection, bounded by runs)",
            required=True,
            least=0.0,
            compared=Compared(
                0.01,
                "the bisection stops at 0.1% (1% where the case says so); searches are "
                "bounded by their runs, never by time, so a machine's speed never moves it",
                higher_is_worse=False,
            ),
        ),
        Column(
            "dt_limit_exact",
            "number",
            "s",
            "the limit from the method's stability region and the scene's eigenvalues, where known",
            required=True,
        ),
        Column("dt_unstable", "number", "s", "the smallest step found unstable"),
        Column("runs", "count", "runs", "the simulations the search took", least=0.0),
        _STATUS,
        _NOTE,
        _DEVICE,
    ),
)
"""``stability.csv``."""

RESTITUTION = Table(
    "restitution",
    "one bounce of a ball dropped on a plane with a set restitution, per engine, method and step",
    ("engine", "method", "dt", "e_set", "bounce"),
    (
        _ENGINE,
        _METHOD,
        Column("dt", "number", "s", "the step", required=True),
        Column(
            "e_set",
            "number",
            "1",
            "the coefficient of restitution asked for",
            required=True,
            least=0.0,
            most=1.0,
        ),
        Column("bounce", "count", "", "which bounce (1, 2, 3)", required=True, least=1.0, whole=True),
        Column(
            "e_measured",
            "number",
            "1",
            "the restitution measured from the speeds just before and after contact",
            label="e_measured (from speeds)",
            required=True,
        ),
        Column(
            "e_apex",
            "number",
            "1",
            "the restitution measured from the apex heights before and after",
            label="e_apex (from apexes)",
        ),
        Column("v_in", "number", "m/s", "the normal speed into the contact"),
        Column("v_out", "number", "m/s", "the normal speed out of the contact"),
        Column("apex", "number", "m", "the height of the apex after the bounce"),
        Column("penetration", "number", "m", "how deep the ball went into the plane"),
        _STATUS,
        _NOTE,
        Column(
            "phases",
            "count",
            "",
            "first bounces of the impact-phase drops measured (bounce 1 only): balls dropped "
            "from heights whose contact begins at evenly spaced points within a step",
            whole=True,
            least=0.0,
        ),
        Column(
            "e_phase_median",
            "number",
            "1",
            "the median restitution (from speeds) over the impact-phase drops (bounce 1 only)",
            label="e median over phases",
        ),
        Column(
            "e_phase_min",
            "number",
            "1",
            "the smallest restitution over the impact-phase drops (bounce 1 only)",
            label="e min over phases",
        ),
        Column(
            "e_phase_max",
            "number",
            "1",
            "the largest restitution over the impact-phase drops (bounce 1 only)",
            label="e max over phases",
        ),
        _DEVICE,
    ),
)
"""``restitution.csv``."""

SCALING = Table(
    "scaling",
    "the rain scene with n particles, one engine and method (truestep bench)",
    ("engine", "method", "n"),
    (
        _ENGINE,
        _METHOD,
        Column("n", "count", "particles", "the particles of the scene", required=True),
        Column("steps", "count", "steps", "the steps timed (the budget decides)", machine=True),
        Column("repeats", "count", "runs", "how many runs were timed", machine=True),
        Column("wall_s", "number", "s", "the median wall time of the timed runs", machine=True),
        Column(
            "particle_steps_per_s",
            "number",
            "1/s",
            "particles times steps per wall second",
            label="particle-steps per s",
            machine=True,
        ),
        Column(
            "bandwidth_fraction",
            "number",
            "1",
            "the fraction of this machine's copy bandwidth (measured in the same run) the "
            "run's least memory traffic reaches",
            machine=True,
        ),
        Column(
            "untimed_s",
            "number",
            "s",
            "the time a size that did not run spent before it stopped",
            machine=True,
        ),
        Column("status", "name", "", "ok, skipped (over the budget) or the run's failure", required=True),
        _NOTE,
        _DEVICE,
    ),
)
"""``scaling.csv``."""

SCORECARD = Table(
    "scorecard",
    "an engine and method on a family of scenes: the report's scorecard as numbers",
    ("engine", "method", "family"),
    (
        _ENGINE,
        _METHOD,
        _name("family", "the family of scenes (the scorecard's column)"),
        Column(
            "target",
            "number",
            "1",
            "the error asked for, as a fraction of each case's error scale",
            required=True,
        ),
        Column("cases_run", "count", "cases", "the family's cases it ran", least=0.0, whole=True),
        Column(
            "cases_measured",
            "count",
            "cases",
            "of those, the cases with an error measure (an exact solution or a reference run)",
            least=0.0,
            whole=True,
        ),
        Column(
            "cases_reached",
            "count",
            "cases",
            "of those, the cases it reached the target error on",
            least=0.0,
            whole=True,
        ),
        Column(
            "cost_ratio",
            "number",
            "1",
            "the median over the cases it reached of its cheapest wall time there over the "
            "cheapest of every run that reached it (1: the fastest, or tied with it); empty if it "
            "reached none",
            machine=True,
        ),
        Column(
            "stability_cases",
            "count",
            "cases",
            "the family's stability searches whose exact limit is not 0",
            least=0.0,
            whole=True,
        ),
        Column(
            "stability_ratio",
            "number",
            "1",
            "the median of its largest stable step over the exact limit (or, with none known, over "
            "the best any method reached)",
        ),
        Column(
            "stability_zero",
            "count",
            "cases",
            "the searches whose exact limit is 0 (unstable at every step, as theory says)",
            least=0.0,
            whole=True,
        ),
        Column(
            "restitution_bounces",
            "count",
            "bounces",
            "the bounces of the restitution sweep it was measured on (the same in every family)",
            least=0.0,
            whole=True,
        ),
        Column(
            "restitution_gap",
            "number",
            "1",
            "the median over those bounces of the distance of e_measured from e_set",
        ),
        Column(
            "restitution_gap_worst",
            "number",
            "1",
            "the largest distance of e_measured from e_set over those bounces",
        ),
        Column(
            "stability_ratio_high",
            "number",
            "1",
            "the same median over the searches' smallest unstable steps (their limits where none "
            "was found): the boundary lies between stability_ratio and this; wide where round-off "
            "decides it (chaotic motion, a run on the edge of a test), and rankings tie overlapping "
            "intervals",
        ),
    ),
)
"""``scorecard.csv``: the report's scorecard figure as a table a tool reads."""

TABLES = {t.name: t for t in (RESULTS, STABILITY, RESTITUTION, SCALING, SCORECARD)}
"""Every table, by name."""

DERIVED: dict[str, Compared] = {
    "order": Compared(
        0.05,
        "absolute: fitted from errors that each hold to 1e-3, so the fit holds to about "
        "1e-3 / log(dt ratio); a lost order moves it by 1",
        higher_is_worse=False,
        relative=False,
    ),
    "e_error": Compared(
        0.005,
        "absolute, in |e_measured - e_set|, the restitution measured from velocities against the one set",
        relative=False,
    ),
    "wall_ratio": Compared(
        0.5,
        "relative (a run may take up to 1.5 times its former share of the named engine's time) "
        "beyond the noise of both runs' ratios (each row's spread, at least 15% and 10 us): "
        "a shared machine moves single timings by tens of percent, microsecond ones two-fold",
    ),
}
"""What a baseline compares beyond the tables' own columns: each method's fitted order (per
case and engine), the restitution error of each bounce, and (with ``--time-against``) a
row's wall time as a ratio to one engine/method's."""


def compared() -> dict[str, Compared]:
    """Every quantity a baseline compares, by name: the tables' compared columns, then
    :data:`DERIVED`."""
    out = {c.name: c.compared for t in TABLES.values() for c in t.columns if c.compared is not None}
    return {**out, **DERIVED}


def labels() -> dict[str, str]:
    """Column name -> the report's header, for every column whose header is not its bare
    name (a name in two tables has one header)."""
    out: dict[str, str] = {}
    for table in TABLES.values():
        for c in table.columns:
            if c.header != c.name:
                out.setdefault(c.name, c.header)
    return out


def markdown() -> str:
    """Every table's columns as markdown: name, type, unit and meaning."""
    parts = []
    for table in TABLES.values():
        lines = [
            f"### `{table.name}.csv`",
            "",
            f"One row: {table.row}. Keys: {', '.join(f'`{k}`' for k in table.keys)}.",
            "",
            "| column | type | unit | meaning |",
            "|---|---|---|---|",
        ]
        for c in table.columns:
            notes = [c.meaning]
            if c.machine:
                notes.append("(depends on the machine)")
            lines.append(f"| `{c.name}` | {c.kind} | {c.unit or '-'} | {' '.join(notes)} |")
        parts.append("\n".join(lines))
    return "\n\n".join(parts) + "\n"
