"""The one start every engine shares (DESIGN.md rule 3): the assembled, consistent state produced
once by the in-house kinematics."""

from __future__ import annotations

from adapters.inhouse.constraints import layout_of
from adapters.inhouse.kinematics import assemble
from adapters.inhouse.states import body_states
from harness.model import Mechanism
from harness.trajectory import BodyStates

_CACHE: dict[str, BodyStates] = {}


def initial_state(mech: Mechanism) -> BodyStates:
    """World body states at t = 0 satisfying the constraints to machine precision.

    Cached per scenario content hash; raises :class:`~adapters.inhouse.kinematics.AssemblyError`
    when the mechanism cannot be assembled.
    """
    key = mech.content_hash or mech.name
    if key not in _CACHE:
        assembly = assemble(mech)
        _CACHE[key] = body_states(layout_of(mech), assembly.q, assembly.v)
    state = _CACHE[key]
    return BodyStates(state.position.copy(), state.quaternion.copy(), state.velocity.copy(),
                      state.angular_velocity.copy())
