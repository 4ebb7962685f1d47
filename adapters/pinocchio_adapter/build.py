"""Translate a neutral :class:`~mbh._harness.model.mechanism.Mechanism` into a Pinocchio model.

The spanning tree of the mechanism becomes Pinocchio's kinematic tree in joint coordinates; every
cut joint becomes loop-closure constraints of Pinocchio's constraint-dynamics API
(``pin.RigidConstraintModel``).

Frames
------
Each tree body ``b`` gets one Pinocchio joint whose frame sits at the point of ``b``'s parent joint
(the joint through which the tree reaches ``b``) with ``b``'s body axes.  Its inertia is therefore
``pin.Inertia(mass, -point, inertia)`` with the scenario's centroidal inertia unchanged, and an
operational frame named after the body marks its centre of mass.  At zero joint coordinates every
body is in the scenario's reference configuration.

Loop closures (the fewest equations Pinocchio's rigid constraints offer)
------------------------------------------------------------------------
* spherical: one ``CONTACT_3D`` point constraint (3 equations, none redundant);
* revolute, planar mechanism: one ``CONTACT_3D`` at the joint point (3 equations for a joint of
  class 2: one redundant);
* revolute, spatial mechanism: two ``CONTACT_3D`` at the joint point and one axis length further
  along the axis (6 equations for a joint of class 5: one redundant).  ``CONTACT_6D`` would lock the
  rotation about the axis, so it cannot close a revolute;
* prismatic, translational, cylindrical, universal: no rigid constraint of Pinocchio keeps a slide
  or a single angular relation, so the tree never cuts them when it can avoid it, and a mechanism
  that must cut one is unsupported.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from mbh._adapters.base import UNCLOSABLE, UnsupportedCase
from mbh._harness.model.mechanism import GROUND, Body, Joint, JointActuation, Mechanism
from mbh._harness.model.topology import SpanningTree, spanning_tree

#: Distance (m) between the two point constraints that close a spatial revolute.
AXIS_LEVER = 1.0


@dataclass(frozen=True)
class PinocchioModel:
    """A mechanism translated for Pinocchio: what :func:`build_model` returns.

    Attributes
    ----------
    mechanism : Mechanism
        The neutral model it was built from.
    tree : SpanningTree
        The spanning tree; its joints are Pinocchio joints, its cut joints constraints.
    model : pin.Model
        Kinematic tree with the scenario's inertias and gravity, and one CoM frame per body.
    constraints : tuple of pin.RigidConstraintModel
        Loop closures of the cut joints, in the order of ``tree.cut_joints``.
    body_frames : tuple of int
        Frame id of each body's centre of mass, in the mechanism's body order.
    joint_ids : dict
        Tree joint name → Pinocchio joint id.
    tau_joint : ndarray, shape (nv,)
        Generalized forces of the joint actuations on tree joints, N·m or N.

    The redundant closure equations are counted at the start of a run, where the loop is closed
    (:func:`.dynamics.redundancy_notes`): this model has no assembled configuration of its own.
    """

    mechanism: Mechanism
    tree: SpanningTree
    model: pin.Model
    constraints: tuple
    body_frames: tuple[int, ...]
    joint_ids: dict[str, int]
    tau_joint: np.ndarray


def closure_equations(mech: Mechanism, joint: Joint) -> int:
    """Constraint equations Pinocchio needs to close a loop cut at ``joint``
    (:data:`mbh._adapters.base.UNCLOSABLE`).

    Parameters
    ----------
    mech : Mechanism
        Whether it is planar decides a revolute cut: one point constraint, or two.
    joint : Joint

    Returns
    -------
    int
        3 per point constraint; :data:`UNCLOSABLE` when Pinocchio has no constraint for that
        joint type.
    """
    if joint.type == "spherical":
        return 3
    if joint.type == "revolute":
        return 3 if mech.planar else 6
    return UNCLOSABLE


def build_model(mech: Mechanism) -> PinocchioModel:
    """Build the Pinocchio model of ``mech``.

    Parameters
    ----------
    mech : Mechanism

    Returns
    -------
    PinocchioModel

    Raises
    ------
    UnsupportedCase
        If a joint that Pinocchio cannot close with a rigid constraint must be cut.
    """
    tree = spanning_tree(mech, lambda joint: closure_equations(mech, joint))
    unclosable = [name for name in tree.cut_joints
                  if closure_equations(mech, mech.joint(name)) == UNCLOSABLE]
    if unclosable:
        kinds = ", ".join(f"{name} ({mech.joint(name).type})" for name in unclosable)
        raise UnsupportedCase(f"every spanning tree of {mech.name!r} cuts a joint Pinocchio's "
                              f"rigid constraints cannot close: {kinds}")
    model = pin.Model()
    model.name = mech.name
    model.gravity = pin.Motion(np.asarray(mech.gravity, dtype=float), np.zeros(3))
    joint_ids = {}
    # Depth-first: Pinocchio's algorithms (crba's nvSubtree ranges) need every subtree's
    # velocity indices contiguous; breadth-first numbering breaks crba and constraintDynamics.
    for body_name in tree.depth_first_order():
        joint_ids[tree.parent_joint[body_name]] = _add_body(model, mech, tree, body_name, joint_ids)
    body_frames = tuple(model.getFrameId(body.name) for body in mech.bodies)
    constraints = tuple(c for name in tree.cut_joints
                        for c in _closure(model, mech, tree, joint_ids, mech.joint(name)))
    return PinocchioModel(mech, tree, model, constraints, body_frames, joint_ids,
                          _joint_actuation(mech, tree, model, joint_ids))


def _body(mech: Mechanism, name: str) -> Body | None:
    """Body ``name`` of ``mech``, None for ground."""
    index = mech.body_index(name)
    return None if index < 0 else mech.bodies[index]


def _sides(joint: Joint, flipped: bool) -> tuple[tuple, tuple]:
    """``((parent, point, axis), (child, point, axis))`` of a tree joint, in body frames."""
    first = (joint.body1, joint.point1, joint.axis1)
    second = (joint.body2, joint.point2, joint.axis2)
    return (second, first) if flipped else (first, second)


def _origin(mech: Mechanism, tree: SpanningTree, body_name: str) -> np.ndarray:
    """Origin of ``body_name``'s Pinocchio joint frame in its body frame, shape (3,), m.

    The point, on the body, of the joint that links it to its tree parent.
    """
    if body_name == GROUND:
        return np.zeros(3)
    joint = mech.joint(tree.parent_joint[body_name])
    return _sides(joint, tree.flipped[joint.name])[1][1]


def _reference_pose(mech: Mechanism, body_name: str) -> pin.SE3:
    """Reference pose of a body's frame (ground: identity), body → world."""
    body = _body(mech, body_name)
    return pin.SE3.Identity() if body is None else pin.SE3(body.rotation, body.position)


