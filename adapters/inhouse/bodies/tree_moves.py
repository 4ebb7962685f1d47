"""The spanning tree of a mechanism as a chain of elementary moves, one per joint coordinate: the
topology half of the joint-coordinate formulation (its kinematics: :mod:`.tree_kinematics`).

The system graph, its spanning tree and the path matrix P come from
:mod:`mbh._harness.model.topology` (Arczewski 1995, §2: incidence matrix Ŝ, eq. 2; path matrix P,
eq. 3).  The tree is chosen there with this formulation's closure cost: a joint that can be a tree
joint costs the absolute equations it would add if cut (its class: 2 planar, 4 or 5 spatial), a
joint that cannot (spherical) costs nothing, so it is cut first.  Every tree joint becomes one or
two *moves*; a move takes a child frame from a parent frame by one coordinate:

* ``turn``:  A_C = A_P Rot(u, σθ) R₀,  r_C + A_C c = r_P + A_P p         (u, p in P's frame)
* ``slide``: A_C = A_P R₀,             r_C + A_C c = r_P + A_P p + σ s A_P u

with R₀ the child's orientation relative to the parent at zero coordinate (the reference
configuration's: the scenario draws every joint assembled there), p and c the joint point in each
frame, σ = ±1.  A joint's coordinate is the motion of its ``body2`` relative to its ``body1``
(right-hand rule about, or slide along, its axis, zero in the reference configuration), the sign
convention of the path matrix; a tree that runs from ``body2`` to ``body1`` (``flipped``) inverts
the moves (σ → −σ, R₀ → R₀ᵀ, p ↔ c, u → R₀ᵀu, in reverse order).

==============  =======  ==============================================================
joint           moves    frames
==============  =======  ==============================================================
revolute        1        turn about the axis
prismatic,      1        slide along the axis
translational
cylindrical     2        turn, then slide along the same axis (a frame without mass between)
universal       2        turn about ``axis1`` (on body1), then about ``axis2`` (on body2)
spherical       —        not as a tree joint yet (3 rotations need a singularity-free chart);
                         cut, it closes the loop with its 3 absolute equations
==============  =======  ==============================================================
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from mbh._harness.model.mechanism import (GROUND, PLANAR_JOINT_CLASS, SPATIAL_JOINT_CLASS, Joint,
                                          Mechanism)
from mbh._harness.model.topology import SpanningTree, spanning_tree

#: Joint types that can be tree joints here, with their number of coordinates.
TREE_JOINT_COORDINATES = {"revolute": 1, "prismatic": 1, "translational": 1, "cylindrical": 2,
                          "universal": 2}


@dataclass(frozen=True)
class Move:
    """One elementary relative motion (see the module docstring).

    Attributes
    ----------
    parent, child : int
        Frame indices: bodies first in declaration order, then the massless frames inside
        two-coordinate joints; −1 is ground.
    kind : str
        ``"turn"`` or ``"slide"``.
    axis : ndarray, shape (3,)
        Unit axis u in the parent's frame.
    at_parent, at_child : ndarray, shape (3,)
        The joint point in the parent's and the child's frame, m.
    offset : ndarray, shape (4,)
        R₀ as a unit quaternion, scalar first.
    sign : float
        σ = ±1.
    coordinate : int
        Index of the move's coordinate in θ.
    joint : str
    """

    parent: int
    child: int
    kind: str
    axis: np.ndarray
    at_parent: np.ndarray
    at_child: np.ndarray
    offset: np.ndarray
    sign: float
    coordinate: int
    joint: str

    def inverted(self, coordinate: int) -> "Move":
        """The same motion seen from the child (parent and child swapped)."""
        back = Rotation.from_quat(self.offset, scalar_first=True).inv()
        return Move(self.child, self.parent, self.kind, back.apply(self.axis), self.at_child,
                    self.at_parent, back.as_quat(scalar_first=True), -self.sign, coordinate,
                    self.joint)


def closure_cost(mech: Mechanism):
    """The cost :func:`~mbh._harness.model.topology.spanning_tree` minimises over the cut joints:
    the joint's class for a joint that can be a tree joint, 0 for one that cannot (cut first)."""
    joint_class = PLANAR_JOINT_CLASS if mech.planar else SPATIAL_JOINT_CLASS

    def cost(joint: Joint) -> int:
        return joint_class[joint.type] if joint.type in TREE_JOINT_COORDINATES else 0
    return cost


