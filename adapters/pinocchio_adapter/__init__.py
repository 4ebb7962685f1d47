"""Pinocchio adapter package: :class:`PinocchioAdapter` (registered as ``pinocchio``).

Modules: :mod:`.build` (mechanism → ``pin.Model`` + loop constraints), :mod:`.state` (body states ↔
joint coordinates), :mod:`.dynamics` (the constrained equations of motion as an integrator
problem), :mod:`.adapter` (methods and the stepping loop).
"""

from mbh._adapters.pinocchio_adapter.adapter import PinocchioAdapter

__all__ = ["PinocchioAdapter"]
