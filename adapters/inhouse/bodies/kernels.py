"""Compiled constraint kernels: Φ, Φ_q, Φ_t and γ for a table of primitive constraints.

Every joint of Rouvinen 2003, ch. 2 is composed of a handful of primitives (see
:mod:`mbh._adapters.inhouse.bodies.constraints`), stored row-wise in flat arrays so that one compiled loop
evaluates the whole system:

==========  ====  ==========================================================================
kind        rows  Φ
==========  ====  ==========================================================================
POINT       2|3   p_i(ū_i) − p_j(ū_j)                          (C^s, Rouvinen 2003, eq. 11; Frączek & Wojtyra 2009, eq. 1.35)
DOT_VV      1     (A_i ā_i)ᵀ(A_j ā_j)                           (C^d1, Rouvinen 2003, eq. 6–7)
DOT_VD      1     (A_i ā_i)ᵀ(p_j(ū_j) − p_i(ū_i)) − c − δ·θ_d(t)   (C^d2, Rouvinen 2003, eq. 8–10)
ANGLE       1     φ_j − φ_i − c − δ·θ_d(t)                      (planar rotation / driver)
NORM        1     θ_iᵀθ_i − 1                                   (Rouvinen 2003, eq. 4)
DRIVE_ROT   1     (A_i h̄_i)ᵀ A_j (sin θ_d f̄_j + cos θ_d ḡ_j) = sin(θ_d − θ)   (driven rotation)
==========  ====  ==========================================================================

θ_d(t) = value + rate·t is the driver; δ = 1 on the driver row.  γ is the acceleration
right-hand side Φ_q q̈ = γ = −(Φ_q q̇)_q q̇ − 2Φ_qt q̇ − Φ_tt (Frączek & Wojtyra 2009, eq. 1.16, Rouvinen 2003, eq. 21–23).

Arrays (k primitives): ``kind, bi, bj, row, driver`` int64 (k,); ``ui, uj, pi, gj`` float64 (k, 3)
(vectors or points on body i / j, the second point on i for DOT_VD, the second vector on j for
DRIVE_ROT); ``const`` float64 (k,).  The kernels take them packed, with ``nc`` first and the
driver ``drive`` and row count ``m`` last, as one tuple ``args``
(:attr:`~mbh._adapters.inhouse.bodies.constraints.ConstraintSystem.kernel_args`).  Φ, Φ_q and γ are inlined
into their compiled callers (the cost model of :mod:`~mbh._adapters.inhouse.numerics.inlining`): a call of a compiled function with eleven
array arguments cost ~0.13 µs (planar four-bar, one call in a compiled loop: Φ_q 0.38 → 0.25 µs,
γ 0.32 → 0.18 µs inlined), at the price of a longer first compilation.

The small helpers below are inlined into the kernels' compiled callers, as those of
:mod:`mbh._adapters.inhouse.bodies.bodykin` are, and for the same reason: a call of a separately compiled
function with array arguments costs more than their arithmetic.  Like those, they pass vectors as
tuples (x, y, z), never through scratch arrays (the module notes there say why).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from mbh._adapters.inhouse.bodies.bodykin import (
    PLANAR_NC,
    add_point_block,
    add_point_jacobian,
    add_rotate_jacobian,
    point_rate_xyz,
    point_xyz,
    rotate_quadratic_xyz,
    rotate_rate_xyz,
    rotate_xyz,
)
from mbh._adapters.inhouse.numerics.inlining import called_from_python, into_compiled_callers

POINT, DOT_VV, DOT_VD, ANGLE, NORM, DRIVE_ROT = range(6)


@njit(cache=True, inline=into_compiled_callers)
def _drive(drive, t):
    """θ_d, θ̇_d at time t for ``drive = (value, rate)`` (linear in t, so θ̈_d = 0)."""
    return drive[0] + drive[1] * t, drive[1]


@njit(cache=True, inline=into_compiled_callers)
def _dot(a, b):
    """aᵀb of two tuples (3)."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True, inline=into_compiled_callers)
def _second_vector(k, kind, tab_uj, tab_gj, theta):
    """The vector on body j of a DOT_VV row (ū_j) or of a DRIVE_ROT row (sin θ_d f̄_j +
    cos θ_d ḡ_j), shape (3,) (a row view of ``tab_uj`` for DOT_VV)."""
    if kind == DOT_VV:
        return tab_uj[k]
    s, c = np.sin(theta), np.cos(theta)
    return s * tab_uj[k] + c * tab_gj[k]


