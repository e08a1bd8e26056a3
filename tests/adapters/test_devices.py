"""A device is a choice of the run (``truestep run --device``): parsed and checked against the
run's engines and the machine before anything runs, carried to every process of the run,
recorded in ``run.json`` and the journal; where the machine has no GPU, asking for one is
one line and exit 2, and nothing is written."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pandas as pd
import pytest

from truestep.adapters import devices
from truestep.adapters.devices import DeviceChoice, DeviceError, parse, resolve
from truestep.cases import load_cases
from truestep.execution.journal import Journal, JournalError, fingerprint


class OnCpu:
    """An adapter class whose constructor takes no device."""


class OnDevice:
    """An adapter class whose constructor takes a device (as Warp's engines' do)."""

    def __init__(self, *, device: str | None = None) -> None:
        self.device = device


class OnDeviceByName(OnDevice):
    """An adapter class that moves off the CPU only when named (as the reference does)."""

    device_named_only = True


CLASSES = {"reference": OnCpu, "mujoco": OnCpu, "newton": OnDevice, "mujoco-warp": OnDevice}


@pytest.mark.parametrize(
    ("text", "every", "engines"),
    [
        (None, None, {}),
        ("", None, {}),
        ("cuda:0", "cuda:0", {}),
        ("cuda", "cuda", {}),
        ("cpu", "cpu", {}),
        ("newton=cuda:1", None, {"newton": "cuda:1"}),
        ("cuda:0, mujoco-warp=cpu", "cuda:0", {"mujoco-warp": "cpu"}),
        ({"newton": "cuda:0"}, None, {"newton": "cuda:0"}),
    ],
)
def test_the_forms_a_device_choice_takes(text, every, engines):
    assert parse(text) == DeviceChoice(every, engines)


@pytest.mark.parametrize(
    ("text", "said"),
    [
        ("gpu", "'gpu' is not a device"),
        ("cuda:x", "is not a device"),
        ("newton=tpu", "'tpu' is not a device"),
        ("cuda:0,cuda:1", "two devices for every engine"),
        ("newton=cuda:0,newton=cpu", "two devices for engine 'newton'"),
        ("=cuda:0", "without its engine"),
    ],
)
def test_a_form_it_does_not_know_is_refused(text, said):
    with pytest.raises(DeviceError, match=said):
        parse(text)


def test_every_engine_that_takes_a_device_gets_it_and_a_named_one_wins():
    engines = ["reference", "newton", "mujoco-warp"]
    assert resolve(parse("cuda:0"), engines, CLASSES, gpus=1) == {"newton": "cuda:0", "mujoco-warp": "cuda:0"}
    assert resolve(parse("cuda:0,mujoco-warp=cpu"), engines, CLASSES, gpus=1) == {"newton": "cuda:0"}
    assert resolve(parse("newton=cuda:1"), engines, CLASSES, gpus=2) == {"newton": "cuda:1"}


def test_the_reference_moves_to_a_gpu_only_when_named():
    """``--device cuda:0`` moves the GPU engines and leaves the reference on the CPU (on a GPU
    it models fewer scenes); ``reference=cuda:0`` moves it; a run of the reference alone
    cannot take a device for every engine."""
    from truestep.adapters.reference import ReferenceAdapter

    assert devices.takes_device(ReferenceAdapter) and devices.named_only(ReferenceAdapter)
    classes = {**CLASSES, "reference": OnDeviceByName}
    engines = ["reference", "newton"]
    assert resolve(parse("cuda:0"), engines, classes, gpus=1) == {"newton": "cuda:0"}
    assert resolve(parse("reference=cuda:0"), engines, classes, gpus=1) == {"reference": "cuda:0"}
    both = {"reference": "cuda:0", "newton": "cuda:0"}
    assert resolve(parse("cuda:0,reference=cuda:0"), engines, classes, gpus=1) == both
    with pytest.raises(DeviceError, match=r"none of the run's engines .* the reference when named"):
        resolve(parse("cuda:0"), ["reference"], classes, gpus=1)


def test_the_reference_made_for_a_gpu_marks_its_process_and_compiles_nothing_before_the_fork(monkeypatch):
    """``ReferenceAdapter(device="cuda:0")`` says its process wants a GPU (no Warp engine
    then starts Warp before the runs are forked), offers its device methods, and its
    ``prepare`` compiles no CPU loop; made for the CPU, it marks nothing."""
    pytest.importorskip("warp")
    from truestep.adapters import reference, warp_runtime
    from truestep.adapters.reference import DEVICE_METHODS, ReferenceAdapter

    monkeypatch.setattr(warp_runtime, "_GPU_WANTED", [])
    ReferenceAdapter()
    assert not warp_runtime.wants_gpu()
    monkeypatch.setattr(reference, "prepared", lambda *a, **k: pytest.fail("a CPU loop compiled on a GPU"))
    on_gpu = ReferenceAdapter(device="cuda:0")
    assert warp_runtime.wants_gpu() and on_gpu.methods == DEVICE_METHODS and on_gpu.adaptive_methods == ()
    on_gpu.prepare(load_cases("bouncing-ball")[0], "lecture")


def test_the_cpu_or_nothing_asked_needs_no_gpu_and_resolves_to_nothing(monkeypatch):
    monkeypatch.setattr(devices, "cuda_devices", lambda python=None: pytest.fail("no GPU is asked"))
    for text in (None, "cpu", "newton=cpu"):
        assert resolve(parse(text), ["reference", "newton"], CLASSES) == {}


@pytest.mark.parametrize(
    ("text", "engines", "gpus", "said"),
    [
        ("newton=cuda:0", ["reference", "mujoco"], 1, "'newton' is not one of the run's engines"),
        ("mujoco=cuda:0", ["reference", "mujoco"], 1, "mujoco computes on the CPU only"),
        ("cuda:0", ["reference", "mujoco"], 1, "none of the run's engines .* takes a device"),
        ("cuda:0", ["reference", "newton"], 0, "newton=cuda:0: this machine has no CUDA device"),
        ("newton=cuda:1", ["newton"], 1, r"has 1 CUDA device\(s\), cuda:0 to cuda:0"),
    ],
)
def test_what_cannot_run_here_is_one_line(text, engines, gpus, said):
    with pytest.raises(DeviceError, match=said) as err:
        resolve(parse(text), engines, CLASSES, gpus=gpus)
    assert "\n" not in str(err.value)


def test_the_gpus_are_counted_in_a_fresh_interpreter_and_a_failed_count_is_none(tmp_path):
    """The count is the last line a fresh interpreter prints; one that fails, prints no
    number, or cannot start counts no GPU (here a stand-in for Python answers)."""

    def fake(body: str) -> str:
        path = tmp_path / f"python{len(list(tmp_path.iterdir()))}"
        path.write_text(f"#!/bin/sh\n{body}\n")
        path.chmod(0o755)
        return str(path)

    assert devices.cuda_devices(fake("echo greeting; echo 2")) == 2
    assert devices.cuda_devices(fake("echo 2; exit 1")) == 0
    assert devices.cuda_devices(fake("echo none")) == 0
    assert devices.cuda_devices(str(tmp_path / "absent")) == 0


def test_the_devices_travel_in_the_environment_and_are_put_back(monkeypatch):
    monkeypatch.setenv(devices.ENV, "newton=cuda:3")
    with devices.used({"newton": "cuda:0", "mujoco-warp": "cuda:1"}):
        assert os.environ[devices.ENV] == "mujoco-warp=cuda:1,newton=cuda:0"
        assert devices.chosen("newton") == "cuda:0" and devices.chosen("reference") is None
        assert devices.in_use() == {"newton": "cuda:0", "mujoco-warp": "cuda:1"}
    assert os.environ[devices.ENV] == "newton=cuda:3"
    with devices.used({}):
        assert devices.ENV not in os.environ and devices.in_use() == {}
    monkeypatch.delenv(devices.ENV)
    with devices.used({"newton": "cuda:0"}):
        pass
    assert devices.ENV not in os.environ


def test_warp_s_engines_take_the_run_s_device_and_a_subclass_s_own_wins():
    """In a fresh interpreter (an adapter made for a GPU marks its process): the device the
    environment carries, per engine; the CPU without one; a device given to the
    constructor (a user's subclass) over the run's."""
    pytest.importorskip("newton")
    pytest.importorskip("mujoco_warp")
    code = textwrap.dedent("""
        from truestep.adapters import get_adapter
        from truestep.adapters.newton_adapter import NewtonAdapter
        from truestep.adapters import warp_runtime as wr
        print(get_adapter("newton").device, get_adapter("mujoco-warp").device)
        print(NewtonAdapter(device="cuda:2").device, wr.wants_gpu())
    """)
    env = {**os.environ, devices.ENV: "newton=cuda:0"}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, env=env)
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.split() == ["cuda:0", "cpu", "cuda:2", "True"]


def test_a_resumed_run_must_have_the_same_devices(tmp_path):
    """A run on the CPU alone keeps the fingerprint it had before ``--device`` was (no
    entry); a resume with other devices is refused, saying so."""
    cases = load_cases("free-fall")
    plain = fingerprint(cases, ["reference"], quick=True)
    assert "devices" not in plain and fingerprint(cases, ["reference"], True, {}) == plain
    journal = Journal(tmp_path / "rep")
    journal.start(fingerprint(cases, ["reference", "newton"], True, {"newton": "cuda:0"}))
    with pytest.raises(JournalError, match=r"other devices \(--device\)"):
        Journal(tmp_path / "rep").resume(fingerprint(cases, ["reference", "newton"], quick=True))
    assert (
        Journal(tmp_path / "rep").resume(
            fingerprint(cases, ["reference", "newton"], True, {"newton": "cuda:0"})
        )
        == 0
    )


def _truestep(*args: str, cwd) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "truestep", *args], capture_output=True, text=True, timeout=300, cwd=cwd
    )


@pytest.mark.parametrize(
    ("device", "engines", "said"),
    [
        ("gpu", "reference", "--device: 'gpu' is not a device"),
        ("cuda:0", "reference", "--device: cuda:0: none of the run's engines (reference) takes a device"),
        ("cuda:99", "reference,newton", "--device: newton=cuda:99: this machine has "),
    ],
)
def test_a_device_that_cannot_run_here_exits_2_with_one_line_and_writes_nothing(
    tmp_path, device, engines, said
):
    """``cuda:99``: more GPUs than any machine here has, so the answer is the same with a
    GPU or without one."""
    if "newton" in engines:
        pytest.importorskip("newton")
    done = _truestep(
        "run",
        "--quick",
        "--cases",
        "free-fall",
        "--engines",
        engines,
        "--device",
        device,
        "--out",
        "rep",
        cwd=tmp_path,
    )
    assert done.returncode == 2, done.stderr[-2000:]
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"truestep: error: {said}")
    assert "Traceback" not in done.stderr and not (tmp_path / "rep").exists()


def test_a_run_records_its_devices_and_its_rows_carry_what_happened_there(tmp_path, monkeypatch):
    """Newton put on ``cuda:0`` of a machine said to have one GPU: on a machine without it,
    its rows are ``crashed`` rows that say why (nothing disappears), the reference's are
    ok, and ``run.json`` and the reproducing command name the device."""
    pytest.importorskip("newton")
    from truestep import api
    from truestep.adapters import warp_runtime

    monkeypatch.setattr(devices, "cuda_devices", lambda python=None: 1)
    monkeypatch.setattr(warp_runtime, "_GPU_WANTED", [])  # this test's GPU adapter marks no other test
    real = os.environ.get(devices.ENV)
    tables = api.run(
        "harmonic-oscillator",
        ["reference", "newton"],
        quick=True,
        analyses=False,
        out=tmp_path / "rep",
        progress=lambda _: None,
        argv=["run", "--device", "newton=cuda:0"],
        device="newton=cuda:0",
    )
    assert os.environ.get(devices.ENV) == real
    record = json.loads((tmp_path / "rep" / "run.json").read_text())
    assert record["devices"] == {"newton": "cuda:0"} and "--device newton=cuda:0" in record["command"]
    page = (tmp_path / "rep" / "index.md").read_text()
    assert "Devices: newton on cuda:0, every other engine on the CPU" in page
    rows = tables.results
    newton, reference = rows[rows.engine == "newton"], rows[rows.engine == "reference"]
    assert len(newton) and len(reference) and set(reference.status) == {"ok"}
    assert set(newton.device) == {"cuda:0"} and set(reference.device) == {"cpu"}
    if devices.cuda_devices() == 0:
        assert set(newton.status) == {"crashed"}
        assert newton.message.str.contains("cuda:0").all()


def test_the_reference_named_onto_a_gpu_runs_its_particle_scenes_there_and_says_what_it_does_not(
    tmp_path, monkeypatch
):
    """``--device reference=cuda:0`` on a machine said to have one GPU: the reference runs
    its two device methods there (without a GPU, ``crashed`` rows naming the device), and a
    scene its device kernel does not model is ``unsupported``, saying so."""
    pytest.importorskip("warp")
    from truestep import api
    from truestep.adapters import warp_runtime
    from truestep.adapters.reference import DEVICE_METHODS

    monkeypatch.setattr(devices, "cuda_devices", lambda python=None: 1)
    monkeypatch.setattr(warp_runtime, "_GPU_WANTED", [])  # this test's GPU adapter marks no other test
    tables = api.run(
        ["bouncing-ball", "hanging-cloth"],
        ["reference"],
        quick=True,
        analyses=False,
        progress=lambda _: None,
        device="reference=cuda:0",
    )
    rows = tables.results
    assert set(rows.method) == set(DEVICE_METHODS)
    ball, cloth = rows[rows.case == "bouncing-ball"], rows[rows.case == "hanging-cloth"]
    assert set(ball.device) == {"cuda:0"} and len(ball) == 2 * len(load_cases("bouncing-ball")[0].quick_dts)
    assert set(cloth.status) == {"unsupported"}
    assert cloth.message.str.contains("on a GPU the reference steps independent particles only").all()
    if devices.cuda_devices() == 0:
        assert set(ball.status) == {"crashed"} and ball.message.str.contains("cuda:0").all()


def test_every_table_says_where_each_row_computed(tmp_path):
    """A run on the CPU: ``cpu`` on every row that ran, in each of the three tables, and
    nothing on rows that did not (an engine that lacks a feature, an adaptive method's
    search)."""
    from truestep import api

    tables = api.run(
        ["bouncing-ball", "harmonic-oscillator"], ["reference", "pymunk"], quick=True, progress=lambda _: None
    )
    for name, table in (
        ("results", tables.results),
        ("stability", tables.stability),
        ("restitution", tables.restitution),
    ):
        ran = ~table.status.isin(["unsupported", "skipped"])
        assert ran.any(), name
        assert set(table.device[ran]) == {"cpu"}, name
        assert table.device[~ran].isna().all(), name


def test_the_published_report_says_every_row_computed_on_the_cpu():
    """The committed report was made without ``--device``: ``run.json`` names no device,
    its footer says every engine computed on the CPU, and each table's ``device`` is
    ``cpu`` on every row that ran and empty on every row that did not."""
    import pandas as pd

    reports = Path(__file__).resolve().parents[2] / "reports"
    assert "devices" not in json.loads((reports / "run.json").read_text())
    assert "Devices: every engine on the CPU" in (reports / "index.md").read_text()
    for name in ("results", "stability", "restitution"):
        table = pd.read_csv(reports / f"{name}.csv")
        ran = ~table.status.isin(["unsupported", "skipped"])
        assert ran.any() and set(table.device[ran]) == {"cpu"}, name
        assert table.device[~ran].isna().all(), name


def test_a_remote_cluster_is_refused_with_a_device(monkeypatch, tmp_path):
    """A cluster's workers make their adapters where they run, which this run's devices
    do not reach: a GPU device with a remote scheduler is refused before anything runs."""
    pytest.importorskip("newton")
    from truestep import api

    monkeypatch.setattr(devices, "cuda_devices", lambda python=None: 1)
    with pytest.raises(DeviceError, match="newton=cuda:0 with --scheduler tcp://"):
        api.run(
            "harmonic-oscillator",
            ["reference", "newton"],
            quick=True,
            out=tmp_path / "rep",
            scheduler="tcp://127.0.0.1:1",
            device="newton=cuda:0",
            progress=lambda _: None,
        )
    assert not (tmp_path / "rep").exists()


def test_the_scaling_table_names_each_row_s_device_and_a_gpu_that_is_not_here_is_rows(tmp_path, monkeypatch):
    """``truestep bench --device``: Newton put on ``cuda:0`` of a machine said to have one
    GPU; without it its rows are ``crashed`` rows that say why, and every row that ran
    names its device (the reference's ``cpu``); rows that did not run name none."""
    pytest.importorskip("newton")
    from truestep import api
    from truestep.adapters import warp_runtime

    monkeypatch.setattr(devices, "cuda_devices", lambda python=None: 1)
    monkeypatch.setattr(warp_runtime, "_GPU_WANTED", [])  # this test's GPU adapter marks no other test
    real = os.environ.get(devices.ENV)
    table = api.bench(
        ["reference", "newton"], sizes=[10], budget_s=120.0, out=tmp_path / "b", device="newton=cuda:0"
    )
    assert os.environ.get(devices.ENV) == real
    ran = ~table.status.isin(["skipped", "unsupported"])
    newton, reference = table[ran & (table.engine == "newton")], table[ran & (table.engine == "reference")]
    assert len(newton) and len(reference)
    assert set(newton.device) == {"cuda:0"} and set(reference.device) == {"cpu"}
    assert set(table.device[~ran]) <= {""}
    if devices.cuda_devices() == 0:
        assert set(newton.status) == {"crashed"} and newton.note.str.contains("cuda:0").all()
    written = pd.read_csv(tmp_path / "b" / "scaling.csv", keep_default_na=False)
    assert list(written.device) == list(table.device)


@pytest.mark.parametrize(
    ("device", "engines", "said"),
    [
        ("pymunk=cuda:0", "pymunk", "--device: pymunk=cuda:0: pymunk computes on the CPU only"),
        ("cuda:99", "reference,newton", "--device: newton=cuda:99: this machine has "),
    ],
)
def test_bench_refuses_a_device_it_cannot_use_in_one_line_and_writes_nothing(tmp_path, device, engines, said):
    if "newton" in engines:
        pytest.importorskip("newton")
    done = _truestep(
        "bench", "--engines", engines, "--sizes", "10", "--device", device, "--out", "b", cwd=tmp_path
    )
    assert done.returncode == 2, done.stderr[-2000:]
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"truestep: error: {said}")
    assert not (tmp_path / "b").exists()