def _joint_frame(mech: Mechanism, tree: SpanningTree, body_name: str) -> pin.SE3:
    """Reference pose of ``body_name``'s Pinocchio joint frame (ground: identity)."""
    return _reference_pose(mech, body_name) * pin.SE3(np.eye(3), _origin(mech, tree, body_name))


def _joint_model(kind: str, parent_axis: np.ndarray, child_axis: np.ndarray):
    """Pinocchio joint model of a tree joint, its axes in the child's joint frame.

    Parameters
    ----------
    kind : str
        Neutral joint type.
    parent_axis, child_axis : ndarray, shape (3,)
        The parent's and the child's joint axis in the child's joint frame at the reference
        configuration (equal except for ``universal``, whose first rotation is about the
        parent's axis).
    """
    if kind == "revolute":
        return _revolute(child_axis)
    if kind in ("prismatic", "translational"):
        return pin.JointModelPrismaticUnaligned(child_axis)
    if kind == "spherical":
        return pin.JointModelSpherical()
    if kind == "universal":
        return pin.JointModelUniversal(parent_axis, child_axis)
    if kind == "cylindrical":
        composite = pin.JointModelComposite(_revolute(child_axis))
        composite.addJoint(pin.JointModelPrismaticUnaligned(child_axis))
        return composite
    raise ValueError(f"joint type {kind!r} has no Pinocchio joint model")


