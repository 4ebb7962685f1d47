"""How many of a Bullet model's loop-closure equations are redundant, counted by the engine's
own kinematics: the closure Jacobian at the start, each cut's rows (a point-to-point constraint,
3) the difference of ``pybullet.calculateJacobian``'s linear part at its two pivots, counted by
:func:`mbh._adapters.closure_notes.redundancy_notes` with the cut :data:`RANK_RTOL`.  (An
R-S-R-R four-bar closed at its spherical joint: 3 rows on a 3-coordinate tree of mobility 1, one
redundant by the mechanism and none by the closure model.)
"""

from __future__ import annotations

import numpy as np

from mbh._adapters import closure_notes
from mbh._adapters.pybullet_adapter.build import PybulletModel
from mbh._adapters.pybullet_adapter.quiet import pybullet
from mbh._adapters.pybullet_adapter.world import BulletWorld, pivot

#: Singular values of the closure Jacobian below this fraction of the largest count as zero
#: (measured at the start: the R-S-R-R four-bar's are 3.05, 1.53 and 0 to round-off; the seed
#: four-bar's, closed by a 3-D point, the same).
RANK_RTOL = 1e-9


class NotCounted(Exception):
    """Bullet's kinematics cannot give the closure Jacobian of this model (the reason)."""


def closure_jacobian(model: PybulletModel, world: BulletWorld) -> np.ndarray:
    """∂(pivot₁ − pivot₂)/∂(joint positions) of every cut at the world's present state, shape
    (3 · cuts, movable joints).

    Raises
    ------
    NotCounted
        Where a tree joint is spherical (its position is a quaternion, which
        ``calculateJacobian``'s joint-position list does not take), or where ``calculateJacobian``
        refuses the model: it builds Bullet's inverse-dynamics tree, which checks the links'
        inertias, and a flat body's principal moment that comes out −1e-17 instead of 0 fails
        that check (found on drawn planar four-bars with slender couplers), although stepping
        accepts it.
    """
    client, body = world.client, world.body
    kinds = [pybullet.getJointInfo(body, j, physicsClientId=client)[2]
             for j in range(pybullet.getNumJoints(body, physicsClientId=client))]
    if pybullet.JOINT_SPHERICAL in kinds:
        raise NotCounted("a spherical tree joint")
    movable = [j for j, kind in enumerate(kinds) if kind != pybullet.JOINT_FIXED]
    positions = [pybullet.getJointState(body, j, physicsClientId=client)[0] for j in movable]
    zeros = [0.0] * len(positions)
    rows = []
    for cut in model.cuts:
        ends = []
        for part, point in ((cut.body1, cut.joint.point1), (cut.body2, cut.joint.point2)):
            if part < 0:  # ground
                ends.append(np.zeros((3, len(positions))))
                continue
            try:
                linear, _ = pybullet.calculateJacobian(body, model.body_links[part],
                                                       pivot(model, part, point), positions,
                                                       zeros, zeros, physicsClientId=client)
            except (SystemError, pybullet.error) as error:
                cause = error.__cause__ or error.__context__ or error  # pybullet's own message
                raise NotCounted(f"pybullet.calculateJacobian refused the model: {cause}") \
                    from None
            ends.append(np.array(linear, dtype=float).reshape(3, len(positions)))
        rows.append(ends[0] - ends[1])
    return np.vstack(rows) if rows else np.zeros((0, len(positions)))


def redundancy_notes(model: PybulletModel, world: BulletWorld) -> list[str]:
    """The note counting the redundant closure equations at the world's state (the start):
    the mechanism's and the closure model's; none when no row is redundant."""
    of_model = model.tree.redundant_closure_equations
    try:
        jacobian = closure_jacobian(model, world)
    except NotCounted as why:
        return [f"{of_model} redundant closure equation(s) of the closure model (the "
                f"mechanism's own not counted: {why})"] if model.cuts else []
    return closure_notes.redundancy_notes(jacobian, of_model, RANK_RTOL)
