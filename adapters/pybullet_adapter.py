"""PyBullet adapter: a Featherstone multibody (``createMultiBody``) in DIRECT mode.

Model
-----
* Ground is the fixed base (mass 0, frame = world).  Every body is one Bullet link whose *link
  frame* sits at its tree joint's point and is parallel to the world in the reference
  configuration; its inertial (centre-of-mass) frame is the body's principal frame.  Joint
  coordinate zero is therefore the scenario's reference configuration.
* Tree joints (from :func:`harness.topology.spanning_tree`) map to Bullet joints: revolute →
  ``JOINT_REVOLUTE``; prismatic and translational → ``JOINT_PRISMATIC`` (which also locks rotation);
  spherical → ``JOINT_SPHERICAL``.  Bullet's multibody has no universal or cylindrical joint: each is
  built as two single-degree-of-freedom joints through one massless connector link (revolute +
  revolute about the two cross axes, prismatic + revolute along the axis), and the trajectory's
  notes say so.
* Cut joints are closed with user constraints: ``JOINT_POINT2POINT`` (3 equations) for spherical
  cuts and for planar revolute cuts (1 redundant equation, recorded in the notes).  Other cut types
  are :class:`~adapters.base.UnsupportedCase`.
* Loads: gravity; joint actuation on tree joints as a generalised force (``TORQUE_CONTROL``), on cut
  joints as equal and opposite body torques; body forces, body torques and spring-dampers as
  external forces recomputed from the body states before every step.  Bullet clears all of them
  after each step, so they are re-applied every step.

Faithfulness switches (each has a test): joint velocity motors off (revolute/prismatic force 0,
spherical motor force 0), linear/angular damping 0, joint damping and friction 0, the 100 rad/s
joint-velocity clamp raised to :data:`_HUGE`, the user-constraint force cap raised to :data:`_HUGE`
after the time step is set, sleeping disabled, no collision shapes (so no contacts), inertia set
explicitly (links without a collision shape otherwise get zero inertia).

Frames in Bullet's API: link states, pivots and spherical joint coordinates live in the link's
*centre-of-mass* frame; a spherical joint's quaternion ``q`` and rate ``w`` satisfy
``R_com = L_parent · R_inertial · R(q)`` and ``ω_child − ω_parent = R_com · w``.
"""

from __future__ import annotations

import contextlib
import ctypes
import math
import os
import time
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from adapters.base import Adapter, MethodSpec, UnsupportedCase
from harness.initial import initial_state
from harness.model import (
    GROUND,
    BodyForce,
    BodyTorque,
    Joint,
    JointActuation,
    Mechanism,
    SpringDamper,
)
from harness.topology import SpanningTree, spanning_tree
from harness.trajectory import BodyStates, Trajectory


def _flush_c_stdout() -> None:
    """Flush the C library's ``stdout`` buffer (a message may still sit in it)."""
    libc = ctypes.CDLL(None)
    try:
        libc.fflush(ctypes.c_void_p.in_dll(libc, "stdout"))
    except ValueError:
        libc.fflush(None)


@contextlib.contextmanager
def _quiet_output() -> Iterator[None]:
    """Silence C-level writes to file descriptors 1 and 2 (PyBullet's banners: the build-time
    banner goes to stderr on import, the MLCP solver announcements to stdout)."""
    try:
        saved = [os.dup(1), os.dup(2)]
    except OSError:
        yield
        return
    try:
        with open(os.devnull, "wb") as devnull:
            os.dup2(devnull.fileno(), 1)
            os.dup2(devnull.fileno(), 2)
            yield
    finally:
        _flush_c_stdout()
        for fd, copy in zip((1, 2), saved):
            os.dup2(copy, fd)
            os.close(copy)


with _quiet_output():
    import pybullet

#: Stand-in for "no limit" in Bullet settings that take a finite number (N, N·m, rad/s, m/s).
_HUGE = 1e30
#: Closure cost of a cut joint type Bullet cannot close on a multibody (never chosen if avoidable).
_UNCLOSABLE = 1000
#: Equations of one ``JOINT_POINT2POINT`` user constraint.
_POINT2POINT_EQUATIONS = 3
#: A run has diverged when a centre of mass leaves a ball this many times the mechanism's size.
_DIVERGED_SCALE = 1e3

