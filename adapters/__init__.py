"""Engines behind one Adapter protocol; the reference implementation is one of them."""

from __future__ import annotations

import importlib
import importlib.util

from truestep.adapters.base import Adapter, Trajectory

ADAPTERS: dict[str, str] = {
    "reference": "truestep.adapters.reference:ReferenceAdapter",
    "scipy": "truestep.adapters.scipy_ivp:ScipyAdapter",
    "pymunk": "truestep.adapters.pymunk_adapter:PymunkAdapter",
    "pybullet": "truestep.adapters.pybullet_adapter:PybulletAdapter",
    "mujoco": "truestep.adapters.mujoco_adapter:MujocoAdapter",
}
"""Engine name -> ``module:class``; an engine's module is imported only when asked for."""


def get_adapter(name: str) -> Adapter:
    """Instantiate the adapter registered as ``name``."""
    try:
        target = ADAPTERS[name]
    except KeyError:
        raise KeyError(f"unknown engine {name!r}; known: {', '.join(ADAPTERS)}") from None
    module, cls = target.split(":")
    return getattr(importlib.import_module(module), cls)()


def available_engines() -> list[str]:
    """Engines whose adapter module exists in this checkout."""
    return [n for n, t in ADAPTERS.items() if importlib.util.find_spec(t.split(":")[0]) is not None]


__all__ = ["ADAPTERS", "Adapter", "Trajectory", "available_engines", "get_adapter"]
