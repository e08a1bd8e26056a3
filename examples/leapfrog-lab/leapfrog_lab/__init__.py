"""leapfrog-lab: a small particle engine (drift-kick-drift leapfrog) and its truestep adapter."""

from leapfrog_lab.world import World

__all__ = ["World"]
