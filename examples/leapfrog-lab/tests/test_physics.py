"""leapfrog-lab's physics, checked by truestep: one test per gate of truestep-gates.toml."""

import pytest

# The engine by its class (works before `pip install`; once installed, "leapfrog" too),
# beside truestep's reference for the no-worse-than gates; the lecture's cases by name
# and this project's own case directory by path (relative to this file).
LECTURE_CASES = "free-fall,harmonic-oscillator,damped-oscillator,spring-damper-pair,bouncing-ball"


@pytest.mark.truestep(
    engines="leapfrog_lab.adapter:LeapfrogAdapter,reference",
    cases=f"{LECTURE_CASES},../leapfrog_lab/cases",
    gates="../truestep-gates.toml",
    quick=True,
    case_gates=False,
)
def test_physics(truestep_gate):
    truestep_gate.check()