def _revolute(axis: np.ndarray):
    """RX/RY/RZ for exactly a positive coordinate axis, else RevoluteUnaligned.

    The test is on every component: a unit axis tilted from a coordinate axis by less than
    ~1.5e-8 rad has its largest component round to exactly 1.0, and snapping it would drop the
    tilt (a generated axis (0, 5e-11, 1) became RZ: the start's angular velocity was then
    reproduced only to 5e-11 rad/s).
    """
    aligned = {0: pin.JointModelRX, 1: pin.JointModelRY, 2: pin.JointModelRZ}
    index = int(np.argmax(np.abs(axis)))
    if np.array_equal(axis, np.eye(3)[index]):
        return aligned[index]()
    return pin.JointModelRevoluteUnaligned(axis)


def _add_body(model: pin.Model, mech: Mechanism, tree: SpanningTree, body_name: str,
              joint_ids: dict[str, int]) -> int:
    """Add ``body_name``'s joint, inertia and CoM frame to ``model``; return the joint id."""
    joint = mech.joint(tree.parent_joint[body_name])
    (_, _, parent_axis), (_, child_point, child_axis) = _sides(joint, tree.flipped[joint.name])
    parent = tree.parent[body_name]
    parent_id = 0 if parent == GROUND else joint_ids[tree.parent_joint[parent]]
    placement = _joint_frame(mech, tree, parent).actInv(_joint_frame(mech, tree, body_name))
    parent_rotation = _reference_pose(mech, parent).rotation
    child_rotation = _reference_pose(mech, body_name).rotation
    parent_axis_here = child_rotation.T @ parent_rotation @ parent_axis
    joint_model = _joint_model(joint.type, parent_axis_here, child_axis)
    joint_id = model.addJoint(parent_id, joint_model, placement, joint.name)
    body = _body(mech, body_name)
    # Assigned, not appendBodyToJoint: that adds to the joint's zero inertia and rounds the
    # centroidal inertia by ~1e-14 relative.
    model.inertias[joint_id] = pin.Inertia(body.mass, -child_point, body.inertia)
    model.addFrame(pin.Frame(body_name, joint_id, pin.SE3(np.eye(3), -child_point),
                             pin.FrameType.OP_FRAME), False)
    return joint_id


def _anchor(mech: Mechanism, tree: SpanningTree, joint_ids: dict[str, int], body_name: str,
            point: np.ndarray) -> tuple[int, pin.SE3]:
    """``(joint id, placement in that joint's frame)`` of ``point`` (body frame) of a body.

    The placement's axes are the world axes at the reference configuration, so the two anchors
    of a cut joint coincide there as full frames.
    """
    if body_name == GROUND:
        return 0, pin.SE3(np.eye(3), point)
    rotation = _reference_pose(mech, body_name).rotation
    joint_id = joint_ids[tree.parent_joint[body_name]]
    return joint_id, pin.SE3(rotation.T, point - _origin(mech, tree, body_name))


def _closure(model: pin.Model, mech: Mechanism, tree: SpanningTree, joint_ids: dict[str, int],
             joint: Joint) -> list:
    """The rigid constraints closing the cut ``joint`` (see the module docstring)."""
    offsets = [0.0]
    if joint.type == "revolute" and not mech.planar:
        offsets.append(AXIS_LEVER)
    constraints = []
    for offset in offsets:
        id1, place1 = _anchor(mech, tree, joint_ids, joint.body1,
                              joint.point1 + offset * joint.axis1)
        id2, place2 = _anchor(mech, tree, joint_ids, joint.body2,
                              joint.point2 + offset * joint.axis2)
        constraint = pin.RigidConstraintModel(pin.ContactType.CONTACT_3D, model, id1, place1,
                                              id2, place2, pin.ReferenceFrame.LOCAL)
        constraint.name = f"{joint.name}@{offset:g}"
        constraints.append(constraint)
    return constraints


def _joint_actuation(mech: Mechanism, tree: SpanningTree, model: pin.Model,
                     joint_ids: dict[str, int]) -> np.ndarray:
    """Generalized forces of the actuations on tree joints, shape (nv,).

    The actuation acts on ``body2`` with the reaction on ``body1``; Pinocchio's coordinate moves
    the child relative to the parent, so a flipped joint takes the opposite sign.  On a
    cylindrical joint it is the torque (the rotation, first coordinate of the composite).
    """
    tau = np.zeros(model.nv)
    for force in mech.forces:
        if isinstance(force, JointActuation) and force.joint in joint_ids:
            sign = -1.0 if tree.flipped[force.joint] else 1.0
            tau[model.joints[joint_ids[force.joint]].idx_v] += sign * force.value
    return tau
