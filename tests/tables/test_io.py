"""Malformed tables handed to ``truestep gate``: exit 2 and one line, never a traceback or
a quiet pass."""

from __future__ import annotations

import shutil
from pathlib import Path

import pandas as pd
import pytest

from truestep.cli import main

REPORTS = Path(__file__).resolve().parents[2] / "reports"


@pytest.fixture()
def run_dir(tmp_path):
    for name in ("results.csv", "stability.csv", "restitution.csv"):
        shutil.copy(REPORTS / name, tmp_path / name)
    return tmp_path


def _gate(path: Path, capsys) -> tuple[int, str]:
    code = main(["gate", "--results", str(path / "results.csv"), "-q"])
    return code, capsys.readouterr().err


def test_the_published_tables_are_read(run_dir, capsys):
    assert _gate(run_dir, capsys)[0] in (0, 1)


def _header(path: Path) -> str:
    return path.read_text().splitlines()[0]


@pytest.mark.parametrize(
    ("table", "damage"),
    [
        ("results.csv", lambda p: p.write_text("")),
        ("results.csv", lambda p: p.write_text(_header(p) + "\n")),  # header only
        ("results.csv", lambda p: p.write_bytes(b"\0" * 64)),
        ("results.csv", lambda p: p.write_bytes(b"case,engine\n\xff\xfe,x\n")),
        ("results.csv", lambda p: p.write_text(p.read_text() + "a,b\n")),  # ragged
        (
            "results.csv",
            lambda p: p.write_text(p.read_text().replace(",ok,", ",7,", 1).replace(",ok,", ",fine,", 1)),
        ),
        ("results.csv", lambda p: p.write_text(p.read_text().replace(",step,ok,", ",step,ok,x", 1))),
        ("stability.csv", lambda p: p.write_bytes(b"\x89PNG\r\n\x1a\n\0\0")),
        ("stability.csv", lambda p: p.write_text("case,engine\nx,y\n")),  # missing columns
        ("restitution.csv", lambda p: (p.unlink(), p.mkdir())),  # a directory
    ],
)
def test_malformed_tables_are_exit_2_and_one_line(run_dir, capsys, table, damage):
    damage(run_dir / table)
    code, err = _gate(run_dir, capsys)
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2, err
    assert len(lines) == 1 and len(lines[0]) < 300 and "Traceback" not in err
    assert table in lines[0]


def test_an_unusable_out_fails_before_the_sweep(tmp_path, capsys):
    target = tmp_path / "a-file"
    target.write_text("kept")
    code = main(["run", "--quick", "--cases", "free-fall", "--engines", "reference", "--out", str(target)])
    err = capsys.readouterr().err
    assert code == 2 and "is a file" in err and "sweep" not in err
    assert target.read_text() == "kept"


@pytest.mark.parametrize("table", ["results.csv", "stability.csv", "restitution.csv"])
def test_a_malformed_baseline_is_exit_2_and_one_line_and_an_api_error(run_dir, tmp_path, capsys, table):
    """The baseline directory is read as strictly as the results: by ``truestep gate
    --baseline`` (exit 2) and by ``truestep.compare`` (:class:`TableError`)."""
    import truestep
    from truestep.tables.io import TableError

    base = tmp_path / "baseline"
    base.mkdir()
    for name in ("results.csv", "stability.csv", "restitution.csv"):
        shutil.copy(run_dir / name, base / name)
    (base / table).write_text("case,engine,method\n1,2,3\n")
    code = main(["gate", "--results", str(run_dir / "results.csv"), "--baseline", str(base), "-q"])
    err = capsys.readouterr().err
    assert code == 2 and table in err and "Traceback" not in err
    assert len([line for line in err.splitlines() if line.strip()]) == 1
    with pytest.raises(TableError, match=table):
        truestep.compare(base, run_dir)
    with pytest.raises(TableError, match="not a directory"):
        truestep.compare(base / table, run_dir)


def _edit(path: Path, change) -> None:
    """Rewrite the CSV table at ``path`` through ``change(rows) -> rows``."""
    import csv
    import io

    rows = list(csv.reader(io.StringIO(path.read_text())))
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerows(change(rows))
    path.write_text(buf.getvalue())