_TREE_JOINT_TYPES = {
    "revolute": (pybullet.JOINT_REVOLUTE,),
    "prismatic": (pybullet.JOINT_PRISMATIC,),
    "translational": (pybullet.JOINT_PRISMATIC,),
    "spherical": (pybullet.JOINT_SPHERICAL,),
    "universal": (pybullet.JOINT_REVOLUTE, pybullet.JOINT_REVOLUTE),
    "cylindrical": (pybullet.JOINT_PRISMATIC, pybullet.JOINT_REVOLUTE),
}

#: PyBullet's own defaults (PhysicsServerCommandProcessor and btContactSolverInfo), checked by the
#: test that runs ``default`` with and without setting them and compares bit for bit.
_ENGINE_DEFAULTS = {
    "numSolverIterations": 50,
    "erp": 0.2,
    "contactERP": 0.08,
    "frictionERP": 0.2,
    "globalCFM": 0.0,
    "numSubSteps": 0,
    "solverResidualThreshold": 1e-7,
    "constraintSolverType": pybullet.CONSTRAINT_SOLVER_LCP_SI,
    "useSplitImpulse": True,
    "warmStartingFactor": 0.1,
    "numNonContactInnerIterations": 1,
}
#: The most accurate solver settings measured at a given step (see the report): full error
#: reduction of the loop closure, more iterations, no residual early exit.  The MLCP solvers
#: (PGS, Dantzig) do worse on these loops: PGS blows up, Dantzig leaves the loop open.
_BEST = {**_ENGINE_DEFAULTS, "numSolverIterations": 200, "erp": 1.0, "solverResidualThreshold": 0.0}
#: ``best`` with ten Bullet sub-steps per step (ten times the work per step).
_SUBSTEPS = {**_BEST, "numSubSteps": 10}


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
        Bullet links in creation order (parents first).
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


def closure_equations(mech: Mechanism):
    """The closure-cost function of :func:`harness.topology.spanning_tree` for Bullet.

    Spherical cuts and planar revolute cuts take one point-to-point constraint (3 equations);
    Bullet offers no multibody constraint for the other joint types (:data:`_UNCLOSABLE`).
    """

    def cost(joint: Joint) -> int:
        if joint.type == "spherical" or (mech.planar and joint.type == "revolute"):
            return _POINT2POINT_EQUATIONS
        return _UNCLOSABLE

    return cost


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
    for name in tree.order:
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
    cost = closure_equations(mech)
    for name in tree.cut_joints:
        joint = mech.joint(name)
        if cost(joint) >= _UNCLOSABLE:
            raise UnsupportedCase(f"cut joint {name!r} is {joint.type}: a Bullet multibody closes "
                                  "loops only with point-to-point constraints here (spherical, "
                                  "planar revolute)")


def _notes(mech: Mechanism, tree: SpanningTree) -> tuple[str, ...]:
    notes = []
    if tree.redundant_closure_equations > 0:
        notes.append(f"{tree.redundant_closure_equations} redundant closure equation(s)")
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
    tree = spanning_tree(mech, closure_equations(mech))
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


# ----------------------------------------------------------------------------------------------
# Kinematics shared by the state conversion and the loads
# ----------------------------------------------------------------------------------------------

def _quat_xyzw(matrix: np.ndarray) -> list[float]:
    return list(Rotation.from_matrix(matrix).as_quat())


def _matrix(quat_xyzw) -> np.ndarray:
    return Rotation.from_quat(quat_xyzw).as_matrix()


@dataclass(frozen=True)
class _Pose:
    """World pose and velocity of a body (ground: identity at rest)."""

    position: np.ndarray
    rotation: np.ndarray
    velocity: np.ndarray
    omega: np.ndarray


def _poses(mech: Mechanism, states: BodyStates) -> dict[int, _Pose]:
    """Body index → :class:`_Pose` from ``states`` (quaternions scalar first), ground as -1."""
    poses = {-1: _Pose(np.zeros(3), np.eye(3), np.zeros(3), np.zeros(3))}
    wxyz = np.asarray(states.quaternion, dtype=float)
    for index in range(len(mech.bodies)):
        poses[index] = _Pose(np.asarray(states.position[index], dtype=float),
                             _matrix(np.roll(wxyz[index], -1)),
                             np.asarray(states.velocity[index], dtype=float),
                             np.asarray(states.angular_velocity[index], dtype=float))
    return poses


