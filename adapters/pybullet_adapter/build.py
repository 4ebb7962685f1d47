"""Lay out a neutral :class:`~mbh._harness.model.mechanism.Mechanism` as a Bullet multibody: spanning tree, links,
tree joints and cut joints, collected in a :class:`PybulletModel` (no Bullet client is involved).

Model
-----
* Ground is the fixed base (mass 0, frame = world).  Every body is one Bullet link whose *link
  frame* sits at its tree joint's point and is parallel to the world in the reference
  configuration; its inertial (centre-of-mass) frame is the body's principal frame.  Joint
  coordinate zero is therefore the scenario's reference configuration.
* Tree joints (from :func:`mbh._harness.model.topology.spanning_tree`) map to Bullet joints: revolute →
  ``JOINT_REVOLUTE``; prismatic and translational → ``JOINT_PRISMATIC`` (which also locks rotation);
  spherical → ``JOINT_SPHERICAL``.  Bullet's multibody has no universal or cylindrical joint: each is
  built as two single-degree-of-freedom joints through one massless connector link (revolute +
  revolute about the two cross axes, prismatic + revolute along the axis), and the trajectory's
  notes say so.
* Cut joints are closed with user constraints: ``JOINT_POINT2POINT`` (3 equations) for spherical
  cuts and for planar revolute cuts (1 redundant equation, recorded in the notes).  Other cut types
  are :class:`~mbh._adapters.base.UnsupportedCase`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mbh._adapters.base import UNCLOSABLE, UnsupportedCase
from mbh._adapters.pybullet_adapter.quiet import pybullet
from mbh._harness.model.mechanism import GROUND, Joint, Mechanism
from mbh._harness.model.topology import SpanningTree, spanning_tree

#: Equations of one ``JOINT_POINT2POINT`` user constraint.
_POINT2POINT_EQUATIONS = 3

_TREE_JOINT_TYPES = {
    "revolute": (pybullet.JOINT_REVOLUTE,),
    "prismatic": (pybullet.JOINT_PRISMATIC,),
    "translational": (pybullet.JOINT_PRISMATIC,),
    "spherical": (pybullet.JOINT_SPHERICAL,),
    "universal": (pybullet.JOINT_REVOLUTE, pybullet.JOINT_REVOLUTE),
    "cylindrical": (pybullet.JOINT_PRISMATIC, pybullet.JOINT_REVOLUTE),
}


@dataclass(frozen=True)
class _Link:
    """One Bullet link.

    ``body`` is the mechanism body index (-1 for a massless connector); ``parent`` the parent link
    (-1 = base = ground); ``axis`` (unit) and ``origin`` (m) the joint axis and the link frame
    origin in world coordinates at the reference configuration.
    """

    body: int
    parent: int
    joint_type: int
    axis: np.ndarray
    origin: np.ndarray


@dataclass(frozen=True)
class _TreeJoint:
    """A tree joint and the Bullet links carrying its coordinates.

    ``parent``/``child`` are body indices along the tree (-1 = ground); ``sign`` is -1 when the tree
    runs from the joint's body2 to its body1; ``links`` the Bullet links of its coordinates (two for
    universal and cylindrical); ``axes`` the axes of those coordinates (world, reference).
    """

    joint: Joint
    parent: int
    child: int
    sign: float
    links: tuple[int, ...]
    axes: tuple[np.ndarray, ...]
    origin: np.ndarray
    parent_origin: np.ndarray


@dataclass(frozen=True)
class _Cut:
    """A cut joint closed by a point-to-point constraint; ``body1``/``body2`` are body indices."""

    joint: Joint
    body1: int
    body2: int


@dataclass(frozen=True)
class PybulletModel:
    """What :meth:`PybulletAdapter.build` returns: the Bullet layout of a mechanism.

    Attributes
    ----------
    mechanism : Mechanism
    tree : SpanningTree
    links : tuple of _Link
        Bullet links in creation order: depth-first pre-order, the order ``createMultiBody``
        re-sorts its links into, so a link's index here is its Bullet link index (checked by
        :func:`~mbh._adapters.pybullet_adapter.world.bullet_world` against the link names it reads
        back).
    body_links : tuple of int
        Bullet link index of each body (declaration order).
    principal : ndarray, shape (n_bodies, 3, 3)
        Principal axes of each body in its body frame (columns), det +1.
    moments : ndarray, shape (n_bodies, 3)
        Principal moments of inertia, kg·m².
    tree_joints : tuple of _TreeJoint
    cuts : tuple of _Cut
    notes : tuple of str
    size : float
        Largest distance of a reference centre of mass or joint point from the origin, m.
    """

    mechanism: Mechanism
    tree: SpanningTree
    links: tuple[_Link, ...]
    body_links: tuple[int, ...]
    principal: np.ndarray
    moments: np.ndarray
    tree_joints: tuple[_TreeJoint, ...]
    cuts: tuple[_Cut, ...]
    notes: tuple[str, ...]
    size: float


def closure_equations(mech: Mechanism, joint: Joint) -> int:
    """Constraint equations Bullet needs to close a loop cut at ``joint``
    (:data:`mbh._adapters.base.UNCLOSABLE`).

    Spherical cuts and planar revolute cuts take one point-to-point constraint (3 equations);
    Bullet offers no multibody constraint for the other joint types (:data:`UNCLOSABLE`).
    """
    if joint.type == "spherical" or (mech.planar and joint.type == "revolute"):
        return _POINT2POINT_EQUATIONS
    return UNCLOSABLE


def _principal_axes(inertia: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Principal moments, shape (3,), and axes (columns, det +1), shape (3, 3), of ``inertia``."""
    if np.count_nonzero(inertia - np.diag(np.diag(inertia))) == 0:
        return np.diag(inertia).copy(), np.eye(3)
    moments, axes = np.linalg.eigh(inertia)
    if np.linalg.det(axes) < 0:
        axes[:, 2] *= -1.0
    return moments, axes


