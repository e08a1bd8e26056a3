"""Fuzzing in the normal suite: generated case files through the loader, damaged tables
through :func:`truestep.tables.io.read_table`.

The bounded tests run with every ``pytest`` (a few hundred examples, well under 30 s, the
same ones every run).
Case files are loaded in a separate worker process (``tools/campaigns/fuzz_campaign.py``'s
:class:`LoadWorker`) with an address-space cap and a per-file timeout, so that a file
that makes the loader hang or allocate without bound fails the test instead of stalling
or swapping the suite. Shrinking is off (a hang would be retried for every shrink step);
a failure reports the generated file's recipe (``how``) and its first bytes instead.

``test_fuzz_campaign_long`` is the long campaign (10 000 case files through the loader,
200 through ``truestep run``, 100 tables through ``truestep gate``; about half an hour
on two cores). It is marked ``fuzz`` and skipped unless asked for: ``pytest -m fuzz``
or ``TRUESTEP_FUZZ=1 pytest tests/fuzz/test_fuzz.py`` (``addopts`` is left alone, so a plain
``pytest`` collects it and reports it skipped).
"""

from __future__ import annotations

import importlib.util
import os
import shutil
import sys
import tempfile
import tomllib
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

import fuzz_strategies as fs
import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from truestep.tables.io import TableError, read_table

ROOT = Path(__file__).resolve().parents[2]
LOAD_TIMEOUT_S = 3.0
"""Per file: the slowest shipped case loads in well under a second."""

BOUNDED = settings(
    max_examples=150,
    deadline=None,
    phases=[Phase.explicit, Phase.reuse, Phase.generate],
    report_multiple_bugs=False,
    suppress_health_check=[HealthCheck.too_slow],
    derandomize=os.environ.get("TRUESTEP_FUZZ_RANDOM") != "1",
)
"""Bounded: the same examples every run (``TRUESTEP_FUZZ_RANDOM=1`` draws fresh ones), so
that the normal suite does not pass or fail by chance; the campaign covers more."""

NEEDS = {
    "results": {"case", "engine", "method", "dt", "dt_kind", "status", "error"},
    "stability": {"case", "engine", "method", "dt_limit", "dt_limit_exact"},
    "restitution": {"engine", "method", "dt", "e_set", "bounce", "e_measured"},
}
"""The columns ``truestep gate`` asks of each table (as in ``truestep.cli``)."""


def _campaign() -> ModuleType:
    spec = importlib.util.spec_from_file_location(
        "fuzz_campaign", ROOT / "tools" / "campaigns" / "fuzz_campaign.py"
    )
    assert spec and spec.loader
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("fuzz_campaign", module)
    spec.loader.exec_module(module)
    return module


campaign = _campaign()


@pytest.fixture(scope="module")
def worker() -> Iterator[object]:
    """A loader process of this checkout (this interpreter), killed after the module."""
    w = campaign.LoadWorker(campaign.Target(ROOT, Path(sys.executable)), LOAD_TIMEOUT_S, memory_gb=3.0)
    yield w
    w.kill()


@pytest.fixture(scope="module")
def scratch() -> Iterator[Path]:
    with tempfile.TemporaryDirectory(prefix="truestep-fuzz-") as tmp:
        yield Path(tmp)


def _check_load(worker: object, scratch: Path, mutant: fs.CaseMutant) -> None:
    """The loader accepts ``mutant`` or refuses it with one short line naming the file."""
    counter = getattr(_check_load, "n", 0) + 1
    _check_load.n = counter  # type: ignore[attr-defined]
    path = mutant.write(scratch / f"{counter:05d}")
    reply = campaign.classify_load(path, worker)
    detail = (
        f"{reply['outcome']}: {reply.get('type', '')} {reply.get('in_repo') or reply.get('at', '')} "
        f"{reply.get('why', '')}\n  message: {str(reply.get('message', ''))[:400]}\n"
        f"  how: {mutant.how}\n  file starts: {mutant.data[:300]!r}"
    )
    assert reply["outcome"] in {"accepted", "clean"}, detail


def test_toml_writer_round_trips_the_shipped_cases() -> None:
    """The mutants are written by :func:`fuzz_strategies.to_toml`: it must write every
    shipped case back as the same table, or the mutants would not be the cases mutated."""
    for base in fs.load_bases(ROOT):
        assert tomllib.loads(fs.to_toml(base.data)) == base.data, base.name


@BOUNDED
@given(mutant=fs.case_mutants(ROOT))
def test_loader_on_mutated_cases(worker: object, scratch: Path, mutant: fs.CaseMutant) -> None:
    """Shipped cases mutated (structure and bytes) and schema-made cases: the loader
    raises nothing but ``CaseError`` / ``SelectionError``, on one line of at most 300
    characters that names the file; it never hangs nor runs out of memory."""
    _check_load(worker, scratch, mutant)


