"""Adapter registry: engine name → adapter class, imported on first use.

Engines are imported lazily so that listing adapters or running one engine never pays for (or
fails on) another engine's import.
"""

from __future__ import annotations

import importlib

from adapters.base import Adapter

_REGISTRY = {
    "inhouse": "adapters.inhouse.adapter:InhouseAdapter",
    "mujoco": "adapters.mujoco_adapter:MujocoAdapter",
    "pybullet": "adapters.pybullet_adapter:PybulletAdapter",
    "pinocchio": "adapters.pinocchio_adapter:PinocchioAdapter",
    "exudyn": "adapters.exudyn_adapter:ExudynAdapter",
}


def adapter_names() -> list[str]:
    """Registered adapter names."""
    return list(_REGISTRY)


def get_adapter(name: str) -> Adapter:
    """An instance of adapter ``name``; an unknown name raises a ValueError listing valid ones."""
    if name not in _REGISTRY:
        raise ValueError(f"unknown adapter {name!r}; valid: {', '.join(_REGISTRY)}")
    module_name, _, class_name = _REGISTRY[name].partition(":")
    return getattr(importlib.import_module(module_name), class_name)()
