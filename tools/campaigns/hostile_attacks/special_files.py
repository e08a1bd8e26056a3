"""Special files wherever truestep reads a path: refused at once, never read whole."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from hostile_attacks.common import (
    Campaign,
    case_file,
    gate,
    mkfifo,
    refused,
    shipped_tables,
)


def cases_dir_with(where: Path, make: Callable[[Path], object]) -> Path:
    d = where / "cases"
    d.mkdir()
    case_file(d)
    make(d / "special.toml")
    return d


def attack_fifo_toml_in_a_cases_directory(c: Campaign, where: Path) -> tuple[bool, str]:
    """A FIFO named ``*.toml`` in a ``--cases`` directory (``truestep list``)."""
    d = cases_dir_with(where, mkfifo)
    return refused(c.truestep(["list", "--cases", str(d)], where, memory_gb=6, peak=True))


def attack_dev_zero_toml_in_a_cases_directory(c: Campaign, where: Path) -> tuple[bool, str]:
    """A link to /dev/zero named ``*.toml`` in a ``--cases`` directory (``truestep run``)."""
    d = cases_dir_with(where, lambda p: p.symlink_to("/dev/zero"))
    return refused(
        c.truestep(
            ["run", "--quick", "--engines", "reference", "--cases", str(d), "--out", "rep"],
            where,
            memory_gb=6,
            peak=True,
        )
    )


def attack_dev_urandom_as_a_case_file(c: Campaign, where: Path) -> tuple[bool, str]:
    """``--cases link.toml`` where the link leads to /dev/urandom."""
    (where / "link.toml").symlink_to("/dev/urandom")
    return refused(c.truestep(["list", "--cases", "link.toml"], where, memory_gb=6, peak=True))


def sparse(path: Path, size: int = 20 * 2**30) -> None:
    with path.open("w") as fh:
        fh.truncate(size)


def attack_sparse_20_gib_case_file(c: Campaign, where: Path) -> tuple[bool, str]:
    """A sparse case file of 20 GiB."""
    d = cases_dir_with(where, sparse)
    return refused(c.truestep(["list", "--cases", str(d)], where, memory_gb=6, peak=True))


def attack_fifo_gates_file(c: Campaign, where: Path) -> tuple[bool, str]:
    """``truestep gate --gates`` a FIFO."""
    tables = shipped_tables(where / "t")
    mkfifo(where / "gates.toml")
    return refused(gate(c, where, tables / "results.csv", "--gates", "gates.toml"))


def attack_dev_zero_gates_file(c: Campaign, where: Path) -> tuple[bool, str]:
    """``truestep gate --gates`` a link to /dev/zero."""
    tables = shipped_tables(where / "t")
    (where / "gates.toml").symlink_to("/dev/zero")
    return refused(gate(c, where, tables / "results.csv", "--gates", "gates.toml"))


def attack_fifo_results_table(c: Campaign, where: Path) -> tuple[bool, str]:
    """``truestep gate --results`` a FIFO."""
    mkfifo(where / "results.csv")
    return refused(gate(c, where, where / "results.csv"))


def attack_dev_zero_results_table(c: Campaign, where: Path) -> tuple[bool, str]:
    """``truestep gate --results`` a link to /dev/zero."""
    (where / "results.csv").symlink_to("/dev/zero")
    return refused(gate(c, where, where / "results.csv"))


def attack_dev_urandom_results_table(c: Campaign, where: Path) -> tuple[bool, str]:
    """``truestep gate --results`` a link to /dev/urandom."""
    (where / "results.csv").symlink_to("/dev/urandom")
    return refused(gate(c, where, where / "results.csv"))


def attack_fifo_beside_the_results_table(c: Campaign, where: Path) -> tuple[bool, str]:
    """A FIFO ``stability.csv`` beside a good results table."""
    tables = shipped_tables(where / "t")
    (tables / "stability.csv").unlink()
    mkfifo(tables / "stability.csv")
    return refused(gate(c, where, tables / "results.csv"))


def attack_dev_zero_beside_the_results_table(c: Campaign, where: Path) -> tuple[bool, str]:
    """``restitution.csv`` a link to /dev/zero beside a good results table."""
    tables = shipped_tables(where / "t")
    (tables / "restitution.csv").unlink()
    (tables / "restitution.csv").symlink_to("/dev/zero")
    return refused(gate(c, where, tables / "results.csv"))


def attack_sparse_20_gib_results_table(c: Campaign, where: Path) -> tuple[bool, str]:
    """A sparse results table of 20 GiB."""
    path = where / "results.csv"
    sparse(path)
    return refused(gate(c, where, path))


def attack_baseline_results_is_dev_urandom(c: Campaign, where: Path) -> tuple[bool, str]:
    """``--baseline DIR`` whose results table is a link to /dev/urandom."""
    tables = shipped_tables(where / "t")
    base = where / "base"
    base.mkdir()
    (base / "results.csv").symlink_to("/dev/urandom")
    return refused(gate(c, where, tables / "results.csv", "--baseline", str(base)))


def attack_load_case_on_a_fifo(c: Campaign, where: Path) -> tuple[bool, str]:
    """``truestep.load_case`` (the Python API) on a FIFO: a clean CaseError, no hang."""
    mkfifo(where / "fifo.toml")
    result = c.python(
        "import truestep\ntry:\n    truestep.load_case('fifo.toml')\n"
        "except truestep.cases.CaseError as e:\n    print('CLEAN', e)\n",
        where,
    )
    return result.code == 0 and "CLEAN" in result.out, result.why()


def attack_compare_on_a_fifo(c: Campaign, where: Path) -> tuple[bool, str]:
    """``truestep.compare`` (the Python API) on a folder whose results table is a FIFO."""
    tables = shipped_tables(where / "t")
    bad = where / "bad"
    bad.mkdir()
    mkfifo(bad / "results.csv")
    result = c.python(
        "import truestep\nfrom truestep.tables.io import TableError\ntry:\n"
        f"    truestep.compare({str(bad)!r}, {str(tables)!r})\n"
        "except TableError as e:\n    print('CLEAN', e)\n",
        where,
    )
    return result.code == 0 and "CLEAN" in result.out, result.why()


ATTACKS = [
    attack_fifo_toml_in_a_cases_directory,
    attack_dev_zero_toml_in_a_cases_directory,
    attack_dev_urandom_as_a_case_file,
    attack_sparse_20_gib_case_file,
    attack_fifo_gates_file,
    attack_dev_zero_gates_file,
    attack_fifo_results_table,
    attack_dev_zero_results_table,
    attack_dev_urandom_results_table,
    attack_fifo_beside_the_results_table,
    attack_dev_zero_beside_the_results_table,
    attack_sparse_20_gib_results_table,
    attack_baseline_results_is_dev_urandom,
    attack_load_case_on_a_fifo,
    attack_compare_on_a_fifo,
]
