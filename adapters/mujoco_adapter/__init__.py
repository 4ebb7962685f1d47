"""MuJoCo adapter package: :class:`MujocoAdapter` (registered as ``mujoco``), :func:`export_mjcf`.

The neutral mechanism becomes an MJCF model built through ``mujoco.MjSpec``.  Modules:
:mod:`.build` (mechanism → ``MjSpec`` and ``MjModel``, closure costs, faithfulness switches),
:mod:`.loads` (applied loads, constant and pose-dependent), :mod:`.state` (harness body states ↔
``qpos``/``qvel``), :mod:`.methods` (method specs, parameter checks, the configured model),
:mod:`.stepping` (stepping with divergence detection), :mod:`.adapter` (the adapter and the run
loop).
"""

from mbh._adapters.mujoco_adapter.adapter import MujocoAdapter, export_mjcf
from mbh._adapters.mujoco_adapter.build import MujocoModel, build_model, closure_equations

__all__ = ["MujocoAdapter", "MujocoModel", "build_model", "closure_equations", "export_mjcf"]
