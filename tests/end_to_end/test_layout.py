"""The layout every tool reads: the four source folders are one package, ``truestep``, in the
checkout as when installed; its import graph has every file and no cycle; dependencies point
the way the design says."""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path

import grimp
import pytest

ROOT = Path(__file__).resolve().parents[2]
FOLDERS = {
    "truestep": "truestep",
    "adapters": "truestep.adapters",
    "cases": "truestep.cases",
    "reference_impl": "truestep.reference_impl",
}
LAYERS: tuple[tuple[str, ...], ...] = (
    ("runtime", "numerics", "style", ""),
    ("tables",),
    ("reference_impl",),
    ("cases",),
    ("adapters",),
    ("measures",),
    ("execution",),
    ("figures",),
    ("reporting",),
    ("ci",),
    ("api",),
    ("cli", "commands", "command", "pytest_plugin", "__main__"),
)
"""The package's layers, bottom first, by the part of a module's name after ``truestep.``: a
module imports only its own layer or one below. At the bottom the leaves every part may use
(processes, locks, publishing and safe reads in ``runtime``; the figures' look in
``style``; thread pinning in ``numerics``; the package root's version), then the tables'
column spec, the reference's numerics, the cases, the adapters, the measures, the
experiment driver, the figures, the report, the CI gates, the Python API and, on top, the
command line and the pytest plugin."""
LAYER_EXCEPTIONS = {("truestep.cases.loader", "truestep.adapters")}
"""Known arrows against the layers, each a lazy import inside a function: the loader's
default for the engines a case's gates may name is every engine the adapters' registry
knows (built-in, entry points, and ``module:Class`` names resolved in this process);
callers above the cases pass the names themselves."""


def _source_modules() -> dict[str, Path]:
    """Every module of the four folders, by the name it is imported as -> its file."""
    modules = {}
    for folder, package in FOLDERS.items():
        for path in sorted((ROOT / folder).glob("**/*.py")):
            if folder == "truestep" and path.relative_to(ROOT / folder).parts[0] in FOLDERS:
                continue  # a linked folder, read under its own name
            parts = path.relative_to(ROOT / folder).with_suffix("").parts
            name = ".".join([package, *parts])
            modules[name.removesuffix(".__init__")] = path
    return modules


@pytest.fixture(scope="module")
def graph() -> grimp.ImportGraph:
    return grimp.build_graph("truestep", exclude_type_checking_imports=True)


def _layer(module: str) -> int:
    parts = module.split(".")
    part = parts[1] if len(parts) > 1 else ""
    return next(i for i, names in enumerate(LAYERS) if part in names)


def test_the_folders_are_linked_into_the_package():
    for folder in ("adapters", "cases", "reference_impl"):
        link = ROOT / "truestep" / folder
        assert link.is_symlink() and os.readlink(link) == f"../{folder}", link


def test_every_source_file_is_the_module_its_name_says(graph):
    """Python finds each file under its package name, at its own path (no copy elsewhere),
    and the import graph holds it."""
    modules = _source_modules()
    assert len(modules) > 90
    for name, path in modules.items():
        spec = importlib.util.find_spec(name)
        assert spec is not None and spec.origin is not None, name
        assert Path(spec.origin).resolve() == path.resolve(), (name, spec.origin)
    assert set(modules) <= set(graph.modules), sorted(set(modules) - set(graph.modules))


def _cycles(graph: grimp.ImportGraph) -> list[list[str]]:
    """The import graph's strongly connected groups of more than one module (Tarjan, by an
    explicit stack)."""
    adj = {m: sorted(graph.find_modules_directly_imported_by(m)) for m in sorted(graph.modules)}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    groups: list[list[str]] = []
    for root in adj:
        if root in index:
            continue
        work = [(root, 0)]
        while work:
            v, i = work.pop()
            if i == 0:
                index[v] = low[v] = len(index)
                stack.append(v)
                on.add(v)
            if i < len(adj[v]):
                work.append((v, i + 1))
                w = adj[v][i]
                if w not in index:
                    work.append((w, 0))
                elif w in on:
                    low[v] = min(low[v], index[w])
                continue
            if low[v] == index[v]:
                group = []
                while True:
                    w = stack.pop()
                    on.discard(w)
                    group.append(w)
                    if w == v:
                        break
                if len(group) > 1:
                    groups.append(sorted(group))
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[v])
    return groups