@settings(BOUNDED, max_examples=60)
@given(data=fs.schema_cases(ROOT), name=st.sampled_from([b.name for b in fs.load_bases(ROOT)]))
def test_loader_on_schema_cases(worker: object, scratch: Path, data: dict, name: str) -> None:
    """Cases assembled from the shipped files' schema (plausible keys, values seen there,
    sometimes hostile ones): accepted, or refused with one short line."""
    _check_load(worker, scratch, fs.CaseMutant(name, fs.to_toml(data).encode("utf-8", "replace"), "schema"))


KNOWN_ESCAPES = {
    # A >4300-digit integer inside a value of the wrong type: quoting it (fields.short) calls
    # repr() on the container, and int -> str trips Python's digit limit (ValueError).
    "huge-int-in-a-list": ("harmonic-oscillator", "title = [0x" + "f" * 4000 + "]\n"),
    # An unknown name is answered with the whole list of known ones: past 300 characters once
    # the file's path is ~60 characters long (a path under /tmp/pytest-of-... is).
    "unknown-property-lists-all": ("sliding-contact", 'properties = ["<img src=x onerror=alert(1)>"]\n'),
    "unknown-exact-lists-all": ("sliding-contact", '[reference]\nexact = "<img src=x onerror=alert(1)>"\n'),
}
"""What the campaign still found at 2213af4 (one minimal file per class): the line
prepended (or the table replaced) in the shipped case."""


@pytest.mark.parametrize("label", sorted(KNOWN_ESCAPES))
def test_known_escapes(scratch: Path, worker: object, label: str) -> None:
    """The remaining failure classes of the campaign, as fixed files at a path of 60
    characters."""
    del scratch
    name, text = KNOWN_ESCAPES[label]
    shipped = (ROOT / "cases" / f"{name}.toml").read_text()
    if text.startswith("[reference]"):
        data = tomllib.loads(shipped)
        data["reference"] = tomllib.loads(text)["reference"]
        body = fs.to_toml(data)
    else:
        data = tomllib.loads(shipped)
        data.pop(text.split(" = ")[0], None)
        body = text + fs.to_toml(data)
    top = Path(tempfile.mkdtemp(prefix="tf-"))
    try:
        directory = top / ("d" * max(1, 60 - len(str(top / f"{name}.toml")) - 1))
        directory.mkdir()
        path = directory / f"{name}.toml"
        path.write_text(body)
        reply = campaign.classify_load(path, worker)
    finally:
        shutil.rmtree(top, ignore_errors=True)
    assert reply["outcome"] in {"accepted", "clean"}, (reply, len(str(path)))


@settings(BOUNDED, max_examples=150)
@given(mutant=fs.table_mutants(ROOT))
def test_read_table_on_mutated_tables(scratch: Path, mutant: fs.TableMutant) -> None:
    """Damaged results / stability / restitution tables: ``read_table`` raises only
    ``TableError``, on one line of at most 300 characters."""
    path = scratch / "tables" / f"{mutant.table}.csv"
    path.parent.mkdir(exist_ok=True)
    path.write_bytes(mutant.data)
    try:
        read_table(path, mutant.table, NEEDS[mutant.table], rows=mutant.table == "results")
    except TableError as err:
        message = str(err)
        assert "\n" not in message and len(message) <= campaign.MAX_LINE, (mutant.how, message[:400])


def _asked_for(config: pytest.Config) -> bool:
    expr = str(config.getoption("-m") or "")
    return os.environ.get("TRUESTEP_FUZZ") == "1" or ("fuzz" in expr and "not fuzz" not in expr)


@pytest.mark.fuzz
def test_fuzz_campaign_long(request: pytest.FixtureRequest, tmp_path: Path) -> None:
    """The long campaign against this checkout: no traceback, hang, memory blow-up, long
    error line or accepted-then-failed run, and no garbage table accepted by ``gate``.
    Skipped unless ``-m fuzz`` or ``TRUESTEP_FUZZ=1`` (see the module docstring)."""
    if not _asked_for(request.config):
        pytest.skip("the long fuzz campaign runs with -m fuzz or TRUESTEP_FUZZ=1")
    out = tmp_path / "summary.json"
    campaign.main(
        [
            "--loader",
            os.environ.get("TRUESTEP_FUZZ_LOADER", "10000"),
            "--run",
            os.environ.get("TRUESTEP_FUZZ_RUN", "200"),
            "--gate",
            os.environ.get("TRUESTEP_FUZZ_GATE", "100"),
            "--seed",
            os.environ.get("TRUESTEP_FUZZ_SEED", "4"),
            "--jobs",
            "2",
            "--repo",
            str(ROOT),
            "--python",
            sys.executable,
            "--work",
            str(tmp_path / "work"),
            "--json",
            str(out),
        ]
    )
    import json

    summary = json.loads(out.read_text())
    bad = {
        phase: {
            k: v
            for k, v in counts.items()
            if k in campaign.GATE_BAD and v and (phase == "gate" or k in campaign.BAD)
        }
        for phase, counts in summary["counts"].items()
    }
    assert not any(bad.values()), (bad, {p: c[:5] for p, c in summary["classes"].items()})