def _first_ok(rows: list[list[str]]) -> int:
    k = rows[0].index("status")
    return next(i for i, r in enumerate(rows) if i and r[k] == "ok")


def _set(name: str, value: str):
    def change(rows):
        rows[_first_ok(rows)][rows[0].index(name)] = value
        return rows

    return change


def _blank_numbers(rows):
    for r in rows[1:]:
        for name in ("error", "energy_drift", "energy_drift_final", "nfev", "steps", "wall_s"):
            r[rows[0].index(name)] = ""
    return rows


DAMAGED = {
    "a repeated row": ("results.csv", lambda rows: [*rows, rows[_first_ok(rows)]], "same case"),
    "dt 0": ("results.csv", _set("dt", "0"), "positive and finite"),
    "dt < 0": ("results.csv", _set("dt", "-0.01"), "positive and finite"),
    "dt inf": ("results.csv", _set("dt", "inf"), "positive and finite"),
    "an error of 1e999": ("results.csv", _set("error", "1e999"), "not a value a run writes"),
    "a negative count": ("results.csv", _set("nfev", "-4"), "not a value a run writes"),
    "a wall time of 0": ("results.csv", _set("wall_s", "0"), "positive and finite"),
    "every number gone": ("results.csv", _blank_numbers, "nfev"),
    "a field of 30,000 characters": ("results.csv", _set("message", "x" * 30_000), "30000 characters"),
    "a column twice": ("results.csv", lambda rows: [[*r, r[6]] for r in rows], "twice"),
    "an empty engine": ("results.csv", _set("engine", ""), "empty"),
    "a repeated stability search": ("stability.csv", lambda rows: [*rows, rows[1]], "same case"),
    "a bounce of 1.5": ("restitution.csv", _set("bounce", "1.5"), "bounce"),
    "e_set 2": ("restitution.csv", _set("e_set", "2"), "e_set"),
}


@pytest.mark.parametrize("label", list(DAMAGED))
def test_tables_no_run_writes_are_refused_in_one_line(run_dir, tmp_path, capsys, label):
    import truestep
    from truestep.tables.io import TableError

    table, change, reason = DAMAGED[label]
    _edit(run_dir / table, change)
    code, err = _gate(run_dir, capsys)
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2 and len(lines) == 1 and reason in lines[0] and table in lines[0], err
    with pytest.raises(TableError, match=reason):
        truestep.compare(run_dir, REPORTS)


def test_an_all_nan_baseline_is_refused(run_dir, tmp_path, capsys):
    base = tmp_path / "base"
    shutil.copytree(run_dir, base)
    _edit(base / "results.csv", _blank_numbers)
    assert main(["gate", "--results", str(run_dir / "results.csv"), "--baseline", str(base), "-q"]) == 2
    assert "column nfev: empty in an ok row" in capsys.readouterr().err


def test_a_method_named_nan_is_a_name(run_dir, tmp_path, capsys):
    from truestep.tables.io import REQUIRED, read_table

    def rename(rows):
        e, m, c = (rows[0].index(k) for k in ("engine", "method", "case"))
        for r in rows[1:]:
            if (r[e], r[m], r[c]) == ("reference", "rk4", "free-fall"):
                r[m] = "nan"
        return rows

    _edit(run_dir / "results.csv", rename)
    table = read_table(run_dir / "results.csv", "results", set(REQUIRED["results"]))
    assert (table["method"] == "nan").sum() > 0 and table["method"].notna().all()
    dt = table.loc[(table["method"] == "nan") & (table["status"] == "ok"), "dt"].iloc[0]
    gates = tmp_path / "gates.toml"
    gates.write_text(
        f'[[gates]]\ncases = "free-fall"\nkind = "status"\nmethod = "nan"\n'
        f'dt = {float(dt)!r}\nexpect = "ok"\n'
    )
    code = main(
        [
            "gate",
            "--results",
            str(run_dir / "results.csv"),
            "--cases",
            "free-fall",
            "--gates",
            str(gates),
            "-v",
        ]
    )
    out = capsys.readouterr().out
    assert code == 0 and "ok   free-fall/status/reference/nan@" in out and "(gates[0]" in out, out