def _link_rotation(mech: Mechanism, pose: _Pose, body: int) -> np.ndarray:
    """Orientation of ``body``'s link frame (world-parallel at the reference), shape (3, 3)."""
    return pose.rotation if body < 0 else pose.rotation @ mech.bodies[body].rotation.T


def _attached_point(mech: Mechanism, pose: _Pose, body: int, ref_point: np.ndarray):
    """Current world position and velocity of the point of ``body`` at ``ref_point`` (reference)."""
    if body < 0:
        return ref_point, np.zeros(3)
    ref = mech.bodies[body]
    offset = pose.rotation @ (ref.rotation.T @ (ref_point - ref.position))
    return pose.position + offset, pose.velocity + np.cross(pose.omega, offset)


def _angle(rotation: np.ndarray, axis: np.ndarray) -> float:
    """Angle (rad) of ``rotation`` about the unit ``axis`` (a rotation about that axis)."""
    x, y, z, w = Rotation.from_matrix(rotation).as_quat()
    return 2.0 * math.atan2(float(np.dot([x, y, z], axis)), w)


def _axis_rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    return Rotation.from_rotvec(axis * angle).as_matrix()


def _coordinates(model: PybulletModel, tj: _TreeJoint, poses: dict[int, _Pose]):
    """Bullet coordinates of tree joint ``tj``: list of (link, position, velocity) per link.

    Spherical joints give a quaternion (x, y, z, w) and a rate (3,) in the centre-of-mass frame.
    """
    mech = model.mechanism
    parent, child = poses[tj.parent], poses[tj.child]
    lp = _link_rotation(mech, parent, tj.parent)
    relative = lp.T @ _link_rotation(mech, child, tj.child)
    omega = child.omega - parent.omega
    kind = tj.joint.type
    if kind == "spherical":
        ref = mech.bodies[tj.child]
        com = child.rotation @ model.principal[tj.child]
        joint_rotation = (ref.rotation @ model.principal[tj.child]).T @ lp.T @ com
        return [(tj.links[0], _quat_xyzw(joint_rotation), list(com.T @ omega))]
    if kind == "revolute":
        return [(tj.links[0], _angle(relative, tj.axes[0]), float(lp @ tj.axes[0] @ omega))]
    slide = _slide(mech, tj, poses, lp)
    if kind in ("prismatic", "translational"):
        return [(tj.links[0], *slide)]
    if kind == "cylindrical":
        rate = float(lp @ tj.axes[1] @ omega)
        return [(tj.links[0], *slide), (tj.links[1], _angle(relative, tj.axes[1]), rate)]
    return _universal(tj, relative, lp, omega)


def _slide(mech: Mechanism, tj: _TreeJoint, poses: dict[int, _Pose], lp: np.ndarray):
    """Displacement (m) and rate (m/s) along a sliding tree joint's axis."""
    origin, velocity = _attached_point(mech, poses[tj.child], tj.child, tj.origin)
    base, base_velocity = _attached_point(mech, poses[tj.parent], tj.parent, tj.parent_origin)
    axis = tj.axes[0]
    gap = origin - base
    displacement = float(axis @ (lp.T @ gap - (tj.origin - tj.parent_origin)))
    rate = float((lp @ axis) @ (velocity - base_velocity - np.cross(poses[tj.parent].omega, gap)))
    return displacement, rate


def _universal(tj: _TreeJoint, relative: np.ndarray, lp: np.ndarray, omega: np.ndarray):
    """Angles and rates of ``relative`` = R(a, θ1) R(b, θ2), a and b the two cross axes."""
    a, b = tj.axes
    turned = relative @ b
    first = math.atan2(float(a @ np.cross(b, turned)), float(b @ turned))
    rest = _axis_rotation(a, -first) @ relative
    second = math.atan2(float(b @ np.cross(a, rest @ a)), float(a @ (rest @ a)))
    columns = np.column_stack([lp @ a, lp @ _axis_rotation(a, first) @ b])
    rates = np.linalg.lstsq(columns, omega, rcond=None)[0]
    return [(tj.links[0], first, float(rates[0])), (tj.links[1], second, float(rates[1]))]


