"""Translate a neutral :class:`~mbh._harness.model.mechanism.Mechanism` into a MuJoCo specification (``MjSpec``)
and compile it, with every faithfulness switch set explicitly.

Model
-----
* The bodies form the spanning tree chosen by :func:`mbh._harness.model.topology.spanning_tree` with
  MuJoCo's closure costs (:func:`closure_equations`).  Each tree joint becomes hinge / slide /
  ball joints inside the child body, no dummy bodies: revolute = hinge, prismatic and
  translational = slide, cylindrical = slide + hinge, universal = two hinges (the parent-fixed
  cross axis first, then the child-fixed one), spherical = ball.
* Every body frame is the neutral body frame (origin at the centre of mass), so ``xpos``/``xquat``
  are the harness's body states; mass and the full centroidal inertia go in through
  ``fullinertia``.  The reference configuration is MuJoCo's ``qpos0``.
* Cut joints are closed by site-based ``connect`` equality constraints (3 equations each):
  spherical with one, planar revolute with one (1 redundant equation), spatial revolute with two
  along the axis (1 redundant).  MuJoCo has no equality that leaves a sliding or a second
  rotational freedom free, so cut prismatic, translational, cylindrical and universal joints are
  unsupported.
* Faithfulness: no geoms (and the contact flag off), no actuators, joint damping, stiffness,
  armature and friction loss explicitly zero, joints unlimited.  Spring-dampers are native
  spatial tendons between two sites (stiffness, damping, spring length).  Actuation of a tree
  joint is a constant ``qfrc_applied`` on its dof; body torques and forces at the centre of mass
  are constant ``xfrc_applied``; actuation of a cut joint and forces away from the centre of mass
  depend on the pose and are recomputed before every step (held constant within a step).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from mbh._adapters.base import UNCLOSABLE, UnsupportedCase
from mbh._adapters.mujoco_adapter.loads import _loads, _Loads
from mbh._harness.model.mechanism import GROUND, Body, Joint, Mechanism, SpringDamper
from mbh._harness.model.topology import SpanningTree, spanning_tree

#: Smallest principal moment MuJoCo is given, relative to the body's largest, or for a point mass
#: (no moment at all) to its moment m r² about its farthest joint point (MuJoCo refuses a
#: non-positive moment; a slender bar has a zero moment about its own axis).
INERTIA_FLOOR = 1e-9
#: Margin of MuJoCo's check of the principal moments A ≤ B ≤ C, A + B ≥ C: a flat body (all its
#: mass in one plane, e.g. a planar link built from parts) has C = A + B exactly, so round-off
#: decides whether MuJoCo accepts it.  A body with A + B < (1 + FLAT_TOLERANCE) C is taken as flat
#: and its two smaller moments are raised until A + B = (1 + TRIANGLE_MARGIN) C; any other body is
#: left as it is (a slender bar's floored moment already gives A + B = (1 + INERTIA_FLOOR) C).
FLAT_TOLERANCE = 1e-12
TRIANGLE_MARGIN = 1e-9
_SLIDING = ("prismatic", "translational")
_Z = np.array([0.0, 0.0, 1.0])


def closure_equations(mech: Mechanism, joint: Joint) -> int:
    """Constraint equations MuJoCo needs to close a loop cut at ``joint``.

    Parameters
    ----------
    mech : Mechanism
        Decides whether a revolute cut is planar (one ``connect``) or spatial (two).
    joint : Joint

    Returns
    -------
    int
        3 per ``connect`` equality; :data:`UNCLOSABLE` for joint types MuJoCo cannot close.
    """
    if joint.type == "spherical":
        return 3
    if joint.type == "revolute":
        return 3 if mech.planar else 6
    return UNCLOSABLE


@dataclass(frozen=True)
class MujocoModel:
    """What :meth:`MujocoAdapter.build` returns.

    Attributes
    ----------
    mechanism : Mechanism
    tree : SpanningTree
    spec : mujoco.MjSpec
        The compiled specification (``spec.to_xml()`` is the MJCF).
    model : mujoco.MjModel
        The compiled model at MuJoCo's defaults; :meth:`MujocoAdapter.simulate` works on a copy.
    body_ids : ndarray of int, shape (n_bodies,)
        MuJoCo body id of each mechanism body (declaration order), read back by name.
    loads : _Loads
    notes : tuple of str
        Facts about the translation a reader of a case must know (raised inertias).
    """

    mechanism: Mechanism
    tree: SpanningTree
    spec: mujoco.MjSpec
    model: mujoco.MjModel
    body_ids: np.ndarray
    loads: _Loads
    notes: tuple[str, ...] = ()


# --------------------------------------------------------------------------------------------
# Building the specification


def _pose(mech: Mechanism, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Reference rotation (3×3, body → world) and CoM position (3,) of body ``name`` or ground."""
    if name == GROUND:
        return np.eye(3), np.zeros(3)
    body = mech.bodies[mech.body_index(name)]
    return body.rotation, body.position


