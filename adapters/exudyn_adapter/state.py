"""Conversions between the harness's body states and Exudyn's node coordinates: Euler-parameter
rates of a world angular velocity (initial velocities of ``NodeRigidBodyEP``) and sign-continuous
quaternions of the sensed rotation matrices.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation


def _quaternion_rate(quaternion: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """Euler-parameter rates θ̇ = ½ [0, ω] ⊗ θ for a world angular velocity, shape (4,)."""
    w, x, y, z = quaternion
    wx, wy, wz = omega
    return 0.5 * np.array([-wx * x - wy * y - wz * z,
                           wx * w + wy * z - wz * y,
                           -wx * z + wy * w + wz * x,
                           wx * y - wy * x + wz * w])


def _quaternions(rotations: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Scalar-first quaternions of ``rotations`` (shape (n, 3, 3)), signs continuous from
    ``reference`` (shape (4,)); shape (n, 4)."""
    quats = Rotation.from_matrix(rotations).as_quat(scalar_first=True)
    previous = reference
    for i, quat in enumerate(quats):
        if np.dot(quat, previous) < 0:
            quats[i] = -quat
        previous = quats[i]
    return quats