# ----------------------------------------------------------------------------------------------
# The Bullet world
# ----------------------------------------------------------------------------------------------

def _inertial_frame(model: PybulletModel, link: _Link) -> tuple[list, list]:
    """Inertial frame position and orientation (x, y, z, w) of ``link`` in its link frame."""
    if link.body < 0:
        return [0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]
    body = model.mechanism.bodies[link.body]
    return list(body.position - link.origin), _quat_xyzw(body.rotation @ model.principal[link.body])


def _create_multibody(model: PybulletModel, client: int) -> int:
    """Create the multibody (no collision or visual shapes) and return its unique id."""
    links = model.links
    origins = [np.zeros(3) if link.parent < 0 else links[link.parent].origin for link in links]
    inertial = [_inertial_frame(model, link) for link in links]
    return pybullet.createMultiBody(
        baseMass=0.0, baseCollisionShapeIndex=-1, baseVisualShapeIndex=-1,
        basePosition=[0.0, 0.0, 0.0], baseOrientation=[0.0, 0.0, 0.0, 1.0],
        linkMasses=[0.0 if l.body < 0 else model.mechanism.bodies[l.body].mass for l in links],
        linkCollisionShapeIndices=[-1] * len(links), linkVisualShapeIndices=[-1] * len(links),
        linkPositions=[list(l.origin - o) for l, o in zip(links, origins)],
        linkOrientations=[[0.0, 0.0, 0.0, 1.0]] * len(links),
        linkInertialFramePositions=[pos for pos, _ in inertial],
        linkInertialFrameOrientations=[orn for _, orn in inertial],
        linkParentIndices=[l.parent + 1 for l in links],
        linkJointTypes=[l.joint_type for l in links],
        linkJointAxis=[list(l.axis) for l in links],
        physicsClientId=client,
    )


def _make_faithful(model: PybulletModel, uid: int, client: int) -> None:
    """Switch off everything Bullet adds to the mechanism (see the module docstring)."""
    for index, link in enumerate(model.links):
        moments = [0.0] * 3 if link.body < 0 else list(model.moments[link.body])
        # Its own call: combined with linearDamping, angularDamping, maxJointVelocity or
        # activationState, changeDynamics silently leaves the inertia at zero.
        pybullet.changeDynamics(uid, index, localInertiaDiagonal=moments, physicsClientId=client)
        pybullet.changeDynamics(uid, index, linearDamping=0.0,
                                angularDamping=0.0, jointDamping=0.0, maxJointVelocity=_HUGE,
                                activationState=pybullet.ACTIVATION_STATE_DISABLE_SLEEPING,
                                physicsClientId=client)
        if link.joint_type == pybullet.JOINT_SPHERICAL:
            pybullet.setJointMotorControlMultiDof(uid, index, pybullet.POSITION_CONTROL,
                                                  targetPosition=[0.0, 0.0, 0.0, 1.0],
                                                  positionGain=0.0, velocityGain=0.0,
                                                  force=[0.0, 0.0, 0.0], physicsClientId=client)
        else:
            pybullet.setJointMotorControl2(uid, index, pybullet.VELOCITY_CONTROL, force=0.0,
                                           physicsClientId=client)
    pybullet.changeDynamics(uid, -1, linearDamping=0.0, angularDamping=0.0,
                            activationState=pybullet.ACTIVATION_STATE_DISABLE_SLEEPING,
                            physicsClientId=client)


def _pivot(model: PybulletModel, body: int, local: np.ndarray) -> list[float]:
    """A body-frame point in the centre-of-mass (principal) frame Bullet's pivots use."""
    return list(local) if body < 0 else list(model.principal[body].T @ local)


def _add_cut_constraints(model: PybulletModel, uid: int, client: int) -> list[int]:
    """Create the point-to-point constraints with no force cap; returns their ids.

    Call after the time step is set: ``maxForce`` is stored as an impulse cap (force × step).
    """
    ids = []
    for cut in model.cuts:
        link1 = -1 if cut.body1 < 0 else model.body_links[cut.body1]
        link2 = -1 if cut.body2 < 0 else model.body_links[cut.body2]
        cid = pybullet.createConstraint(
            uid, link1, uid, link2, pybullet.JOINT_POINT2POINT, [0.0, 0.0, 0.0],
            _pivot(model, cut.body1, cut.joint.point1), _pivot(model, cut.body2, cut.joint.point2),
            physicsClientId=client)
        pybullet.changeConstraint(cid, maxForce=_HUGE, physicsClientId=client)
        ids.append(cid)
    return ids