def _quat(rotation: np.ndarray) -> np.ndarray:
    """Scalar-first unit quaternion of a rotation matrix, shape (4,)."""
    return Rotation.from_matrix(rotation).as_quat(scalar_first=True)


def _elementary_joints(joint: Joint, flipped: bool, parent_to_child: np.ndarray) -> list:
    """MuJoCo joints that make up one tree joint, as ``(suffix, mjtJoint, axis in child frame)``.

    ``parent_to_child`` (3×3) maps parent-frame vectors into the child frame at the reference.
    """
    child_axis = joint.axis1 if flipped else joint.axis2
    hinge, slide = mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtJoint.mjJNT_SLIDE
    if joint.type == "revolute":
        return [("", hinge, child_axis)]
    if joint.type in _SLIDING:
        return [("", slide, child_axis)]
    if joint.type == "cylindrical":
        return [("_slide", slide, child_axis), ("_hinge", hinge, child_axis)]
    if joint.type == "universal":
        parent_axis = parent_to_child @ (joint.axis2 if flipped else joint.axis1)
        return [("_1", hinge, parent_axis), ("_2", hinge, child_axis)]
    return [("", mujoco.mjtJoint.mjJNT_BALL, _Z)]


def floored_inertia(inertia: np.ndarray, point_moment: float = 0.0) -> tuple[np.ndarray, float]:
    """``inertia`` with every principal moment raised to at least :data:`INERTIA_FLOOR` times
    the largest (a point mass's, all zero: times ``point_moment``), and the floor (kg·m²);
    unchanged when no moment is below it.

    Parameters
    ----------
    inertia : ndarray, shape (3, 3)
        Centroidal inertia tensor, kg·m².
    point_moment : float
        The body's moment m r² about its farthest joint point (:func:`point_moment`), kg·m².

    Returns
    -------
    inertia : ndarray, shape (3, 3)
    floor : float
    """
    moments, axes = np.linalg.eigh(inertia)
    floor = INERTIA_FLOOR * (float(moments[-1]) if moments[-1] > 0.0 else point_moment)
    if moments[0] >= floor:
        return inertia, floor
    return axes @ np.diag(np.maximum(moments, floor)) @ axes.T, floor


def point_moment(mech: Mechanism, name: str) -> float:
    """Moment m r² (kg·m²) of body ``name``'s mass about the farthest of its joint points."""
    arms = [float(point @ point) for joint in mech.joints
            for body, point in ((joint.body1, joint.point1), (joint.body2, joint.point2))
            if body == name]
    return mech.bodies[mech.body_index(name)].mass * max(arms, default=0.0)


