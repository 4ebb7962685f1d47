"""Conversions between the harness's body states and Pinocchio's joint coordinates.

``body_states`` runs Pinocchio's forward kinematics; ``joint_state`` inverts it: Gauss–Newton on
the pose errors of every body (``pin.log6`` with its Jacobian ``pin.Jlog6``) for the
configuration, then a least-squares solve of the frame Jacobians for the velocity.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from mbh._adapters.pinocchio_adapter.build import PinocchioModel
from mbh._harness.model.trajectory import BodyStates

#: Pose error (m, rad) at which the configuration solve stops.  Measured floor on 6200 generated
#: mechanisms (mbh._harness.testing.strategies, sizes 1–3.6 m): at most 9.0e-16, so 11× margin.
POSE_TOL = 1e-14
#: Gauss–Newton iterations allowed for the configuration solve.
POSE_MAX_ITER = 50
#: Largest difference between the given body states and those of the solved joint state (m, 1,
#: m/s, rad/s).  Measured on the same mechanisms (speeds up to 12.7 m/s or rad/s): at most
#: 2.6e-14, so 38× margin.
ROUND_TRIP_TOL = 1e-12


class ConversionError(ValueError):
    """The body states cannot be written in the tree's joint coordinates."""


def body_states(pm: PinocchioModel, data: pin.Data, q: np.ndarray, v: np.ndarray,
                previous: np.ndarray | None = None) -> BodyStates:
    """Body states of joint state ``(q, v)``.

    Parameters
    ----------
    pm : PinocchioModel
    data : pin.Data
        Scratch data of ``pm.model``.
    q : ndarray, shape (nq,)
    v : ndarray, shape (nv,)
    previous : ndarray, shape (n_bodies, 4), optional
        Quaternions of the previous sample: each new one takes the sign closest to it, so the
        series is continuous.

    Returns
    -------
    BodyStates
        World CoM positions (m), scalar-first quaternions, CoM velocities (m/s) and angular
        velocities (rad/s, world axes).
    """
    model = pm.model
    pin.forwardKinematics(model, data, q, v)
    pin.updateFramePlacements(model, data)
    n = len(pm.body_frames)
    position, quaternion = np.empty((n, 3)), np.empty((n, 4))
    velocity, angular = np.empty((n, 3)), np.empty((n, 3))
    for index, frame in enumerate(pm.body_frames):
        pose = data.oMf[frame]
        twist = pin.getFrameVelocity(model, data, frame, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
        position[index] = pose.translation
        x, y, z, w = pin.Quaternion(pose.rotation).coeffs()
        quaternion[index] = (w, x, y, z)
        velocity[index] = twist.linear
        angular[index] = twist.angular
    if previous is not None:
        quaternion *= np.where(np.sum(quaternion * previous, axis=1) < 0.0, -1.0, 1.0)[:, None]
    return BodyStates(position, quaternion, velocity, angular)


def _rotation(quaternion: np.ndarray) -> np.ndarray:
    """Rotation matrix of a scalar-first unit quaternion, shape (3, 3)."""
    w, x, y, z = quaternion
    return pin.Quaternion(w, x, y, z).normalized().toRotationMatrix()


def _pose_errors(pm: PinocchioModel, data: pin.Data, q: np.ndarray, targets: list) -> tuple:
    """Stacked body pose errors log6(oMb(q)⁻¹·target) (shape (6 n_bodies,)) and their Jacobian."""
    model = pm.model
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    errors, jacobians = [], []
    for frame, target in zip(pm.body_frames, targets):
        gap = data.oMf[frame].actInv(target)
        errors.append(pin.log6(gap).vector)
        local = frame_jacobian(model, data, frame, pin.ReferenceFrame.LOCAL)
        jacobians.append(-pin.Jlog6(gap.inverse()) @ local)
    return np.concatenate(errors), np.vstack(jacobians)


def frame_jacobian(model: pin.Model, data: pin.Data, frame: int, reference) -> np.ndarray:
    """``pin.getFrameJacobian`` as shape (6, nv) always: the binding returns a 1-D array of 6 when
    the model has a single degree of freedom (a one-joint tree)."""
    return np.reshape(pin.getFrameJacobian(model, data, frame, reference), (6, model.nv))


def joint_state(pm: PinocchioModel, data: pin.Data, states: BodyStates) -> tuple:
    """Joint coordinates reproducing ``states``.

    Parameters
    ----------
    pm : PinocchioModel
    data : pin.Data
        Scratch data of ``pm.model``.
    states : BodyStates
        Body states in the mechanism's body order.

    Returns
    -------
    q : ndarray, shape (nq,)
    v : ndarray, shape (nv,)

    Raises
    ------
    ConversionError
        If the poses are not reachable by the tree's joints (pose error above :data:`POSE_TOL`
        after :data:`POSE_MAX_ITER` iterations) or the solved state does not reproduce
        ``states`` to :data:`ROUND_TRIP_TOL`.
    """
    model = pm.model
    targets = [pin.SE3(_rotation(quat), pos)
               for quat, pos in zip(states.quaternion, states.position)]
    q = pin.neutral(model)
    for _ in range(POSE_MAX_ITER):
        error, jacobian = _pose_errors(pm, data, q, targets)
        if np.max(np.abs(error)) <= POSE_TOL:
            break
        step = np.linalg.lstsq(jacobian, -error, rcond=None)[0]
        q = pin.integrate(model, q, step)
    else:
        raise ConversionError(f"body poses not reachable in joint coordinates: pose error "
                              f"{np.max(np.abs(error)):.3g} after {POSE_MAX_ITER} iterations")
    twists = np.hstack([states.velocity, states.angular_velocity]).ravel()
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    jacobian = np.vstack([frame_jacobian(model, data, frame,
                                               pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
                          for frame in pm.body_frames])
    v = np.linalg.lstsq(jacobian, twists, rcond=None)[0]
    _check_round_trip(pm, data, q, v, states)
    return q, v


def _check_round_trip(pm: PinocchioModel, data: pin.Data, q: np.ndarray, v: np.ndarray,
                      states: BodyStates) -> None:
    """Raise a ConversionError unless ``(q, v)`` reproduces ``states`` to :data:`ROUND_TRIP_TOL`."""
    back = body_states(pm, data, q, v, states.quaternion)
    worst = max(np.max(np.abs(getattr(back, name) - getattr(states, name)))
                for name in ("position", "quaternion", "velocity", "angular_velocity"))
    if worst > ROUND_TRIP_TOL:
        raise ConversionError(f"joint coordinates reproduce the body states only to {worst:.3g} "
                              f"(tolerance {ROUND_TRIP_TOL:g}): not representable by the tree")
