"""Body kinematics in absolute coordinates: points and vectors fixed in a body, their Jacobians
with respect to the body's coordinates, and their velocity-squared acceleration terms.

Two coordinate sets (Frączek & Wojtyra 2009, §1.2, Rouvinen 2003, ch. 2):

* planar, ``NC = 3``: q_b = (x, y, φ); A(φ) the planar rotation; ∂(A ū)/∂φ = Ω A ū (Frączek & Wojtyra 2009, eq. 1.19).
* spatial, ``NC = 7``: q_b = (R, θ0..θ3) with Euler parameters; A(θ) of Rouvinen 2003, eq. 5 written as
  A = (2θ0² − 1) I + 2(θ̄θ̄ᵀ + θ0 θ̃̄).  (The seed's eq. 5 prints the diagonal as
  2(θ2² + θ3²) − 1; with θᵀθ = 1 the correct entry is 1 − 2(θ2² + θ3²), which this form gives.)

The Jacobians are the exact derivatives of these polynomial expressions, valid also off the
normalisation manifold, so that they can be checked by finite differences anywhere.  On the
manifold they equal the seed's −A ũ̄ Ḡ form (Rouvinen 2003, table 1, eq. 28).

The compiled kernels take these quantities as tuples (x, y, z) of scalars, not as arrays: a
helper writing into a scratch array made every row of Φ_q and γ cost several times its arithmetic
(a spatial slider-crank's γ 2.99 µs, its six DOT_VV rows 1.5 µs of it; the same rows written
with tuples 0.08 µs), presumably because the compiler must assume that a scratch array may alias
q and q̇ and so reloads them after every store.  Jacobians are added straight into the rows of
Φ_q (:func:`add_rotate_jacobian`, :func:`add_point_jacobian`, :func:`add_point_block`); the
force kernels of :mod:`mbh._adapters.inhouse.formulations.dynamics` follow the same rule.  All are inlined into
their compiled callers (numba's ``inline=`` with the cost model of
:mod:`~mbh._adapters.inhouse.numerics.inlining`, which leaves out only a kernel Python calls by
itself, compiled alone): a call of a separately compiled function with array
arguments costs more than these few flops (its arguments' reference counts, atomic updates, are
changed on entry and exit).

All functions are numba-compiled; ``body < 0`` denotes ground (the world frame), whose points and
vectors are constant.  Vectors are always 3-vectors (planar ones have z = 0).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from mbh._adapters.inhouse.numerics.inlining import into_compiled_callers

PLANAR_NC = 3
SPATIAL_NC = 7


@njit(cache=True, inline=into_compiled_callers)
def rotate_xyz(q, nc, body, u):
    """World vector A_b ū as a tuple (x, y, z)."""
    if body < 0:
        return u[0], u[1], u[2]
    k = body * nc
    if nc == PLANAR_NC:
        c, s = np.cos(q[k + 2]), np.sin(q[k + 2])
        return c * u[0] - s * u[1], s * u[0] + c * u[1], u[2]
    t0, t1, t2, t3 = q[k + 3], q[k + 4], q[k + 5], q[k + 6]
    dot = t1 * u[0] + t2 * u[1] + t3 * u[2]
    a = 2.0 * t0 * t0 - 1.0
    return (a * u[0] + 2.0 * t1 * dot + 2.0 * t0 * (t2 * u[2] - t3 * u[1]),
            a * u[1] + 2.0 * t2 * dot + 2.0 * t0 * (t3 * u[0] - t1 * u[2]),
            a * u[2] + 2.0 * t3 * dot + 2.0 * t0 * (t1 * u[1] - t2 * u[0]))


@njit(cache=True, inline=into_compiled_callers)
def _with_origin(x, y, z, coordinates, nc, body):
    """(x, y, z) plus the body's origin entries of ``coordinates`` (r_b of q, or ṙ_b of q̇);
    unchanged for the ground (body < 0)."""
    if body < 0:
        return x, y, z
    k = body * nc
    if nc == SPATIAL_NC:
        return x + coordinates[k], y + coordinates[k + 1], z + coordinates[k + 2]
    return x + coordinates[k], y + coordinates[k + 1], z


@njit(cache=True, inline=into_compiled_callers)
def point_xyz(q, nc, body, u):
    """World position r_b + A_b ū of a body point as a tuple (x, y, z)  (Rouvinen 2003, eq. 1)."""
    x, y, z = rotate_xyz(q, nc, body, u)
    return _with_origin(x, y, z, q, nc, body)


@njit(cache=True, inline=into_compiled_callers)
def _planar_rotate_column(q, k, u):
    """∂(A ū)/∂φ = Ω A ū (Frączek & Wojtyra 2009, eq. 1.19) of the planar body whose coordinates start at q[k],
    a tuple (3)."""
    c, s = np.cos(q[k + 2]), np.sin(q[k + 2])
    return -s * u[0] - c * u[1], c * u[0] - s * u[1], 0.0


@njit(cache=True, inline=into_compiled_callers)
def _spatial_rotate_columns(q, k, u):
    """∂(A ū)/∂θ0 … ∂(A ū)/∂θ3 of the spatial body whose coordinates start at q[k], four
    tuples (3): ∂/∂θ0 = 4θ0 ū + 2 θ̄ × ū and ∂/∂θk = 2 e_k (θ̄·ū) + 2 θ̄ ū_k + 2 θ0 (e_k × ū)."""
    t0, t1, t2, t3 = q[k + 3], q[k + 4], q[k + 5], q[k + 6]
    dot = t1 * u[0] + t2 * u[1] + t3 * u[2]
    return ((4.0 * t0 * u[0] + 2.0 * (t2 * u[2] - t3 * u[1]),
             4.0 * t0 * u[1] + 2.0 * (t3 * u[0] - t1 * u[2]),
             4.0 * t0 * u[2] + 2.0 * (t1 * u[1] - t2 * u[0])),
            (2.0 * t1 * u[0] + 2.0 * dot, 2.0 * t2 * u[0] - 2.0 * t0 * u[2],
             2.0 * t3 * u[0] + 2.0 * t0 * u[1]),
            (2.0 * t1 * u[1] + 2.0 * t0 * u[2], 2.0 * t2 * u[1] + 2.0 * dot,
             2.0 * t3 * u[1] - 2.0 * t0 * u[0]),
            (2.0 * t1 * u[2] - 2.0 * t0 * u[1], 2.0 * t2 * u[2] + 2.0 * t0 * u[0],
             2.0 * t3 * u[2] + 2.0 * dot))


@njit(cache=True, inline=into_compiled_callers)
def add_rotate_jacobian(jac, r, q, nc, body, u, w, sign):
    """jac[r, body's columns] += sign · wᵀ ∂(A_b ū)/∂q_b, w a tuple (3); nothing for the ground
    and nothing on the translation columns."""
    if body < 0:
        return
    k = body * nc
    if nc == PLANAR_NC:
        column = _planar_rotate_column(q, k, u)
        jac[r, k + 2] += sign * (w[0] * column[0] + w[1] * column[1])
        return
    columns = _spatial_rotate_columns(q, k, u)
    for c in range(4):
        column = columns[c]
        jac[r, k + 3 + c] += sign * (w[0] * column[0] + w[1] * column[1] + w[2] * column[2])


@njit(cache=True, inline=into_compiled_callers)
def add_point_jacobian(jac, r, q, nc, body, u, w, sign):
    """jac[r, body's columns] += sign · wᵀ ∂(r_b + A_b ū)/∂q_b, w a tuple (3)."""
    if body < 0:
        return
    k = body * nc
    jac[r, k] += sign * w[0]
    jac[r, k + 1] += sign * w[1]
    if nc == SPATIAL_NC:
        jac[r, k + 2] += sign * w[2]
    add_rotate_jacobian(jac, r, q, nc, body, u, w, sign)


@njit(cache=True, inline=into_compiled_callers)
def add_point_block(jac, r, q, nc, body, u, sign):
    """jac[r:r + d, body's columns] += sign · ∂(r_b + A_b ū)/∂q_b, the d = 2 (planar) or 3
    (spatial) rows of a body point's position."""
    if body < 0:
        return
    k = body * nc
    if nc == PLANAR_NC:
        column = _planar_rotate_column(q, k, u)
        for x in range(2):
            jac[r + x, k + x] += sign
            jac[r + x, k + 2] += sign * column[x]
        return
    columns = _spatial_rotate_columns(q, k, u)
    for x in range(3):
        jac[r + x, k + x] += sign
        for c in range(4):
            jac[r + x, k + 3 + c] += sign * columns[c][x]


@njit(cache=True, inline=into_compiled_callers)
def rotate_rate_xyz(q, v, nc, body, u):
    """d(A_b ū)/dt = ∂(A_b ū)/∂q_b · q̇_b as a tuple (x, y, z).

    Planar: φ̇ Ω A ū.  Spatial: 4θ0θ̇0 ū + 2θ̇0 θ̄ × ū + 2(θ̄̇ (θ̄·ū) + θ̄ (θ̄̇·ū) + θ0 θ̄̇ × ū).
    """
    if body < 0:
        return 0.0, 0.0, 0.0
    k = body * nc
    if nc == PLANAR_NC:
        x, y, _ = rotate_xyz(q, nc, body, u)
        rate = v[k + 2]
        return -rate * y, rate * x, 0.0
    t0, t1, t2, t3 = q[k + 3], q[k + 4], q[k + 5], q[k + 6]
    d0, d1, d2, d3 = v[k + 3], v[k + 4], v[k + 5], v[k + 6]
    dot = t1 * u[0] + t2 * u[1] + t3 * u[2]
    rate_dot = d1 * u[0] + d2 * u[1] + d3 * u[2]
    return (d0 * (4.0 * t0 * u[0] + 2.0 * (t2 * u[2] - t3 * u[1]))
            + 2.0 * (d1 * dot + t1 * rate_dot + t0 * (d2 * u[2] - d3 * u[1])),
            d0 * (4.0 * t0 * u[1] + 2.0 * (t3 * u[0] - t1 * u[2]))
            + 2.0 * (d2 * dot + t2 * rate_dot + t0 * (d3 * u[0] - d1 * u[2])),
            d0 * (4.0 * t0 * u[2] + 2.0 * (t1 * u[1] - t2 * u[0]))
            + 2.0 * (d3 * dot + t3 * rate_dot + t0 * (d1 * u[1] - d2 * u[0])))


@njit(cache=True, inline=into_compiled_callers)
def point_rate_xyz(q, v, nc, body, u):
    """Velocity ṙ_b + d(A_b ū)/dt of a body point as a tuple (x, y, z)."""
    x, y, z = rotate_rate_xyz(q, v, nc, body, u)
    return _with_origin(x, y, z, v, nc, body)


@njit(cache=True, inline=into_compiled_callers)
def rotate_quadratic_xyz(q, v, nc, body, u):
    """The part of d²(A_b ū)/dt² without q̈ as a tuple (x, y, z).

    Planar: −A ū φ̇².  Spatial: A(θ) is quadratic in θ, so the term is 2 A_q(θ̇) ū with
    A_q(θ̇) = 2θ̇0² I + 2 θ̄̇θ̄̇ᵀ + 2 θ̇0 θ̄̇~ (equivalent to Rouvinen 2003, eq. 31–33 on the manifold).
    """
    if body < 0:
        return 0.0, 0.0, 0.0
    k = body * nc
    if nc == PLANAR_NC:
        w2 = v[k + 2] * v[k + 2]
        x, y, _ = rotate_xyz(q, nc, body, u)
        return -x * w2, -y * w2, 0.0
    d0, d1, d2, d3 = v[k + 3], v[k + 4], v[k + 5], v[k + 6]
    dot = d1 * u[0] + d2 * u[1] + d3 * u[2]
    return (4.0 * (d0 * d0 * u[0] + d1 * dot + d0 * (d2 * u[2] - d3 * u[1])),
            4.0 * (d0 * d0 * u[1] + d2 * dot + d0 * (d3 * u[0] - d1 * u[2])),
            4.0 * (d0 * d0 * u[2] + d3 * dot + d0 * (d1 * u[1] - d2 * u[0])))