def balanced_inertia(inertia: np.ndarray) -> tuple[np.ndarray, float]:
    """``inertia`` of a flat body (principal moments A ≤ B ≤ C with A + B < (1 +
    :data:`FLAT_TOLERANCE`) C) with A and B each raised by half the shortfall to
    A + B = (1 + :data:`TRIANGLE_MARGIN`) C, as MuJoCo requires A + B ≥ C: moments about the
    in-plane axes, which a planar mechanism's joints never turn it about.  Any other body's
    ``inertia`` is returned as it is.

    Parameters
    ----------
    inertia : ndarray, shape (3, 3)
        Centroidal inertia tensor, kg·m².

    Returns
    -------
    inertia : ndarray, shape (3, 3)
    raise : float
        What A and B were each raised by, kg·m² (0.0 when unchanged).
    """
    moments, axes = np.linalg.eigh(inertia)
    if moments[0] + moments[1] >= (1.0 + FLAT_TOLERANCE) * moments[2]:
        return inertia, 0.0
    shortfall = (1.0 + TRIANGLE_MARGIN) * moments[2] - moments[0] - moments[1]
    raised = moments + np.array([0.5, 0.5, 0.0]) * shortfall
    return axes @ np.diag(raised) @ axes.T, 0.5 * shortfall


def mujoco_inertia(mech: Mechanism, body: Body) -> tuple[np.ndarray, str | None, float]:
    """The centroidal inertia MuJoCo is given for ``body``: floored (:func:`floored_inertia`)
    then balanced (:func:`balanced_inertia`).

    Returns
    -------
    inertia : ndarray, shape (3, 3)
        kg·m².
    floor_note : str or None
        What the floor changed, if it changed anything.
    raised : float
        What a flat body's in-plane moments were raised by, kg·m² (0.0 for any other body).
    """
    original = np.asarray(body.inertia, dtype=float)
    moments = np.linalg.eigvalsh(original)
    floored, floor = floored_inertia(original, point_moment(mech, body.name))
    floor_note = None
    if floored is not original:
        scale = ("its largest" if moments[-1] > 0.0
                 else "m r² about its farthest joint point: a point mass")
        floor_note = (f"body {body.name}: principal moment {moments[0]:.3g} raised to "
                      f"{floor:.3g} kg·m² ({INERTIA_FLOOR:g} × {scale}) for MuJoCo, which "
                      "requires positive inertia")
    balanced, raised = balanced_inertia(floored)
    return balanced, floor_note, raised


def _inertia_notes(mech: Mechanism) -> tuple[str, ...]:
    """One note per body whose moments were floored, and one for all flat bodies
    (:func:`mujoco_inertia`)."""
    notes, flat = [], {}
    for body in mech.bodies:
        _, floor_note, raised = mujoco_inertia(mech, body)
        if floor_note:
            notes.append(floor_note)
        if raised > 0.0:
            flat[body.name] = raised
    if flat:
        allowed = ("a planar mechanism's joints never turn them about those axes" if mech.planar
                   else f"a relative change of at most {TRIANGLE_MARGIN:g}")
        notes.append(f"flat {'body' if len(flat) == 1 else 'bodies'} {', '.join(flat)} (principal "
                     f"moments A + B = C to round-off): A and B raised by at most "
                     f"{max(flat.values()):.3g} kg·m² for MuJoCo, which requires A + B ≥ C "
                     f"({allowed})")
    return tuple(notes)


def _add_body(spec_parent, mech: Mechanism, name: str, parent: str):
    """Add body ``name`` under ``spec_parent`` at its reference pose relative to ``parent``."""
    rot_p, pos_p = _pose(mech, parent)
    body = mech.bodies[mech.body_index(name)]
    inertia, _, _ = mujoco_inertia(mech, body)
    added = spec_parent.add_body(name=name, pos=rot_p.T @ (body.position - pos_p),
                                 quat=_quat(rot_p.T @ body.rotation))
    added.mass = body.mass
    added.ipos = np.zeros(3)
    added.fullinertia = [inertia[0, 0], inertia[1, 1], inertia[2, 2],
                         inertia[0, 1], inertia[0, 2], inertia[1, 2]]
    added.explicitinertial = True
    added.gravcomp = 0.0
    return added


def _add_tree_joint(spec_body, mech: Mechanism, joint: Joint, flipped: bool, parent: str) -> None:
    """Add the MuJoCo joints of tree joint ``joint`` to ``spec_body`` (the child)."""
    rot_p, _ = _pose(mech, parent)
    rot_c, _ = _pose(mech, spec_body.name)
    anchor = joint.point1 if flipped else joint.point2
    for suffix, kind, axis in _elementary_joints(joint, flipped, rot_c.T @ rot_p):
        spec_body.add_joint(name=joint.name + suffix, type=kind, axis=axis, pos=anchor,
                            limited=mujoco.mjtLimited.mjLIMITED_FALSE, damping=[0.0, 0.0, 0.0],
                            stiffness=[0.0, 0.0, 0.0], armature=0.0, frictionloss=0.0)