def test_a_table_cut_short_is_refused(tmp_path, capsys):
    """Issue 37, item 10: a results table cut off inside its last row (a full disk, a
    copy interrupted) was read and gated, exit 0; a table truestep writes ends with a
    newline, so one that does not was cut short: exit 2, one line."""
    from pathlib import Path

    from truestep.cli import main

    published = (Path(__file__).resolve().parents[2] / "reports" / "results.csv").read_bytes()
    half = len(published) // 2
    if published[half - 1 : half] == b"\n":  # cut inside a row, not at its end
        half -= 1
    cut = tmp_path / "results.csv"
    cut.write_bytes(published[:half])
    assert main(["gate", "--results", str(cut), "-q"]) == 2
    err = capsys.readouterr().err
    assert "truncated: its last line has no end" in err and "Traceback" not in err


def test_a_table_cut_at_the_end_of_a_row_is_refused_by_its_recorded_row_count(tmp_path, capsys):
    """A results table cut just after a newline reads as a table of fewer runs; the run
    records each table's row count in ``run.json``, so ``gate`` (on the run, and on it as
    a baseline) and :func:`truestep.compare` refuse it: exit 2, one line naming both
    counts. The run's own tables pass."""
    import truestep
    from truestep.tables.io import TableError

    out = tmp_path / "run"
    truestep.run(["free-fall", "bouncing-ball"], ["reference"], quick=True, out=out, progress=lambda _: None)
    assert main(["gate", "--results", str(out / "results.csv"), "-q"]) == 0
    whole = (out / "results.csv").read_bytes()
    rows = whole.count(b"\n") - 1
    cut = whole[: [k for k, b in enumerate(whole) if b == ord("\n")][rows // 2] + 1]
    (out / "results.csv").write_bytes(cut)
    capsys.readouterr()
    for argv in (
        ["--results", str(out / "results.csv")],
        ["--results", str(out / "results.csv"), "--baseline", str(out)],
    ):
        assert main(["gate", *argv, "-q"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and f"{rows // 2} rows, but the run that wrote it recorded {rows}" in err[0]
    with pytest.raises(TableError, match="cut short or changed since"):
        truestep.compare(out, out)


def test_a_table_without_an_engine_its_run_published_is_refused(tmp_path, capsys):
    """The run records the engines whose rows it published; a results table changed since
    (an engine's rows dropped, its row count recorded anew; or another engine's rows added)
    would compare none of that engine's rows as a baseline and say nothing. ``gate`` (on
    the run, and on it as a baseline) and :func:`truestep.compare` refuse it: exit 2, one
    line naming the engine."""
    import json

    import truestep
    from truestep.tables.io import TableError

    run = tmp_path / "run"
    truestep.run("free-fall", ["reference", "pymunk"], quick=True, out=run, progress=lambda _: None)
    base = tmp_path / "base"
    shutil.copytree(run, base)
    table = pd.read_csv(base / "results.csv", dtype=str, keep_default_na=False)
    kept = table[table["engine"] != "pymunk"]
    kept.to_csv(base / "results.csv", index=False)
    record = json.loads((base / "run.json").read_text())
    record["rows"]["results"] = len(kept)
    (base / "run.json").write_text(json.dumps(record))
    capsys.readouterr()
    for argv in (
        ["--results", str(base / "results.csv")],
        ["--results", str(run / "results.csv"), "--baseline", str(base)],
    ):
        assert main(["gate", *argv, "-q"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "no row of pymunk, which the run published" in err[0]
    with pytest.raises(TableError, match="no row of pymunk"):
        truestep.compare(base, run)
    record["engines"] = ["reference"]
    (base / "run.json").write_text(json.dumps(record))
    table.to_csv(base / "results.csv", index=False)
    record["rows"]["results"] = len(table)
    (base / "run.json").write_text(json.dumps(record))
    assert main(["gate", "--results", str(run / "results.csv"), "--baseline", str(base), "-q"]) == 2
    assert "rows of pymunk, which the run did not publish" in capsys.readouterr().err