def _set_parameters(params: dict, dt: float, gravity: np.ndarray, client: int) -> None:
    """Time step, gravity and every solver setting of the method."""
    pybullet.setGravity(*map(float, gravity), physicsClientId=client)
    settings = dict(params)
    settings["useSplitImpulse"] = int(settings["useSplitImpulse"])
    with _quiet_output():  # the MLCP solvers announce themselves on stdout
        pybullet.setPhysicsEngineParameter(fixedTimeStep=dt, physicsClientId=client, **settings)


def _reset_state(model: PybulletModel, uid: int, states: BodyStates, client: int) -> None:
    """Put the multibody in the body states ``states`` through its joint coordinates."""
    poses = _poses(model.mechanism, states)
    for tj in model.tree_joints:
        for link, position, velocity in _coordinates(model, tj, poses):
            if isinstance(position, list):
                pybullet.resetJointStateMultiDof(uid, link, position, velocity,
                                                 physicsClientId=client)
            else:
                pybullet.resetJointState(uid, link, position, velocity, physicsClientId=client)


def _read_states(model: PybulletModel, uid: int, client: int) -> BodyStates:
    """Every body's centre-of-mass state, converted from the principal to the body frame.

    A non-finite or zero orientation (a blown-up engine state) is returned as NaN.
    """
    rows = pybullet.getLinkStates(uid, list(model.body_links), computeLinkVelocity=1,
                                  computeForwardKinematics=1, physicsClientId=client)
    quats = np.array([row[1] for row in rows], dtype=float)
    good = np.all(np.isfinite(quats), axis=1) & (np.linalg.norm(quats, axis=1) > 0.5)
    body_quats = np.full((len(rows), 4), np.nan)
    for index in np.flatnonzero(good):
        body_rotation = _matrix(quats[index]) @ model.principal[index].T
        body_quats[index] = np.roll(Rotation.from_matrix(body_rotation).as_quat(), 1)
    return BodyStates(position=np.array([row[0] for row in rows], dtype=float),
                      quaternion=body_quats,
                      velocity=np.array([row[6] for row in rows], dtype=float),
                      angular_velocity=np.array([row[7] for row in rows], dtype=float))


# ----------------------------------------------------------------------------------------------
# Loads
# ----------------------------------------------------------------------------------------------

def _tree_actuation(model: PybulletModel) -> list[tuple[int, float]]:
    """(link, generalised force) of every actuation on a tree joint."""
    mech = model.mechanism
    by_joint = {tj.joint.name: tj for tj in model.tree_joints}
    actuation = []
    for force in mech.forces:
        if isinstance(force, JointActuation) and force.joint in by_joint:
            tj = by_joint[force.joint]
            link = tj.links[-1] if tj.joint.type == "cylindrical" else tj.links[0]
            actuation.append((link, tj.sign * force.value))
    return actuation


def _body_wrenches(model: PybulletModel, states: BodyStates) -> np.ndarray:
    """World force and torque about the centre of mass on each body, shape (n_bodies, 2, 3)."""
    mech = model.mechanism
    poses = _poses(mech, states)
    wrench = np.zeros((len(mech.bodies) + 1, 2, 3))  # last row: ground, discarded
    cut_names = set(model.tree.cut_joints)
    for force in mech.forces:
        if isinstance(force, BodyForce):
            index = mech.body_index(force.body)
            wrench[index, 0] += force.force
            wrench[index, 1] += np.cross(poses[index].rotation @ force.point, force.force)
        elif isinstance(force, BodyTorque):
            wrench[mech.body_index(force.body), 1] += force.torque
        elif isinstance(force, SpringDamper):
            _add_spring(mech, force, poses, wrench)
        elif isinstance(force, JointActuation) and force.joint in cut_names:
            joint = mech.joint(force.joint)
            one, two = mech.body_index(joint.body1), mech.body_index(joint.body2)
            torque = force.value * (poses[one].rotation @ joint.axis1)
            wrench[two, 1] += torque
            wrench[one, 1] -= torque
    return wrench[:-1]