def _add_site(bodies: dict, body: str, name: str, point: np.ndarray) -> str:
    """Add a site ``name`` at ``point`` (body frame) of ``body``; returns its name."""
    bodies[body].add_site(name=name, pos=point)
    return name


def _add_connect(spec: mujoco.MjSpec, bodies: dict, joint: Joint, name: str,
                 offset: float) -> None:
    """A site-based ``connect`` between the joint points shifted ``offset`` m along the axis."""
    site1 = _add_site(bodies, joint.body1, f"{name}_1", joint.point1 + offset * joint.axis1)
    site2 = _add_site(bodies, joint.body2, f"{name}_2", joint.point2 + offset * joint.axis2)
    spec.add_equality(name=name, type=mujoco.mjtEq.mjEQ_CONNECT,
                      objtype=mujoco.mjtObj.mjOBJ_SITE, name1=site1, name2=site2)


def _add_closure(spec: mujoco.MjSpec, bodies: dict, mech: Mechanism, joint: Joint) -> None:
    """Close the loop at cut joint ``joint`` with ``connect`` equalities."""
    if closure_equations(mech, joint) == UNCLOSABLE:
        raise UnsupportedCase(f"joint {joint.name!r} ({joint.type}) is cut and MuJoCo has no "
                              f"equality constraint that closes a {joint.type} joint")
    _add_connect(spec, bodies, joint, joint.name, 0.0)
    if joint.type == "revolute" and not mech.planar:
        _add_connect(spec, bodies, joint, f"{joint.name}_axis", 1.0)


def _add_spring(spec: mujoco.MjSpec, bodies: dict, spring: SpringDamper) -> None:
    """A spatial tendon between two sites carrying the spring-damper."""
    tendon = spec.add_tendon(name=spring.name, stiffness=[spring.stiffness, 0.0, 0.0],
                             damping=[spring.damping, 0.0, 0.0],
                             springlength=[spring.free_length, spring.free_length],
                             limited=mujoco.mjtLimited.mjLIMITED_FALSE, armature=0.0,
                             frictionloss=0.0)
    tendon.wrap_site(_add_site(bodies, spring.body1, f"{spring.name}_1", spring.point1))
    tendon.wrap_site(_add_site(bodies, spring.body2, f"{spring.name}_2", spring.point2))


def _make_spec(mech: Mechanism, tree: SpanningTree) -> mujoco.MjSpec:
    """The MuJoCo specification of ``mech`` with tree ``tree`` (not yet compiled)."""
    spec = mujoco.MjSpec()
    spec.modelname = mech.name
    spec.option.gravity = np.asarray(mech.gravity, dtype=float)
    spec.option.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    bodies = {GROUND: spec.worldbody}
    for name in tree.depth_first_order():
        parent = tree.parent[name]
        bodies[name] = _add_body(bodies[parent], mech, name, parent)
        joint = mech.joint(tree.parent_joint[name])
        _add_tree_joint(bodies[name], mech, joint, tree.flipped[joint.name], parent)
    for name in tree.cut_joints:
        _add_closure(spec, bodies, mech, mech.joint(name))
    for force in mech.forces:
        if isinstance(force, SpringDamper):
            _add_spring(spec, bodies, force)
    return spec


def build_model(mechanism: Mechanism) -> MujocoModel:
    """Compile ``mechanism``; raises :class:`UnsupportedCase` for unclosable cut joints."""
    tree = spanning_tree(mechanism, lambda joint: closure_equations(mechanism, joint))
    spec = _make_spec(mechanism, tree)
    model = spec.compile()
    body_ids = np.array([model.body(body.name).id for body in mechanism.bodies])
    return MujocoModel(mechanism, tree, spec, model, body_ids, _loads(mechanism, tree, model),
                       _inertia_notes(mechanism))
