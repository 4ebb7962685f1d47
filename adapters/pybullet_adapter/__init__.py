"""PyBullet adapter package: :class:`PybulletAdapter` (registered as ``pybullet``), a Featherstone
multibody (``createMultiBody``) in DIRECT mode.

Modules: :mod:`.quiet` (PyBullet imported with its console output silenced), :mod:`.build`
(mechanism → Bullet link layout, :class:`PybulletModel`), :mod:`.state` (body states ↔ Bullet joint
coordinates), :mod:`.world` (a live, faithful Bullet world: :func:`bullet_world`), :mod:`.loads`
(the loads re-applied before every step), :mod:`.adapter` (methods and the stepping loop).
"""

from mbh._adapters.pybullet_adapter.adapter import PybulletAdapter
from mbh._adapters.pybullet_adapter.build import PybulletModel, build_model, closure_equations
from mbh._adapters.pybullet_adapter.world import BulletWorld, bullet_world

__all__ = ["BulletWorld", "PybulletAdapter", "PybulletModel", "build_model", "bullet_world",
           "closure_equations"]
