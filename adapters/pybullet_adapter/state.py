"""Conversions between the harness's body states and Bullet's joint coordinates, and the body
kinematics they share with the loads.

:func:`_reset_state` writes body states into the multibody's joint coordinates; :func:`_read_states`
reads every body's centre-of-mass state back, converted from the principal to the body frame.

Frames in Bullet's API: link states, pivots and spherical joint coordinates live in the link's
*centre-of-mass* frame; a spherical joint's quaternion ``q`` and rate ``w`` satisfy
``R_com = L_parent · R_inertial · R(q)`` and ``ω_child − ω_parent = R_com · w``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from mbh._adapters.pybullet_adapter.build import PybulletModel, _TreeJoint
from mbh._adapters.pybullet_adapter.quiet import pybullet
from mbh._harness.model.mechanism import Mechanism
from mbh._harness.model.trajectory import BodyStates

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


def _link_poses(model: PybulletModel, uid: int, client: int) -> dict[int, _Pose] | None:
    """Body index → :class:`_Pose` read straight from Bullet's link states (ground as -1), for the
    loads applied before every step: one ``getLinkStates`` call and one vectorised rotation
    conversion, without the quaternion round trip of :func:`_read_states` (which costs ~60 µs a
    step on four bodies, measured).  None when an orientation is not finite or not a unit
    quaternion (a blown-up state: the caller falls back to :func:`_read_states`)."""
    rows = pybullet.getLinkStates(uid, list(model.body_links), computeLinkVelocity=1,
                                  computeForwardKinematics=1, physicsClientId=client)
    quats = np.array([row[1] for row in rows], dtype=float)
    if not (np.all(np.isfinite(quats)) and np.all(np.abs(np.sum(quats * quats, axis=1) - 1) < 0.5)):
        return None
    rotations = Rotation.from_quat(quats).as_matrix() @ np.transpose(model.principal, (0, 2, 1))
    poses = {-1: _Pose(np.zeros(3), np.eye(3), np.zeros(3), np.zeros(3))}
    for index, row in enumerate(rows):
        poses[index] = _Pose(np.array(row[0]), rotations[index], np.array(row[6]),
                             np.array(row[7]))
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
# Body states <-> joint coordinates
# ----------------------------------------------------------------------------------------------

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
    if good.any():  # all bodies in one call each: the read-back runs once per sample
        body_rotations = (Rotation.from_quat(quats[good]).as_matrix()
                          @ np.transpose(model.principal[good], (0, 2, 1)))
        body_quats[good] = Rotation.from_matrix(body_rotations).as_quat(scalar_first=True)
    return BodyStates(position=np.array([row[0] for row in rows], dtype=float),
                      quaternion=body_quats,
                      velocity=np.array([row[6] for row in rows], dtype=float),
                      angular_velocity=np.array([row[7] for row in rows], dtype=float))
