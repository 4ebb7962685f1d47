"""Body kinematics in absolute coordinates: points and vectors fixed in a body, their Jacobians
with respect to the body's coordinates, and their velocity-squared acceleration terms.

Two coordinate sets (seed 000 §1.2, seed 002 ch. 2):

* planar, ``NC = 3``: q_b = (x, y, φ); A(φ) the planar rotation; ∂(A ū)/∂φ = Ω A ū (000 eq. 1.19).
* spatial, ``NC = 7``: q_b = (R, θ0..θ3) with Euler parameters; A(θ) of 002 eq. 5 written as
  A = (2θ0² − 1) I + 2(θ̄θ̄ᵀ + θ0 θ̃̄).  (The seed's eq. 5 prints the diagonal as
  2(θ2² + θ3²) − 1; with θᵀθ = 1 the correct entry is 1 − 2(θ2² + θ3²), which this form gives.)

The Jacobians are the exact derivatives of these polynomial expressions, valid also off the
normalisation manifold, so that they can be checked by finite differences anywhere.  On the
manifold they equal the seed's −A ũ̄ Ḡ form (002 table 1, eq. 28).

Each function has an ``_into`` form that writes into arrays the caller owns (the compiled kernels
reuse one scratch buffer per call instead of allocating small arrays per primitive, which was
most of their cost); the ones the force kernels use also have an allocating form that wraps it
(:func:`rotate`, :func:`point`, :func:`point_rate`).  All are inlined into their callers
(``inline="always"``): a call of a separately compiled function with array arguments costs more
than these few flops (its arguments' reference counts, atomic updates, are changed on entry and
exit).

All functions are numba-compiled; ``body < 0`` denotes ground (the world frame), whose points and
vectors are constant.  Vectors are always 3-vectors (planar ones have z = 0).
"""

from __future__ import annotations

import numpy as np
from numba import njit

PLANAR_NC = 3
SPATIAL_NC = 7


@njit(cache=True, inline="always")
def rotate_into(out, q, nc, body, u):
    """out[:] = world vector A_b ū, out shape (3,)."""
    if body < 0:
        for x in range(3):
            out[x] = u[x]
        return
    k = body * nc
    if nc == PLANAR_NC:
        c, s = np.cos(q[k + 2]), np.sin(q[k + 2])
        out[0] = c * u[0] - s * u[1]
        out[1] = s * u[0] + c * u[1]
        out[2] = u[2]
        return
    t0, t1, t2, t3 = q[k + 3], q[k + 4], q[k + 5], q[k + 6]
    dot = t1 * u[0] + t2 * u[1] + t3 * u[2]
    a = 2.0 * t0 * t0 - 1.0
    out[0] = a * u[0] + 2.0 * t1 * dot + 2.0 * t0 * (t2 * u[2] - t3 * u[1])
    out[1] = a * u[1] + 2.0 * t2 * dot + 2.0 * t0 * (t3 * u[0] - t1 * u[2])
    out[2] = a * u[2] + 2.0 * t3 * dot + 2.0 * t0 * (t1 * u[1] - t2 * u[0])


@njit(cache=True, inline="always")
def rotate(q, nc, body, u):
    """World vector A_b ū, shape (3,)."""
    out = np.empty(3)
    rotate_into(out, q, nc, body, u)
    return out


@njit(cache=True, inline="always")
def _add_origin(out, coordinates, nc, body):
    """out[:] += the body's origin entries of ``coordinates`` (r_b of q, or ṙ_b of q̇); nothing
    for the ground (body < 0)."""
    if body >= 0:
        k = body * nc
        out[0] += coordinates[k]
        out[1] += coordinates[k + 1]
        if nc == SPATIAL_NC:
            out[2] += coordinates[k + 2]


@njit(cache=True, inline="always")
def point_into(out, q, nc, body, u):
    """out[:] = world position r_b + A_b ū of a body point, out shape (3,)  (002 eq. 1)."""
    rotate_into(out, q, nc, body, u)
    _add_origin(out, q, nc, body)


@njit(cache=True, inline="always")
def point(q, nc, body, u):
    """World position r_b + A_b ū of a body point, shape (3,)  (002 eq. 1)."""
    out = np.empty(3)
    point_into(out, q, nc, body, u)
    return out


@njit(cache=True, inline="always")
def rotate_jacobian_into(jac, q, nc, body, u):
    """jac[:] = ∂(A_b ū)/∂q_b, jac shape (3, nc); translation columns are zero."""
    jac[:] = 0.0
    if body < 0:
        return
    k = body * nc
    if nc == PLANAR_NC:
        c, s = np.cos(q[k + 2]), np.sin(q[k + 2])
        jac[0, 2] = -s * u[0] - c * u[1]
        jac[1, 2] = c * u[0] - s * u[1]
        return
    t0, t1, t2, t3 = q[k + 3], q[k + 4], q[k + 5], q[k + 6]
    dot = t1 * u[0] + t2 * u[1] + t3 * u[2]
    # ∂/∂θ0 = 4θ0 ū + 2 θ̄ × ū
    jac[0, 3] = 4.0 * t0 * u[0] + 2.0 * (t2 * u[2] - t3 * u[1])
    jac[1, 3] = 4.0 * t0 * u[1] + 2.0 * (t3 * u[0] - t1 * u[2])
    jac[2, 3] = 4.0 * t0 * u[2] + 2.0 * (t1 * u[1] - t2 * u[0])
    # ∂/∂θk = 2 e_k (θ̄·ū) + 2 θ̄ ū_k + 2 θ0 (e_k × ū)
    tb = (t1, t2, t3)
    for col in range(3):
        for row in range(3):
            jac[row, 4 + col] = 2.0 * tb[row] * u[col]
        jac[col, 4 + col] += 2.0 * dot
    jac[1, 4] -= 2.0 * t0 * u[2]
    jac[2, 4] += 2.0 * t0 * u[1]
    jac[0, 5] += 2.0 * t0 * u[2]
    jac[2, 5] -= 2.0 * t0 * u[0]
    jac[0, 6] -= 2.0 * t0 * u[1]
    jac[1, 6] += 2.0 * t0 * u[0]