def _add_spring(mech: Mechanism, spring: SpringDamper, poses: dict[int, _Pose],
                wrench: np.ndarray) -> None:
    """Add the spring-damper's forces on its two bodies to ``wrench`` (ground row -1)."""
    ends = []
    for name, local in ((spring.body1, spring.point1), (spring.body2, spring.point2)):
        index = mech.body_index(name)
        pose = poses[index]
        arm = pose.rotation @ local
        ends.append((index, arm, pose.position + arm, pose.velocity + np.cross(pose.omega, arm)))
    delta = ends[1][2] - ends[0][2]
    length = float(np.linalg.norm(delta))
    direction = delta / length
    rate = float(direction @ (ends[1][3] - ends[0][3]))
    tension = spring.stiffness * (length - spring.free_length) + spring.damping * rate
    for (index, arm, _, _), sign in zip(ends, (1.0, -1.0)):
        force = sign * tension * direction
        wrench[index, 0] += force
        wrench[index, 1] += np.cross(arm, force)


def _apply_loads(model: PybulletModel, uid: int, client: int, actuation, needs_state: bool) -> None:
    """Apply this step's joint torques and body wrenches (Bullet clears them every step)."""
    for link, value in actuation:
        pybullet.setJointMotorControl2(uid, link, pybullet.TORQUE_CONTROL, force=value,
                                       physicsClientId=client)
    if not needs_state:
        return
    states = _read_states(model, uid, client)
    for index, (force, torque) in enumerate(_body_wrenches(model, states)):
        link = model.body_links[index]
        if np.any(force):
            pybullet.applyExternalForce(uid, link, list(force), list(states.position[index]),
                                        pybullet.WORLD_FRAME, physicsClientId=client)
        if np.any(torque):
            pybullet.applyExternalTorque(uid, link, list(torque), pybullet.WORLD_FRAME,
                                         physicsClientId=client)


def _needs_body_loads(model: PybulletModel) -> bool:
    """True when some load must be recomputed from the body states every step."""
    cut_names = set(model.tree.cut_joints)
    return any(isinstance(f, (BodyForce, BodyTorque, SpringDamper))
               or (isinstance(f, JointActuation) and f.joint in cut_names)
               for f in model.mechanism.forces)


def _diverged(states: BodyStates, limit: float) -> bool:
    arrays = (states.position, states.quaternion, states.velocity, states.angular_velocity)
    if not all(np.all(np.isfinite(a)) for a in arrays):
        return True
    return bool(np.max(np.linalg.norm(states.position, axis=1)) > limit)


def _check_times(dt: float, t_end: float, sample_times) -> np.ndarray:
    """``sample_times`` as a float array, shape (n_samples,); a ValueError names a bad argument."""
    if not (dt > 0 and math.isfinite(dt)):
        raise ValueError(f"dt must be a positive finite number, got {dt!r}")
    if not (t_end >= 0 and math.isfinite(t_end)):
        raise ValueError(f"t_end must be a non-negative finite number, got {t_end!r}")
    times = np.asarray(sample_times, dtype=float)
    if times.ndim != 1 or np.any(np.diff(times) <= 0) or np.any(times < 0) \
            or np.any(times > t_end + 0.5 * dt):
        raise ValueError("sample_times must be increasing times in [0, t_end]")
    return times


@contextlib.contextmanager
def _client() -> Iterator[int]:
    """A fresh DIRECT physics client, disconnected on exit."""
    with _quiet_output():
        client = pybullet.connect(pybullet.DIRECT)
    try:
        yield client
    finally:
        pybullet.disconnect(physicsClientId=client)


@dataclass
class _Progress:
    """What a run has reached: samples, steps taken and stepping wall time (s)."""

    samples: list
    step: int = 0
    wall: float = 0.0


def _advance(model: PybulletModel, uid: int, client: int, loads: tuple, target: int,
             progress: _Progress) -> None:
    """Step until ``progress.step == target``, timing the loads and the stepping only."""
    actuation, needs_state = loads
    while progress.step < target:
        start = time.perf_counter()
        _apply_loads(model, uid, client, actuation, needs_state)
        pybullet.stepSimulation(physicsClientId=client)
        progress.wall += time.perf_counter() - start
        progress.step += 1