def tree_of(mech: Mechanism) -> SpanningTree:
    """The spanning tree of the joint-coordinate formulation (:func:`closure_cost`)."""
    return spanning_tree(mech, closure_cost(mech))


def unsupported_tree_joints(mech: Mechanism, tree: SpanningTree) -> list[str]:
    """Tree joints that have no moves here (spherical), as ``"name (type)"``."""
    return [f"{name} ({mech.joint(name).type})" for name in tree.tree_joints
            if mech.joint(name).type not in TREE_JOINT_COORDINATES]


def _orientation(mech: Mechanism, body: str) -> Rotation:
    """A body's reference orientation (ground: the identity)."""
    if body == GROUND:
        return Rotation.identity()
    return Rotation.from_matrix(mech.bodies[mech.body_index(body)].rotation)


def _joint_moves(mech: Mechanism, joint: Joint, first: int, spare: int) -> list[Move]:
    """The moves of ``joint`` from body1 to body2, coordinates from ``first``, a two-coordinate
    joint's massless frame numbered ``spare``."""
    i, j = mech.body_index(joint.body1), mech.body_index(joint.body2)
    relative = _orientation(mech, joint.body1).inv() * _orientation(mech, joint.body2)
    r0, same = relative.as_quat(scalar_first=True), np.array([1.0, 0.0, 0.0, 0.0])
    a1, p1, p2 = (np.asarray(x, dtype=float) for x in (joint.axis1, joint.point1, joint.point2))
    kind = joint.type
    if kind == "revolute":
        return [Move(i, j, "turn", a1, p1, p2, r0, 1.0, first, joint.name)]
    if kind in ("prismatic", "translational"):
        return [Move(i, j, "slide", a1, p1, p2, r0, 1.0, first, joint.name)]
    if kind == "cylindrical":
        return [Move(i, spare, "turn", a1, p1, p1, same, 1.0, first, joint.name),
                Move(spare, j, "slide", a1, p1, p2, r0, 1.0, first + 1, joint.name)]
    # universal: A_2 = A_1 Rot(a1, α) R₀ Rot(a2, β) = A_V Rot(R₀ a2, β) R₀ with A_V = A_1 Rot(a1, α)
    crossed = relative.apply(np.asarray(joint.axis2, dtype=float))
    return [Move(i, spare, "turn", a1, p1, p1, same, 1.0, first, joint.name),
            Move(spare, j, "turn", crossed, p1, p2, r0, 1.0, first + 1, joint.name)]


@dataclass(frozen=True)
class TreeMoves:
    """The moves of a mechanism's spanning tree, parents before children.

    Attributes
    ----------
    tree : SpanningTree
    moves : tuple of Move
    n_coordinates : int
        Length of θ.
    n_frames : int
        Bodies plus massless frames.
    coordinate_labels : tuple of str
        ``"joint O angle"`` / ``"joint S slide"`` per coordinate.
    """

    tree: SpanningTree
    moves: tuple[Move, ...]
    n_coordinates: int
    n_frames: int
    coordinate_labels: tuple[str, ...]


def tree_moves(mech: Mechanism, tree: SpanningTree) -> TreeMoves:
    """The moves of ``tree`` (every tree joint in :data:`TREE_JOINT_COORDINATES`), in the tree's
    order (a body's parent joint after its parent's).

    Raises
    ------
    ValueError
        When a tree joint has no moves (:func:`unsupported_tree_joints`).
    """
    missing = unsupported_tree_joints(mech, tree)
    if missing:
        raise ValueError(f"mechanism {mech.name!r}: tree joint(s) {', '.join(missing)} have no "
                         "joint coordinates here")
    moves: list[Move] = []
    labels: list[str] = []
    spare = len(mech.bodies)
    for body in tree.order:
        joint = mech.joint(tree.parent_joint[body])
        own = _joint_moves(mech, joint, len(labels), spare)
        spare += len(own) - 1
        if tree.flipped[joint.name]:
            own = [move.inverted(move.coordinate) for move in reversed(own)]
        moves.extend(own)
        labels.extend(f"joint {joint.name} {'angle' if m.kind == 'turn' else 'slide'}"
                      for m in sorted(own, key=lambda m: m.coordinate))
    return TreeMoves(tree, tuple(moves), len(labels), spare, tuple(labels))