@njit(cache=True, inline="always")
def point_jacobian_into(jac, q, nc, body, u):
    """jac[:] = ∂(r_b + A_b ū)/∂q_b, jac shape (3, nc)."""
    rotate_jacobian_into(jac, q, nc, body, u)
    if body >= 0:
        jac[0, 0] = 1.0
        jac[1, 1] = 1.0
        if nc == SPATIAL_NC:
            jac[2, 2] = 1.0


@njit(cache=True, inline="always")
def rotate_rate_into(out, q, v, nc, body, u):
    """out[:] = d(A_b ū)/dt = ∂(A_b ū)/∂q_b · q̇_b, out shape (3,), written out from the
    Jacobian of :func:`rotate_jacobian_into` times q̇_b.

    Planar: φ̇ Ω A ū.  Spatial: 4θ0θ̇0 ū + 2θ̇0 θ̄ × ū + 2(θ̄̇ (θ̄·ū) + θ̄ (θ̄̇·ū) + θ0 θ̄̇ × ū).
    """
    if body < 0:
        for x in range(3):
            out[x] = 0.0
        return
    k = body * nc
    if nc == PLANAR_NC:
        rotate_into(out, q, nc, body, u)
        rate, along_x = v[k + 2], out[0]
        out[0] = -rate * out[1]
        out[1] = rate * along_x
        out[2] = 0.0
        return
    t0, t1, t2, t3 = q[k + 3], q[k + 4], q[k + 5], q[k + 6]
    d0, d1, d2, d3 = v[k + 3], v[k + 4], v[k + 5], v[k + 6]
    dot = t1 * u[0] + t2 * u[1] + t3 * u[2]
    rate_dot = d1 * u[0] + d2 * u[1] + d3 * u[2]
    out[0] = d0 * (4.0 * t0 * u[0] + 2.0 * (t2 * u[2] - t3 * u[1])) \
        + 2.0 * (d1 * dot + t1 * rate_dot + t0 * (d2 * u[2] - d3 * u[1]))
    out[1] = d0 * (4.0 * t0 * u[1] + 2.0 * (t3 * u[0] - t1 * u[2])) \
        + 2.0 * (d2 * dot + t2 * rate_dot + t0 * (d3 * u[0] - d1 * u[2]))
    out[2] = d0 * (4.0 * t0 * u[2] + 2.0 * (t1 * u[1] - t2 * u[0])) \
        + 2.0 * (d3 * dot + t3 * rate_dot + t0 * (d1 * u[1] - d2 * u[0]))


@njit(cache=True, inline="always")
def point_rate_into(out, q, v, nc, body, u):
    """out[:] = velocity ṙ_b + d(A_b ū)/dt of a body point, out shape (3,)."""
    rotate_rate_into(out, q, v, nc, body, u)
    _add_origin(out, v, nc, body)


@njit(cache=True, inline="always")
def point_rate(q, v, nc, body, u):
    """Velocity of a body point, shape (3,)."""
    out = np.empty(3)
    point_rate_into(out, q, v, nc, body, u)
    return out


@njit(cache=True, inline="always")
def rotate_quadratic_into(out, q, v, nc, body, u):
    """out[:] = the part of d²(A_b ū)/dt² without q̈, out shape (3,).

    Planar: −A ū φ̇².  Spatial: A(θ) is quadratic in θ, so the term is 2 A_q(θ̇) ū with
    A_q(θ̇) = 2θ̇0² I + 2 θ̄̇θ̄̇ᵀ + 2 θ̇0 θ̄̇~ (equivalent to 002 eq. 31–33 on the manifold).
    """
    if body < 0:
        out[:] = 0.0
        return
    k = body * nc
    if nc == PLANAR_NC:
        w2 = v[k + 2] * v[k + 2]
        rotate_into(out, q, nc, body, u)
        out[0] = -out[0] * w2
        out[1] = -out[1] * w2
        out[2] = 0.0
        return
    d0, d1, d2, d3 = v[k + 3], v[k + 4], v[k + 5], v[k + 6]
    dot = d1 * u[0] + d2 * u[1] + d3 * u[2]
    out[0] = 4.0 * (d0 * d0 * u[0] + d1 * dot + d0 * (d2 * u[2] - d3 * u[1]))
    out[1] = 4.0 * (d0 * d0 * u[1] + d2 * dot + d0 * (d3 * u[0] - d1 * u[2]))
    out[2] = 4.0 * (d0 * d0 * u[2] + d3 * dot + d0 * (d1 * u[1] - d2 * u[0]))
