"""The one start every engine shares (docs/design.md, rule 3): the assembled, checked, consistent state
produced once by the harness's neutral kinematics (:mod:`mbh._harness.neutral.assembly`)."""

from __future__ import annotations

from mbh._harness.neutral.assembly import assemble
from mbh._harness.model.mechanism import Mechanism
from mbh._harness.model.trajectory import BodyStates

_CACHE: dict[str, BodyStates] = {}


def initial_state(mech: Mechanism) -> BodyStates:
    """World body states at t = 0 satisfying the constraints to machine precision.

    Cached per scenario content hash (a copy is returned each time); raises
    :class:`~mbh._harness.neutral.assembly.AssemblyError` when the mechanism cannot be started as asked
    (no convergence, a singular configuration, inconsistent velocities).
    """
    key = mech.content_hash or mech.name
    if key not in _CACHE:
        _CACHE[key] = assemble(mech).states
    state = _CACHE[key]
    return BodyStates(state.position.copy(), state.quaternion.copy(), state.velocity.copy(),
                      state.angular_velocity.copy())
