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
LAYERS = {"harness": 0, "adapters": 1, "cases": 2, "reference_impl": 3}
"""Which folder may import which: a module imports only modules of its own folder or of a
folder below it (harness -> adapters -> cases -> reference_impl)."""
LAYER_EXCEPTIONS = {
    ("truestep.cases.loader", "truestep.adapters"),
    ("truestep.cases.loader", "truestep.measures.properties"),
}
"""Known arrows against the layers, each a lazy import inside a function (the loader checks
that a gate names a registered engine and a known property)."""


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
    part = module.split(".")[1] if module.count(".") else ""
    return LAYERS.get(part, LAYERS["harness"])


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
    """harness -> adapters -> cases -> reference_impl; reference_impl imports nothing of
    truestep's other folders, and no folder imports the harness (but for the known arrows,
    and leaves: modules that import nothing of truestep, such as the tables' column spec)."""
    leaves = {m for m in graph.modules if not graph.find_modules_directly_imported_by(m)}
    assert {"truestep.numerics", "truestep.tables.spec", "truestep.execution.time_limit"} <= leaves
    against = [
        (m, w)
        for m in sorted(graph.modules)
        for w in sorted(graph.find_modules_directly_imported_by(m))
        if _layer(w) < _layer(m) and w != "truestep" and w not in leaves and (m, w) not in LAYER_EXCEPTIONS
    ]
    assert against == []