@njit(cache=True, inline=into_compiled_callers)
def _second_vector_rate(k, tab_uj, tab_gj, theta, rate):
    """d/dt of a DRIVE_ROT row's vector on body j, θ̇_d (cos θ_d f̄_j − sin θ_d ḡ_j), shape (3,)."""
    c, s = np.cos(theta), np.sin(theta)
    return rate * (c * tab_uj[k] - s * tab_gj[k])


@called_from_python
@njit(cache=True, inline=into_compiled_callers)
def phi(q, t, args):
    """Constraint residuals Φ(q, t), shape (m,)."""
    nc, kind, bi, bj, row, driver, ui, uj, pi, gj, const, drive, m = args
    out = np.zeros(m)
    dim = 2 if nc == PLANAR_NC else 3
    theta, _ = _drive(drive, t)
    for k in range(kind.shape[0]):
        r, i, j = row[k], bi[k], bj[k]
        kd = kind[k]
        if kd == POINT:
            a = point_xyz(q, nc, i, ui[k])
            b = point_xyz(q, nc, j, uj[k])
            for x in range(dim):
                out[r + x] = a[x] - b[x]
        elif kd == DOT_VV or kd == DRIVE_ROT:
            w = _second_vector(k, kd, uj, gj, theta)
            out[r] = _dot(rotate_xyz(q, nc, i, ui[k]), rotate_xyz(q, nc, j, w))
        elif kd == DOT_VD:
            b = point_xyz(q, nc, j, uj[k])
            w = point_xyz(q, nc, i, pi[k])
            a = rotate_xyz(q, nc, i, ui[k])
            out[r] = a[0] * (b[0] - w[0]) + a[1] * (b[1] - w[1]) + a[2] * (b[2] - w[2]) \
                - const[k] - driver[k] * theta
        elif kd == ANGLE:
            phi_j = q[j * nc + 2] if j >= 0 else 0.0
            phi_i = q[i * nc + 2] if i >= 0 else 0.0
            out[r] = phi_j - phi_i - const[k] - driver[k] * theta
        else:  # NORM
            out[r] = _euler_square(q, i * nc + 3) - 1.0
    return out


@njit(cache=True, inline=into_compiled_callers)
def _euler_square(x, start):
    """x[start:start + 4] · x[start:start + 4] (θᵀθ or θ̇ᵀθ̇ of one body) without a BLAS call."""
    return x[start] * x[start] + x[start + 1] * x[start + 1] + x[start + 2] * x[start + 2] \
        + x[start + 3] * x[start + 3]


@called_from_python
@njit(cache=True, inline=into_compiled_callers)
def jacobian(q, t, args):
    """Constraint Jacobian Φ_q(q, t), shape (m, n)."""
    nc, kind, bi, bj, row, driver, ui, uj, pi, gj, const, drive, m = args
    n = q.shape[0]
    jac = np.zeros((m, n))
    theta, _ = _drive(drive, t)
    for k in range(kind.shape[0]):
        r, i, j = row[k], bi[k], bj[k]
        kd = kind[k]
        if kd == POINT:
            add_point_block(jac, r, q, nc, i, ui[k], 1.0)
            add_point_block(jac, r, q, nc, j, uj[k], -1.0)
        elif kd == DOT_VV or kd == DRIVE_ROT:
            w = _second_vector(k, kd, uj, gj, theta)
            a = rotate_xyz(q, nc, i, ui[k])
            b = rotate_xyz(q, nc, j, w)
            add_rotate_jacobian(jac, r, q, nc, i, ui[k], b, 1.0)
            add_rotate_jacobian(jac, r, q, nc, j, w, a, 1.0)
        elif kd == DOT_VD:
            a = rotate_xyz(q, nc, i, ui[k])
            b = point_xyz(q, nc, j, uj[k])
            w = point_xyz(q, nc, i, pi[k])
            d = (b[0] - w[0], b[1] - w[1], b[2] - w[2])
            add_rotate_jacobian(jac, r, q, nc, i, ui[k], d, 1.0)
            add_point_jacobian(jac, r, q, nc, i, pi[k], a, -1.0)
            add_point_jacobian(jac, r, q, nc, j, uj[k], a, 1.0)
        elif kd == ANGLE:
            if j >= 0:
                jac[r, j * nc + 2] += 1.0
            if i >= 0:
                jac[r, i * nc + 2] -= 1.0
        else:  # NORM
            for c in range(i * nc + 3, i * nc + 7):
                jac[r, c] = 2.0 * q[c]
    return jac


