"""Named outputs computed from body states through the neutral model (docs/design.md, rule 2).

Joint coordinates are measured from the joints' body-frame geometry: the rotation of a revolute or
cylindrical joint is the angle from ``h = A₁ n̄₁`` to ``f = A₂ n̄₂`` about ``a = A₁ ā₁``
(zero in the reference configuration, right-hand rule); the slide of a prismatic or translational
joint is ``a · (p₂ − p₁)``.  A body point p̄ (body frame) is at ``r + A p̄`` and moves with
``v + ω × A p̄`` (ω in world axes, as the trajectory stores it).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from mbh._harness.model.mechanism import GROUND, Joint, Mechanism
from mbh._harness.model.trajectory import Trajectory


def body_rotations(quaternions: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) from scalar-first quaternions (..., 4), normalised.

    A non-finite or zero quaternion (a diverged engine state) gives a NaN matrix instead of an
    exception, so the metrics of a blown-up run stay computable.
    """
    flat = np.asarray(quaternions, dtype=float).reshape(-1, 4)
    norm = np.linalg.norm(flat, axis=1)
    valid = np.isfinite(norm) & (norm > 0.0)
    matrices = np.full((flat.shape[0], 3, 3), np.nan)
    if np.any(valid):
        matrices[valid] = Rotation.from_quat(flat[valid], scalar_first=True).as_matrix()
    return matrices.reshape(*np.shape(quaternions)[:-1], 3, 3)


def rotation_between(first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """Angle (rad, in [0, π]) of the rotation from one orientation to the other, shape (...), from
    scalar-first quaternions (..., 4) of either sign and any positive norm; NaN where either is
    not finite or zero (as :func:`body_rotations` gives a NaN matrix there)."""
    a = np.asarray(first, dtype=float).reshape(-1, 4)
    b = np.asarray(second, dtype=float).reshape(-1, 4)
    norms = np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1)
    valid = np.isfinite(norms) & (norms > 0.0)
    angles = np.full(a.shape[0], np.nan)
    if np.any(valid):
        relative = (Rotation.from_quat(a[valid], scalar_first=True).inv()
                    * Rotation.from_quat(b[valid], scalar_first=True))
        angles[valid] = relative.magnitude()
    return angles.reshape(np.shape(first)[:-1])


def wrap_angle(angle):
    """Angle(s) wrapped to (−π, π], rad."""
    return np.pi - np.mod(np.pi - angle, 2.0 * np.pi)


def body_frame(mech: Mechanism, body: str, positions, rotations):
    """World position (..., 3) and rotation (..., 3, 3) of ``body`` (ground: the world frame)."""
    if body == GROUND:
        shape = positions.shape[:-2]
        return np.zeros((*shape, 3)), np.broadcast_to(np.eye(3), (*shape, 3, 3))
    index = mech.body_index(body)
    return positions[..., index, :], rotations[..., index, :, :]


def joint_angle(mech: Mechanism, joint: Joint, positions, rotations) -> np.ndarray:
    """Wrapped joint rotation in (−π, π], shape (...,), for states (..., n_bodies, ·)."""
    _, rot1 = body_frame(mech, joint.body1, positions, rotations)
    _, rot2 = body_frame(mech, joint.body2, positions, rotations)
    h = rot1 @ joint.normal1
    f = rot2 @ joint.normal2
    a = rot1 @ joint.axis1
    return np.arctan2(np.einsum("...i,...i", np.cross(h, f), a), np.einsum("...i,...i", h, f))


def joint_slide(mech: Mechanism, joint: Joint, positions, rotations) -> np.ndarray:
    """Joint translation a · (p₂ − p₁) minus its reference value, shape (...,), m."""
    pos1, rot1 = body_frame(mech, joint.body1, positions, rotations)
    pos2, rot2 = body_frame(mech, joint.body2, positions, rotations)
    p1 = pos1 + rot1 @ joint.point1
    p2 = pos2 + rot2 @ joint.point2
    return np.einsum("...i,...i", rot1 @ joint.axis1, p2 - p1)


def unwrap_from_start(angles: np.ndarray) -> np.ndarray:
    """Unwrapped angle series relative to its first sample, shape (n_samples,)."""
    unwrapped = np.unwrap(angles)
    return unwrapped - unwrapped[0]


def output_series(mech: Mechanism, trajectory: Trajectory, name: str) -> np.ndarray:
    """The named output at every sample, shape (n_samples,).

    Joint angles are unwrapped, so samples must be dense enough that the joint turns less than π
    between two of them.
    """
    output = mech.output(name)
    if trajectory.n_samples == 0:
        return np.zeros(0)
    if output.kind in ("position", "velocity"):
        data = trajectory.position if output.kind == "position" else trajectory.velocity
        return data[:, mech.body_index(output.target), output.component].copy()
    rotations = body_rotations(trajectory.quaternion)
    if output.kind in ("point_position", "point_velocity"):
        return point_state(mech, trajectory, output.target, output.point, rotations,
                           velocity=output.kind == "point_velocity")[:, output.component]
    joint = mech.joint(output.target)
    if output.kind == "joint_position":
        slide = joint_slide(mech, joint, trajectory.position, rotations)
        return slide - slide[0]
    angle = unwrap_from_start(joint_angle(mech, joint, trajectory.position, rotations))
    if output.kind == "joint_angle":
        return angle + output.offset
    return joint_rate(mech, joint, trajectory.angular_velocity, rotations)


def point_state(mech: Mechanism, trajectory: Trajectory, body: str, point: np.ndarray,
                rotations: np.ndarray, velocity: bool) -> np.ndarray:
    """World position ``r + A p̄`` (m) or velocity ``v + ω × A p̄`` (m/s) of a body point.

    Parameters
    ----------
    body : str
        A moving body's name.
    point : ndarray, shape (3,)
        The point in the body frame, m.
    rotations : ndarray, shape (n_samples, n_bodies, 3, 3)
        Body rotations (body → world) at every sample.
    velocity : bool
        Velocity instead of position.

    Returns
    -------
    ndarray, shape (n_samples, 3)
    """
    index = mech.body_index(body)
    arm = rotations[:, index] @ point
    if velocity:
        return trajectory.velocity[:, index] + np.cross(trajectory.angular_velocity[:, index], arm)
    return trajectory.position[:, index] + arm


def joint_rate(mech: Mechanism, joint: Joint, angular_velocity, rotations) -> np.ndarray:
    """Relative angular velocity of body2 about the joint axis, shape (...,), rad/s."""
    def omega(body):
        if body == GROUND:
            return np.zeros(angular_velocity.shape[:-2] + (3,))
        return angular_velocity[..., mech.body_index(body), :]
    _, rot1 = body_frame(mech, joint.body1, np.zeros(angular_velocity.shape), rotations)
    axis = rot1 @ joint.axis1
    return np.einsum("...i,...i", omega(joint.body2) - omega(joint.body1), axis)
