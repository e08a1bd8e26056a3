"""Case files that raise their own limits, and scenes written to allocate the machine."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from hostile_attacks.common import (
    CASE,
    PEAK_LIMIT_MIB,
    Campaign,
    case_file,
    refused,
)


def listed(c: Campaign, where: Path, path: Path) -> tuple[bool, str]:
    """``truestep list --cases FILE``: held when refused cleanly, within 20 s and
    :data:`PEAK_LIMIT_MIB` (loading never builds or runs what the case asks for)."""
    result = c.truestep(["list", "--cases", str(path)], where, memory_gb=8, peak=True)
    small = result.seconds < 20 and result.peak_mib < PEAK_LIMIT_MIB
    return result.clean_refusal and small, result.why()


def _limit_attack(key: str, value: str) -> Callable[[Campaign, Path], tuple[bool, str]]:
    def attack(c: Campaign, where: Path) -> tuple[bool, str]:
        return listed(c, where, case_file(where, extra=f"[limits]\n{key} = {value}\n"))

    attack.__name__ = f"attack_limits_{key}_raised_to_{value}"
    attack.__doc__ = f"A case file's ``[limits] {key} = {value}``."
    return attack


def attack_emitter_frame_dt_1e_300(c: Campaign, where: Path) -> tuple[bool, str]:
    """An emitter with ``frame_dt = 1e-300``."""
    body = CASE.format(duration="1.0", dt="[0.01]", extra="") + (
        '[[scene.emitters]]\nshape = "cube"\ncenter = [0.0, 0.0, 0.0]\nsize = 0.1\nrate_n = 1.0\n'
        "speed = 1.0\nlifetime = 2\ncapacity = 4\nframe_dt = 1e-300\n"
    )
    return listed(c, where, case_file(where, body=body))


def attack_time_step_1e_300(c: Campaign, where: Path) -> tuple[bool, str]:
    """A run of ``duration = 1e-296`` at ``dt = 1e-300`` (1e4 steps of nothing)."""
    return listed(c, where, case_file(where, duration="1e-296", dt="[1e-300]"))


def attack_stability_bracket_1e_300(c: Campaign, where: Path) -> tuple[bool, str]:
    """A stability search from ``dt_lo = 1e-300`` over ``horizon = 1e-296``."""
    extra = "[stability]\nhorizon = 1e-296\ndt_lo = 1e-300\ndt_hi = 1e-298\n"
    return listed(c, where, case_file(where, extra=extra))


def attack_linear_exact_of_20000_particles(c: Campaign, where: Path) -> tuple[bool, str]:
    """A 20,000-particle block measured against the dense ``linear`` exact solution."""
    body = """kind = "particles"
[scene]
[[scene.blocks]]
count = 20000
low = [0.0, 0.0, 0.0]
high = [1.0, 1.0, 1.0]
mass = 1.0
[run]
duration = 1.0
dt = [0.01]
[reference]
exact = "linear"
"""
    return listed(c, where, case_file(where, body=body))


SCENE_API = """import resource
from truestep.cases.fields import Fields
from truestep.cases.scene import read_scene
from truestep.cases.errors import CaseError
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
scene = {scene}
listed = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
try:
    read_scene(Fields('api', scene, 'scene'))
except CaseError as e:
    print('CLEAN', e)
print('GREW', (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - listed) / 1024)
"""


def scene_api(c: Campaign, where: Path, scene: str) -> tuple[bool, str]:
    """The scene reader (the form the API and ``truestep bench`` use) on a scene built in
    Python: held when refused with a CaseError and the memory grew by under 256 MiB
    beyond the lists themselves (no array was built)."""
    result = c.python(SCENE_API.format(scene=scene), where, timeout=180, memory_gb=6)
    grew = next((float(x.split()[1]) for x in result.out.splitlines() if x.startswith("GREW")), float("inf"))
    return "CLEAN" in result.out and grew < 256, f"grew {grew:.0f} MiB; {result.why()}"


def attack_explicit_list_of_1e8_particles_api(c: Campaign, where: Path) -> tuple[bool, str]:
    """An explicit list of 1e8 positions through the scene reader."""
    return scene_api(c, where, "{'particles': [{'position': [[0.0, 0.0, 0.0]] * 10**8, 'mass': 1.0}]}")


def attack_explicit_list_of_1e8_springs_api(c: Campaign, where: Path) -> tuple[bool, str]:
    """An explicit list of 1e8 spring pairs through the scene reader."""
    return scene_api(
        c,
        where,
        "{'particles': [{'position': [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]], "
        "'mass': 1.0}], 'springs': [{'pairs': [[0, 1]] * 10**8, "
        "'stiffness': 1.0}]}",
    )


def attack_command_line_limit_without_trust(c: Campaign, where: Path) -> tuple[bool, str]:
    """``truestep run --limit steps=1e12`` without saying the inputs are trusted."""
    return refused(c.quick_run(where, "rep", "--limit", "steps=1e12", cases="free-fall"))


ATTACKS = [
    *(
        _limit_attack(k, v)
        for k, v in (
            ("particles", "1000000000000"),
            ("springs", "1000000000000"),
            ("steps", "1000000000000"),
            ("records", "1000000000000"),
            ("work", "1e300"),
            ("memory_mb", "1e300"),
            ("timeout_s", "1e300"),
        )
    ),
    attack_emitter_frame_dt_1e_300,
    attack_time_step_1e_300,
    attack_stability_bracket_1e_300,
    attack_linear_exact_of_20000_particles,
    attack_explicit_list_of_1e8_particles_api,
    attack_explicit_list_of_1e8_springs_api,
    attack_command_line_limit_without_trust,
]