def test_no_import_cycles(graph):
    """Not even through imports inside functions (only ``TYPE_CHECKING`` ones are left out:
    they never run)."""
    assert _cycles(graph) == []


def test_the_cycle_finder_finds_a_cycle():
    """The check above can fail: a two-module cycle and a three-module one are found."""
    fake = grimp.ImportGraph()
    for a, b in [
        ("p.a", "p.b"),
        ("p.b", "p.a"),
        ("p.c", "p.d"),
        ("p.d", "p.e"),
        ("p.e", "p.c"),
        ("p.e", "p.f"),
    ]:
        fake.add_import(importer=a, imported=b)
    assert sorted(_cycles(fake)) == [["p.a", "p.b"], ["p.c", "p.d", "p.e"]]


def test_dependencies_point_one_way(graph):
    """Every import, lazy ones included, points to the importer's layer or one below
    (:data:`LAYERS`), but for the known arrows; the leaves import nothing of truestep."""
    leaves = {m for m in graph.modules if not graph.find_modules_directly_imported_by(m)}
    assert {
        "truestep.numerics",
        "truestep.tables.spec",
        "truestep.runtime.time_limit",
        "truestep.style",
    } <= leaves
    against = [
        (m, w)
        for m in sorted(graph.modules)
        for w in sorted(graph.find_modules_directly_imported_by(m))
        if _layer(w) > _layer(m) and (m, w) not in LAYER_EXCEPTIONS
    ]
    assert against == []
    assert {(m, w) for m, w in LAYER_EXCEPTIONS if w in graph.find_modules_directly_imported_by(m)} == (
        LAYER_EXCEPTIONS
    ), "a known arrow is gone: take it off the list"


def test_every_module_is_in_a_layer():
    """A new subpackage names its layer before it lands (:data:`LAYERS`)."""
    known = {part for names in LAYERS for part in names}
    assert {m.split(".")[1] for m in _source_modules() if m.count(".")} <= known


def test_the_leaves_import_nothing_above_them(graph):
    """``runtime`` and ``style`` import only themselves (and ``numerics``): every other part
    may import them, in a child process or before any engine is loaded."""
    for m in graph.modules:
        if _layer(m) == 0:
            assert all(_layer(w) == 0 for w in graph.find_modules_directly_imported_by(m)), m


THIN_COMMANDS = {
    "baseline": set(),
    "bench": {"truestep.execution.bench_defaults"},
    "compiling": set(),
    "env": set(),
    "figures": set(),
    "gate": {"truestep.tables.spec"},
    "history": set(),
    "listing": set(),
    "run": set(),
}
"""Commands that are a parser and calls into :mod:`truestep.api`, each with the light
modules its parser reads its help from (building the parser, every command's start, must
not import the API): ``bench``'s default sizes and budget, ``gate``'s compared columns.
Every command is one."""
COMMAND_VOCABULARY = {
    "truestep.api",
    "truestep.commands",
    "truestep.commands.common",
    "truestep.runtime.visible",
}
"""What a thin command may import of truestep: the API, the commands' shared parser
helpers, and the escaping of what it prints."""


@pytest.mark.parametrize("command", THIN_COMMANDS)
def test_a_thin_command_imports_nothing_of_truestep_but_the_api(graph, command):
    module = f"truestep.commands.{command}"
    imported = {m for m in graph.find_modules_directly_imported_by(module) if m.startswith("truestep")}
    allowed = COMMAND_VOCABULARY | THIN_COMMANDS[command]
    assert "truestep.api" in imported, f"{module} does not call truestep.api"
    assert imported <= allowed, f"{module} imports {sorted(imported - allowed)}"


COMMON_VOCABULARY = {"truestep.api", "truestep.cases.limits", "truestep.runtime.visible"}
"""What the commands' shared helpers may import of truestep: the API (the cases of a
selection come from :func:`truestep.api.select_cases`, never from the loader), the limits'
keys and ceilings their ``--limit`` help names, and the escaping of what they print."""


def test_the_commands_shared_helpers_load_cases_only_through_the_api(graph):
    imported = {
        m
        for m in graph.find_modules_directly_imported_by("truestep.commands.common")
        if m.startswith("truestep")
    }
    assert imported <= COMMON_VOCABULARY, (
        f"truestep.commands.common imports {sorted(imported - COMMON_VOCABULARY)}"
    )
