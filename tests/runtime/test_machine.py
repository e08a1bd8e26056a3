"""The machine a run's timings were measured on (:mod:`truestep.runtime.machine`): named in
``run.json`` and the report's footer, apart from the floating-point record that decides
the non-timing numbers."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

import pytest

from truestep.runtime import machine

INTEL = """processor\t: 0
vendor_id\t: GenuineIntel
model name\t: Intel(R) Xeon(R)   Processor @ 2.10GHz
flags\t\t: fpu avx2 fma

processor\t: 1
model name\t: Intel(R) Xeon(R)   Processor @ 2.10GHz
"""
OLD_ARM = """processor\t: 0
BogoMIPS\t: 38.40
Features\t: fp asimd

Hardware\t: BCM2835
"""


@pytest.mark.parametrize(
    ("text", "name"),
    [
        (INTEL, "Intel(R) Xeon(R) Processor @ 2.10GHz"),
        (OLD_ARM, "BCM2835"),
        ("processor\t: 0\nprocessor\t: 1\n", "unknown"),  # an index is no name
        ("", "unknown"),
    ],
    ids=["x86-64", "older-arm", "indices-only", "empty"],
)
def test_the_cpu_is_named_as_the_system_names_it(text, name):
    assert machine.cpu_model(text) == name


@pytest.mark.skipif(not sys.platform.startswith("linux") or not shutil.which("lscpu"), reason="needs lscpu")
def test_the_cpu_named_is_the_one_lscpu_names():
    """Another route to the same name: util-linux's ``lscpu``."""
    out = subprocess.run(["lscpu"], capture_output=True, text=True, env={"LC_ALL": "C"}, check=True).stdout
    named = [
        " ".join(line.split(":", 1)[1].split()) for line in out.splitlines() if line.startswith("Model name:")
    ]
    assert named and machine.cpu_model() == named[0]


def test_a_run_records_its_machine_apart_from_its_numerics(tmp_path):
    """``run.json``'s ``machine`` is this machine, and the footer names it; ``numerics``
    (what decides the non-timing numbers) holds no CPU name, so two CPUs that compute
    alike stay comparable bit for bit."""
    from truestep import api

    out = tmp_path / "rep"
    api.run(
        "harmonic-oscillator", ["reference"], quick=True, analyses=False, out=out, progress=lambda _: None
    )
    record = json.loads((out / "run.json").read_text())
    assert record["machine"] == machine.describe()
    assert record["machine"]["cores"] == machine.usable_cores() >= 1
    assert machine.cpu_model() not in json.dumps(record["numerics"])
    footer = f"Machine (what the timings depend on): {machine.line()}, Python "
    assert footer in (out / "index.md").read_text()


def test_the_gate_and_the_history_call_the_same_machines_alike():
    """One rule decides "another machine" for ``gate --time-against``'s note and for
    ``history show``'s mark: the CPU, architecture and cores; a kernel update is the same
    machine, and a run that recorded none (an earlier release's) is not called another."""
    from truestep.ci.history import Point, machine_changes

    amd = {"cpu": "AMD EPYC", "architecture": "x86_64", "cores": 2, "system": "Linux 6.1"}
    kernel = {**amd, "system": "Linux 6.18"}
    four = {**amd, "cores": 4}
    intel = {**amd, "cpu": "Intel(R) Xeon(R) Processor"}
    assert machine.timed_alike(amd, kernel) and machine.timed_alike(amd, None)
    assert not machine.timed_alike(amd, four) and not machine.timed_alike(amd, intel)
    points = [
        Point(f"r{k}", False, 1.0, "ok", m) for k, m in enumerate([amd, kernel, None, intel, intel, four])
    ]
    assert machine_changes(points) == {3: machine.line(intel), 5: machine.line(four)}
