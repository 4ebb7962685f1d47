"""Conversions between the harness's body states and MuJoCo's joint coordinates.

The initial body states become ``qpos`` (joint by joint, from each body's motion relative to its
tree parent) and ``qvel`` (least squares on the centre-of-mass Jacobians), checked by reading them
back; body states are read from ``xpos``/``xquat`` and the bodies' centre-of-mass velocities.
"""

from __future__ import annotations

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from mbh._adapters.mujoco_adapter.build import MujocoModel, _quat
from mbh._harness.model.mechanism import GROUND
from mbh._harness.model.trajectory import BodyStates

#: Largest allowed difference between the harness's initial state and MuJoCo's version of it.
INITIAL_TOLERANCE = 1e-12


def _angle_about(rotation: np.ndarray, axis: np.ndarray) -> float:
    """Angle (rad) of ``rotation`` (3×3), a rotation about unit ``axis``."""
    skew = rotation - rotation.T
    sine = 0.5 * axis @ np.array([skew[2, 1], skew[0, 2], skew[1, 0]])
    return float(np.arctan2(sine, 0.5 * (np.trace(rotation) - 1.0)))


def _joint_coordinates(model: mujoco.MjModel, body: int, rotation: np.ndarray,
                       translation: np.ndarray) -> np.ndarray:
    """``qpos`` entries of body ``body``'s joints for a given motion from the reference.

    Parameters
    ----------
    rotation : ndarray, shape (3, 3)
        Rotation of the child from its reference pose, in its reference frame.
    translation : ndarray, shape (3,)
        Displacement of the child's origin from its reference position, same frame, m.
    """
    start, count = model.body_jntadr[body], model.body_jntnum[body]
    coordinates, remaining = [], rotation
    for joint in range(start, start + count):
        kind, axis = model.jnt_type[joint], model.jnt_axis[joint]
        if kind == mujoco.mjtJoint.mjJNT_SLIDE:
            coordinates.append(axis @ translation)
        elif kind == mujoco.mjtJoint.mjJNT_BALL:
            coordinates.extend(_quat(remaining))
        elif joint + 1 < start + count and model.jnt_type[joint + 1] == mujoco.mjtJoint.mjJNT_HINGE:
            following = model.jnt_axis[joint + 1]
            moved = remaining @ following
            angle = np.arctan2(np.cross(axis, following) @ moved, following @ moved)
            coordinates.append(angle)
            remaining = Rotation.from_rotvec(-angle * axis).as_matrix() @ remaining
        else:
            coordinates.append(_angle_about(remaining, axis))
    return np.array(coordinates)


def _initial_qpos(built: MujocoModel, states: BodyStates) -> np.ndarray:
    """Joint coordinates that put every body at ``states``' pose, shape (nq,)."""
    mech, model = built.mechanism, built.model
    rotations = Rotation.from_quat(states.quaternion, scalar_first=True).as_matrix()
    qpos = model.qpos0.copy()
    for index, body in enumerate(mech.bodies):
        parent = built.tree.parent[body.name]
        if parent == GROUND:
            rot_p, pos_p = np.eye(3), np.zeros(3)
        else:
            rot_p, pos_p = rotations[mech.body_index(parent)], states.position[mech.body_index(parent)]
        mj_body = built.body_ids[index]
        frame = Rotation.from_quat(model.body_quat[mj_body], scalar_first=True).as_matrix()
        relative = frame.T @ rot_p.T @ rotations[index]
        shift = frame.T @ (rot_p.T @ (states.position[index] - pos_p) - model.body_pos[mj_body])
        address = model.jnt_qposadr[model.body_jntadr[mj_body]]
        coordinates = _joint_coordinates(model, mj_body, relative, shift)
        qpos[address:address + len(coordinates)] = coordinates
    return qpos


def _initial_qvel(built: MujocoModel, data: mujoco.MjData, states: BodyStates) -> np.ndarray:
    """Joint rates that reproduce ``states``' velocities (least squares on CoM Jacobians)."""
    model = built.model
    jacobians, targets = [], []
    for index, body in enumerate(built.body_ids):
        jacp, jacr = np.zeros((3, model.nv)), np.zeros((3, model.nv))
        mujoco.mj_jacBodyCom(model, data, jacp, jacr, body)
        jacobians += [jacp, jacr]
        targets += [states.velocity[index], states.angular_velocity[index]]
    solution, *_ = np.linalg.lstsq(np.vstack(jacobians), np.concatenate(targets), rcond=None)
    return solution


def _body_states(built: MujocoModel, model: mujoco.MjModel, data: mujoco.MjData,
                 previous: np.ndarray) -> BodyStates:
    """Body states from ``data.qpos``/``qvel`` (recomputes kinematics and CoM velocities).

    ``previous`` (n_bodies, 4) are the last reported quaternions: each new one takes the sign
    that keeps it on the same hemisphere.
    """
    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)
    mujoco.mj_comVel(model, data)
    ids = built.body_ids
    velocity = np.zeros((len(ids), 6))
    for row, body in zip(velocity, ids):
        mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_BODY, body, row, 0)
    quaternion = data.xquat[ids].copy()
    quaternion *= np.where(np.sum(quaternion * previous, axis=1) < 0.0, -1.0, 1.0)[:, None]
    return BodyStates(position=data.xpos[ids].copy(), quaternion=quaternion,
                      velocity=velocity[:, 3:], angular_velocity=velocity[:, :3])


def _state_mismatch(a: BodyStates, b: BodyStates) -> float:
    """Largest absolute difference between two sets of body states."""
    return max(float(np.max(np.abs(getattr(a, key) - getattr(b, key)), initial=0.0))
               for key in ("position", "quaternion", "velocity", "angular_velocity"))


def _start(built: MujocoModel, model: mujoco.MjModel, data: mujoco.MjData,
           states: BodyStates) -> BodyStates:
    """Set ``data`` to the harness's initial state; returns MuJoCo's own view of it.

    Raises
    ------
    RuntimeError
        If MuJoCo's body states differ from ``states`` by more than :data:`INITIAL_TOLERANCE`.
    """
    data.qpos[:] = _initial_qpos(built, states)
    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)
    data.qvel[:] = _initial_qvel(built, data, states)
    reached = _body_states(built, model, data, states.quaternion)
    mismatch = _state_mismatch(reached, states)
    if mismatch > INITIAL_TOLERANCE:
        raise RuntimeError(f"joint coordinates reproduce the initial body states only to "
                           f"{mismatch:.3g} (> {INITIAL_TOLERANCE:g})")
    return reached
