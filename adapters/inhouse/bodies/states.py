"""Conversions between absolute coordinates (q, q̇) and world body states.

Planar: (x, y, φ) ↔ position (x, y, 0), quaternion (cos φ/2, 0, 0, sin φ/2), ω = (0, 0, φ̇).
Spatial: (R, θ) ↔ position R, quaternion θ (normalised), and ω = 2 E θ̇ with
E = [−θ̄, θ̃̄ + θ0 I] (world axes; the world-frame counterpart of Rouvinen 2003, eq. 28), inverted on the
manifold by θ̇ = ½ Eᵀ ω.
"""

from __future__ import annotations

import numpy as np

from mbh._adapters.inhouse.bodies.constraints import Layout
from mbh._harness.model.trajectory import BodyStates


def _e_matrix(theta: np.ndarray) -> np.ndarray:
    """E(θ), shape (..., 3, 4), for θ of shape (..., 4)."""
    t0, t1, t2, t3 = np.moveaxis(theta, -1, 0)
    return np.stack([
        np.stack([-t1, t0, -t3, t2], axis=-1),
        np.stack([-t2, t3, t0, -t1], axis=-1),
        np.stack([-t3, -t2, t1, t0], axis=-1),
    ], axis=-2)


def body_states(layout: Layout, q: np.ndarray, v: np.ndarray) -> BodyStates:
    """World body states from absolute coordinates q, q̇ of shape (..., n).

    A leading sample axis converts a whole run at once; the result's arrays then have shape
    (..., n_bodies, 3) and (..., n_bodies, 4).
    """
    lead = q.shape[:-1]
    blocks_q = q.reshape(*lead, layout.n_bodies, layout.nc)
    blocks_v = v.reshape(*lead, layout.n_bodies, layout.nc)
    zeros = np.zeros(blocks_q.shape[:-1])
    if layout.planar:
        position = np.stack([blocks_q[..., 0], blocks_q[..., 1], zeros], axis=-1)
        half = 0.5 * blocks_q[..., 2]
        quaternion = np.stack([np.cos(half), zeros, zeros, np.sin(half)], axis=-1)
        velocity = np.stack([blocks_v[..., 0], blocks_v[..., 1], zeros], axis=-1)
        omega = np.stack([zeros, zeros, blocks_v[..., 2]], axis=-1)
        return BodyStates(position, quaternion, velocity, omega)
    theta = blocks_q[..., 3:]
    theta = theta / np.linalg.norm(theta, axis=-1, keepdims=True)
    omega = 2.0 * np.einsum("...ij,...j->...i", _e_matrix(theta), blocks_v[..., 3:])
    return BodyStates(blocks_q[..., :3].copy(), theta, blocks_v[..., :3].copy(), omega)


def coordinates(layout: Layout, states: BodyStates) -> tuple[np.ndarray, np.ndarray]:
    """Absolute coordinates q, q̇ (each shape (n,)) from world body states.

    Planar states are read in the x–y plane (φ from the quaternion's z-rotation); a state that has
    left the plane is measured by the spatial metrics, not here.
    """
    if layout.planar:
        phi = 2.0 * np.arctan2(states.quaternion[:, 3], states.quaternion[:, 0])
        q = np.column_stack([states.position[:, :2], phi])
        v = np.column_stack([states.velocity[:, :2], states.angular_velocity[:, 2]])
        return q.ravel(), v.ravel()
    theta = states.quaternion / np.linalg.norm(states.quaternion, axis=1, keepdims=True)
    theta_dot = 0.5 * np.einsum("bji,bj->bi", _e_matrix(theta), states.angular_velocity)
    q = np.column_stack([states.position, theta])
    v = np.column_stack([states.velocity, theta_dot])
    return q.ravel(), v.ravel()