@njit(cache=True)
def phi_t(q, t, args):
    """Explicit time derivative Φ_t(q, t), shape (m,); non-zero on the driver row only."""
    nc, kind, bi, bj, row, driver, ui, uj, pi, gj, const, drive, m = args
    out = np.zeros(m)
    theta, rate = _drive(drive, t)
    for k in range(kind.shape[0]):
        r = row[k]
        if kind[k] == DRIVE_ROT:
            w_dot = _second_vector_rate(k, uj, gj, theta, rate)
            out[r] = _dot(rotate_xyz(q, nc, bi[k], ui[k]), rotate_xyz(q, nc, bj[k], w_dot))
        elif kind[k] == DOT_VD or kind[k] == ANGLE:
            out[r] = -driver[k] * rate
    return out


@called_from_python
@njit(cache=True, inline=into_compiled_callers)
def gamma(q, v, t, args):
    """Acceleration right-hand side γ(q, q̇, t), shape (m,)  (Frączek & Wojtyra 2009, eq. 1.16; Rouvinen 2003, eq. 21–23)."""
    nc, kind, bi, bj, row, driver, ui, uj, pi, gj, const, drive, m = args
    out = np.zeros(m)
    dim = 2 if nc == PLANAR_NC else 3
    theta, rate = _drive(drive, t)
    for k in range(kind.shape[0]):
        r, i, j = row[k], bi[k], bj[k]
        kd = kind[k]
        if kd == POINT:
            qa_j = rotate_quadratic_xyz(q, v, nc, j, uj[k])
            qa_i = rotate_quadratic_xyz(q, v, nc, i, ui[k])
            for x in range(dim):
                out[r + x] = qa_j[x] - qa_i[x]
        elif kd == DOT_VV or kd == DRIVE_ROT:
            w = _second_vector(k, kd, uj, gj, theta)
            a_i, a_j = rotate_xyz(q, nc, i, ui[k]), rotate_xyz(q, nc, j, w)
            da_i, da_j = rotate_rate_xyz(q, v, nc, i, ui[k]), rotate_rate_xyz(q, v, nc, j, w)
            qa_i = rotate_quadratic_xyz(q, v, nc, i, ui[k])
            qa_j = rotate_quadratic_xyz(q, v, nc, j, w)
            acc = _dot(qa_i, a_j) + 2.0 * _dot(da_i, da_j) + _dot(a_i, qa_j)
            if kd == DRIVE_ROT:
                # Φ_t = a_iᵀ A_j ẇ:  2 Φ_qt q̇ = 2 (ȧ_iᵀ A_j ẇ + a_iᵀ Ȧ_j ẇ);  Φ_tt = −θ̇_d² Φ.
                w_dot = _second_vector_rate(k, uj, gj, theta, rate)
                acc += 2.0 * (_dot(da_i, rotate_xyz(q, nc, j, w_dot))
                              + _dot(a_i, rotate_rate_xyz(q, v, nc, j, w_dot)))
                acc -= rate * rate * _dot(a_i, a_j)
            out[r] = -acc
        elif kd == DOT_VD:
            a_i = rotate_xyz(q, nc, i, ui[k])
            a_j = point_xyz(q, nc, j, uj[k])
            w = point_xyz(q, nc, i, pi[k])
            da_j = point_rate_xyz(q, v, nc, j, uj[k])
            w_dot = point_rate_xyz(q, v, nc, i, pi[k])
            qa_j = rotate_quadratic_xyz(q, v, nc, j, uj[k])
            qa_i = rotate_quadratic_xyz(q, v, nc, i, pi[k])
            total = 0.0
            for x in range(3):
                total += a_i[x] * (qa_j[x] - qa_i[x])
            qa_i = rotate_quadratic_xyz(q, v, nc, i, ui[k])
            da_i = rotate_rate_xyz(q, v, nc, i, ui[k])
            for x in range(3):
                total += qa_i[x] * (a_j[x] - w[x]) + 2.0 * da_i[x] * (da_j[x] - w_dot[x])
            out[r] = -total
        elif kd == NORM:
            out[r] = -2.0 * _euler_square(v, i * nc + 3)
    return out