def _joint_point(mech: Mechanism, joint: Joint, body: int) -> np.ndarray:
    """World position (m) at the reference configuration of ``joint``'s point on ``body``."""
    if body < 0:
        side = joint.point1 if joint.body1 == GROUND else joint.point2
        return np.asarray(side, dtype=float)
    ref = mech.bodies[body]
    local = joint.point1 if mech.body_index(joint.body1) == body else joint.point2
    return ref.position + ref.rotation @ local


def _joint_axes(mech: Mechanism, joint: Joint, flipped: bool) -> tuple[np.ndarray, ...]:
    """Axes (world, reference) of the Bullet coordinates of a tree joint, parent side first."""
    def world(body_name: str, axis: np.ndarray) -> np.ndarray:
        index = mech.body_index(body_name)
        return axis if index < 0 else mech.bodies[index].rotation @ axis

    first = world(joint.body1, joint.axis1)
    if joint.type == "universal":
        second = world(joint.body2, joint.axis2)
        return (second, first) if flipped else (first, second)
    if joint.type == "cylindrical":
        return first, first
    return (first,)


def _layout(mech: Mechanism, tree: SpanningTree) -> tuple[list[_Link], list[int], list[_TreeJoint]]:
    """Bullet links, each body's link index and the tree joints, parents first."""
    links: list[_Link] = []
    body_links = [0] * len(mech.bodies)
    tree_joints = []
    origins = {-1: np.zeros(3)}
    for name in tree.depth_first_order():
        child = mech.body_index(name)
        parent = mech.body_index(tree.parent[name])
        joint = mech.joint(tree.parent_joint[name])
        origin = _joint_point(mech, joint, child)
        axes = _joint_axes(mech, joint, tree.flipped[joint.name])
        parent_link = -1 if parent < 0 else body_links[parent]
        indices = []
        for depth, (joint_type, axis) in enumerate(zip(_TREE_JOINT_TYPES[joint.type], axes)):
            is_last = depth == len(axes) - 1
            links.append(_Link(child if is_last else -1, parent_link, joint_type, axis, origin))
            parent_link = len(links) - 1
            indices.append(parent_link)
        body_links[child] = parent_link
        tree_joints.append(_TreeJoint(joint, parent, child, -1.0 if tree.flipped[joint.name] else 1.0,
                                      tuple(indices), axes, origin, origins[parent]))
        origins[child] = origin
    return links, body_links, tree_joints


def _check_cuts(mech: Mechanism, tree: SpanningTree) -> None:
    """Raise :class:`UnsupportedCase` for a cut joint Bullet cannot close."""
    for name in tree.cut_joints:
        joint = mech.joint(name)
        if closure_equations(mech, joint) == UNCLOSABLE:
            raise UnsupportedCase(f"cut joint {name!r} is {joint.type}: a Bullet multibody closes "
                                  "loops only with point-to-point constraints here (spherical, "
                                  "planar revolute)")


def _notes(mech: Mechanism, tree: SpanningTree) -> tuple[str, ...]:
    notes = []  # the redundant closure equations are counted at the start (redundancy.py)
    for name in tree.tree_joints:
        kind = mech.joint(name).type
        if kind == "universal":
            notes.append(f"universal joint {name!r} built as two revolute joints through one "
                         "massless connector link")
        elif kind == "cylindrical":
            notes.append(f"cylindrical joint {name!r} built as a prismatic and a revolute joint "
                         "through one massless connector link")
    for name in tree.cut_joints:
        notes.append(f"cut joint {name!r} closed by a JOINT_POINT2POINT user constraint")
    return tuple(notes)


def _size(mech: Mechanism) -> float:
    """Largest distance (m) of a reference centre of mass or joint point from the origin."""
    points = [body.position for body in mech.bodies]
    for joint in mech.joints:
        for body in (joint.body1, joint.body2):
            points.append(_joint_point(mech, joint, mech.body_index(body)))
    return float(max(np.linalg.norm(p) for p in points))


def build_model(mech: Mechanism) -> PybulletModel:
    """Lay out ``mech`` as a Bullet multibody; raises :class:`UnsupportedCase` with a reason."""
    tree = spanning_tree(mech, lambda joint: closure_equations(mech, joint))
    _check_cuts(mech, tree)
    links, body_links, tree_joints = _layout(mech, tree)
    axes = [_principal_axes(np.asarray(body.inertia, dtype=float)) for body in mech.bodies]
    cuts = tuple(_Cut(mech.joint(name), mech.body_index(mech.joint(name).body1),
                      mech.body_index(mech.joint(name).body2)) for name in tree.cut_joints)
    return PybulletModel(
        mechanism=mech, tree=tree, links=tuple(links), body_links=tuple(body_links),
        principal=np.array([a for _, a in axes]), moments=np.array([m for m, _ in axes]),
        tree_joints=tuple(tree_joints), cuts=cuts, notes=_notes(mech, tree), size=_size(mech),
    )
