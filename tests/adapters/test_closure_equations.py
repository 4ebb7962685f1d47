"""The joint-coordinate engines' one closure contract (:data:`mbh._adapters.base.UNCLOSABLE`):
``closure_equations(mech, joint) -> int`` in each builder, with the numbers each engine closes
a cut joint with."""

from __future__ import annotations

import inspect
from types import SimpleNamespace

import pytest

from mbh._adapters.base import UNCLOSABLE
from mbh._harness.model.mechanism import JOINT_TYPES

#: (planar, joint type) → equations, per engine; every other pair is UNCLOSABLE.
CLOSABLE = {
    "mujoco": {(True, "revolute"): 3, (False, "revolute"): 6, (True, "spherical"): 3,
               (False, "spherical"): 3},
    "pinocchio": {(True, "revolute"): 3, (False, "revolute"): 6, (True, "spherical"): 3,
                  (False, "spherical"): 3},
    "pybullet": {(True, "revolute"): 3, (True, "spherical"): 3, (False, "spherical"): 3},
}


@pytest.mark.parametrize("engine", sorted(CLOSABLE))
def test_closure_equations_contract(engine):
    build = pytest.importorskip(f"mbh._adapters.{engine}_adapter.build")
    assert list(inspect.signature(build.closure_equations).parameters) == ["mech", "joint"]
    for planar in (True, False):
        for kind in JOINT_TYPES:
            got = build.closure_equations(SimpleNamespace(planar=planar),
                                          SimpleNamespace(type=kind, name="J"))
            assert got == CLOSABLE[engine].get((planar, kind), UNCLOSABLE), (planar, kind)
