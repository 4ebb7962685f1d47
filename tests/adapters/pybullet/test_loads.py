"""The loads applied before every Bullet step read the body poses straight from Bullet's link
states (the per-step path, adapters/pybullet_adapter/state.py `_link_poses`); they must be the
wrenches the full state read-back gives, on scenes with springs, body loads and cut-joint
actuation, after a few hundred and a few thousand steps of motion (at the start a spring at its
free length pulls with round-off only, whose sign either path may flip)."""

from __future__ import annotations

import numpy as np
import pybullet
import pytest

from mbh._adapters.pybullet_adapter import PybulletAdapter, bullet_world
from mbh._adapters.pybullet_adapter.loads import _body_wrenches
from mbh._adapters.pybullet_adapter.state import _link_poses, _read_states
from mbh._harness.model.scenario import load

#: Two computation paths of the same rotations (a matrix from Bullet's quaternion, or that
#: quaternion turned into the body's and back): measured equal to the bit on both scenes; the
#: bound allows any CPU's round-off relative to the largest wrench entry.
RELATIVE_BOUND = 1e-12


@pytest.mark.parametrize("scenario", ["stiff_fourbar", "andrews"])
def test_the_per_step_loads_equal_those_of_the_full_read_back(scenario):
    adapter = PybulletAdapter()
    model = adapter.build(load(scenario))
    with bullet_world(model, None, 1e-4) as world:
        for count in (300, 3000):
            for _ in range(count):
                pybullet.stepSimulation(physicsClientId=world.client)
            poses = _link_poses(model, world.body, world.client)
            assert poses is not None
            fast = _body_wrenches(model, poses)
            full = _body_wrenches(model, _read_states(model, world.body, world.client))
            assert np.abs(fast).max() > 0
            assert np.abs(fast - full).max() <= RELATIVE_BOUND * np.abs(full).max()