def _stepping(model: PybulletModel, uid: int, client: int, sample_steps: np.ndarray,
              n_steps: int, progress: _Progress) -> str:
    """Step through every sample and on to ``n_steps``; returns "ok" or "diverged"."""
    loads = (_tree_actuation(model), _needs_body_loads(model))
    limit = _DIVERGED_SCALE * max(model.size, 1.0)
    for target in sample_steps:
        _advance(model, uid, client, loads, int(target), progress)
        states = _read_states(model, uid, client)
        if _diverged(states, limit):
            return "diverged"
        progress.samples.append(states)
    _advance(model, uid, client, loads, n_steps, progress)
    return "ok"


@dataclass(frozen=True)
class BulletWorld:
    """A live Bullet world of a model: physics client, multibody id and cut-constraint ids."""

    client: int
    body: int
    constraints: tuple[int, ...]


@contextlib.contextmanager
def bullet_world(model: PybulletModel, params: dict | None, dt: float) -> Iterator[BulletWorld]:
    """Build ``model`` in a fresh DIRECT client, faithful and at the harness's initial state.

    Parameters
    ----------
    model : PybulletModel
    params : dict or None
        Resolved method parameters; None leaves every solver setting at PyBullet's own value
        (only the time step and gravity are set).
    dt : float
        Time step, s.
    """
    with _client() as client:
        if params is None:
            pybullet.setGravity(*map(float, model.mechanism.gravity), physicsClientId=client)
            pybullet.setTimeStep(dt, physicsClientId=client)
        else:
            _set_parameters(params, dt, model.mechanism.gravity, client)
        uid = _create_multibody(model, client)
        _make_faithful(model, uid, client)
        constraints = _add_cut_constraints(model, uid, client)
        _reset_state(model, uid, initial_state(model.mechanism), client)
        yield BulletWorld(client, uid, tuple(constraints))


def _run(model: PybulletModel, params: dict, dt: float, sample_times: np.ndarray,
         n_steps: int) -> Trajectory:
    """Step a fresh world and sample it.

    An exception raised by the engine ends the run as ``failed`` with the samples reached.
    """
    progress = _Progress(samples=[])
    sample_steps = np.rint(sample_times / dt).astype(int)
    reason = ""
    try:
        with bullet_world(model, params, dt) as world:
            status = _stepping(model, world.body, world.client, sample_steps, n_steps, progress)
    except Exception as error:  # an engine failure is data (DESIGN.md rule 5)
        status, reason = "failed", f"{type(error).__name__}: {error}"
    if status == "diverged":
        reason = "state non-finite or a centre of mass beyond " \
                 f"{_DIVERGED_SCALE * max(model.size, 1.0):g} m from the origin"
    return Trajectory.from_samples(
        sample_times, progress.samples, status=status, reason=reason,
        failure_time=None if status == "ok" else progress.step * dt,
        wall_time_s=progress.wall, steps=progress.step, notes=list(model.notes),
        counters={"substeps": progress.step * max(1, int(params["numSubSteps"]))},
    )


class PybulletAdapter(Adapter):
    """PyBullet (Bullet's Featherstone multibody with sequential-impulse or LCP constraints)."""

    name = "pybullet"

    def version(self) -> str:
        from importlib.metadata import version
        return f"pybullet {version('pybullet')}"

    def methods(self) -> list[MethodSpec]:
        return [
            MethodSpec("default", "PyBullet's own solver settings at the given step "
                       "(setPhysicsEngineParameter defaults)", dict(_ENGINE_DEFAULTS)),
            MethodSpec("best", "most accurate settings measured: erp = 1 (full error reduction "
                       "of the loop closure), 200 iterations, no residual early exit",
                       dict(_BEST)),
            MethodSpec("substeps", "best with numSubSteps = 10: Bullet divides every step in ten",
                       dict(_SUBSTEPS)),
        ]

    def build(self, mechanism: Mechanism) -> PybulletModel:
        return build_model(mechanism)

    def simulate(self, model: PybulletModel, method: str, dt: float, t_end: float,
                 sample_times: np.ndarray) -> Trajectory:
        _, params = self.method_spec(method)
        times = _check_times(dt, t_end, sample_times)
        return _run(model, params, dt, times, int(round(t_end / dt)))
