"""Whether a body's joints determine how it turns about the axes it has no inertia about.

A body with a zero principal moment (a slender bar, about its own axis) or with all three zero (a
point mass) has no kinetic energy in a turn about those axes through its centre of mass, so its
accelerations are unique only if its joints forbid that turn: the augmented mass matrix
[M Gᵀ; G 0] is regular only if M is positive definite on the motions the joints allow (null G).

The check here looks at one body with every other body held still and its own centre of mass at
rest (the only motions of zero kinetic energy it could have): its angular velocity ω (world axes)
must lie in its zero-moment axes and obey each of its joints' velocity equations, with r the arm
from its centre of mass to the joint point and a, n the joint axis and the normal of a universal
joint's cross axes (world, at the start):

* revolute: ω ∥ a and ω × r = 0 — held unless the axis passes through the centre of mass;
* spherical: ω × r = 0 — a turn about the line from the joint point to the centre of mass
  stays free, so a point mass or a bar whose ends are ball joints is never held by spherical
  joints alone;
* universal: n · ω = 0 and ω × r = 0; cylindrical: ω ∥ a and (ω × r) ∥ a;
* prismatic, translational: ω = 0.

A planar body turns about z only: it is held unless its moment about z is zero and no joint ties
it at a point away from its centre of mass.  Zero-moment bodies joined to each other can together
still have a free motion this one-body view misses; the neutral dynamics refuses those when the
reference is built (:mod:`mbh._harness.neutral.dynamics`, ``IndeterminateAccelerations``).
"""

from __future__ import annotations

from typing import Iterable

import numpy as np

from mbh._harness.model.mechanism import Body, Joint

#: Relative size (of the trace) below which a principal moment counts as zero.
ZERO_MOMENT = 1e-12
#: Smallest singular value (relative: the joint rows are scaled to unit arm) of the joint rows
#: restricted to the zero-moment axes for which a turn counts as held.
HELD = 1e-9
_Z = np.array([0.0, 0.0, 1.0])


def zero_moment_axes(body: Body, planar: bool) -> np.ndarray:
    """World axes (3, k), orthonormal columns, about which ``body`` has no moment of inertia at
    the start (below :data:`ZERO_MOMENT` of the trace); planar bodies turn about z only."""
    world = body.rotation @ body.inertia @ body.rotation.T
    zero = ZERO_MOMENT * float(np.trace(world))
    if planar:
        return _Z[:, None] if world[2, 2] <= zero else np.zeros((3, 0))
    moments, axes = np.linalg.eigh(world)
    return axes[:, moments <= zero]


def _skew(v: np.ndarray) -> np.ndarray:
    """[v]×, so that [v]× w = v × w."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _turn_rows(joint_type: str, arm: np.ndarray, axis: np.ndarray,
               normal: np.ndarray) -> np.ndarray:
    """The joint's velocity equations on ω (rows, 3 columns) with the other body still and this
    body's centre at rest (module docstring); ``arm`` scaled to the body's largest arm."""
    across = np.eye(3) - np.outer(axis, axis)
    if joint_type in ("prismatic", "translational"):
        return np.eye(3)
    if joint_type == "revolute":
        return np.vstack([across, _skew(arm)])
    if joint_type == "cylindrical":
        return np.vstack([across, across @ _skew(arm)])
    if joint_type == "universal":
        return np.vstack([normal[None, :], _skew(arm)])
    return _skew(arm)  # spherical


def free_turn(body: Body, joints: Iterable[Joint], planar: bool) -> np.ndarray | None:
    """A unit world axis through the centre of mass of ``body`` about which it can turn with no
    kinetic energy while its joints (those of ``joints`` it is part of) allow it, or None when
    they hold every such turn (module docstring).

    Parameters
    ----------
    body : Body
        At its start pose.
    joints : iterable of Joint
        The mechanism's joints; those not touching ``body`` are ignored.
    planar : bool
        Whether the scene is planar (the body turns about z only).
    """
    zero_axes = zero_moment_axes(body, planar)
    if zero_axes.shape[1] == 0:
        return None
    sides = []
    for joint in joints:
        for name, point, axis, normal in ((joint.body1, joint.point1, joint.axis1, joint.normal1),
                                          (joint.body2, joint.point2, joint.axis2, joint.normal2)):
            if name == body.name:
                sides.append((joint.type, body.rotation @ point, body.rotation @ axis,
                              body.rotation @ normal))
    reach = max((float(np.linalg.norm(arm)) for _, arm, _, _ in sides), default=0.0) or 1.0
    rows = [_turn_rows(kind, arm / reach, axis, normal) for kind, arm, axis, normal in sides]
    restricted = np.vstack([np.zeros((0, 3)), *rows]) @ zero_axes
    _, values, directions = np.linalg.svd(restricted)
    values = np.concatenate([values, np.zeros(zero_axes.shape[1] - len(values))])
    if values[-1] > HELD:
        return None
    turn = zero_axes @ directions[-1]
    return turn / np.linalg.norm(turn)
