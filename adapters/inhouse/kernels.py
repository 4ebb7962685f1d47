"""Compiled constraint kernels: Φ, Φ_q, Φ_t and γ for a table of primitive constraints.

Every joint of seed 002 ch. 2 is composed of a handful of primitives (see
:mod:`adapters.inhouse.constraints`), stored row-wise in flat arrays so that one compiled loop
evaluates the whole system:

==========  ====  ==========================================================================
kind        rows  Φ
==========  ====  ==========================================================================
POINT       2|3   p_i(ū_i) − p_j(ū_j)                          (C^s, 002 eq. 11; 000 eq. 1.35)
DOT_VV      1     (A_i ā_i)ᵀ(A_j ā_j)                           (C^d1, 002 eq. 6–7)
DOT_VD      1     (A_i ā_i)ᵀ(p_j(ū_j) − p_i(ū_i)) − c − δ·θ_d(t)   (C^d2, 002 eq. 8–10)
ANGLE       1     φ_j − φ_i − c − δ·θ_d(t)                      (planar rotation / driver)
NORM        1     θ_iᵀθ_i − 1                                   (002 eq. 4)
DRIVE_ROT   1     (A_i h̄_i)ᵀ A_j (sin θ_d f̄_j + cos θ_d ḡ_j) = sin(θ_d − θ)   (driven rotation)
==========  ====  ==========================================================================

θ_d(t) = value + rate·t is the driver; δ = 1 on the driver row.  γ is the acceleration
right-hand side Φ_q q̈ = γ = −(Φ_q q̇)_q q̇ − 2Φ_qt q̇ − Φ_tt (000 eq. 1.16, 002 eq. 21–23).

Arrays (k primitives): ``kind, bi, bj, row, driver`` int64 (k,); ``ui, uj, pi, gj`` float64 (k, 3)
(vectors or points on body i / j, the second point on i for DOT_VD, the second vector on j for
DRIVE_ROT); ``const`` float64 (k,).

The small helpers below are inlined into the kernels (``inline="always"``), as those of
:mod:`adapters.inhouse.bodykin` are, and for the same reason: a call of a separately compiled
function with array arguments costs more than their arithmetic.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from adapters.inhouse.bodykin import (
    PLANAR_NC,
    point_into,
    point_jacobian_into,
    rotate,
    rotate_into,
    rotate_jacobian_into,
    rotate_quadratic_into,
    rotate_rate_into,
    point_rate_into,
)

POINT, DOT_VV, DOT_VD, ANGLE, NORM, DRIVE_ROT = range(6)


@njit(cache=True, inline="always")
def _drive(drive, t):
    """θ_d, θ̇_d at time t for ``drive = (value, rate)`` (linear in t, so θ̈_d = 0)."""
    return drive[0] + drive[1] * t, drive[1]


@njit(cache=True, inline="always")
def _rot_target_rate(k, tab_uj, tab_gj, theta, rate):
    return rate * (np.cos(theta) * tab_uj[k] - np.sin(theta) * tab_gj[k])


@njit(cache=True, inline="always")
def _add_block(jac, r, q, nc, body, block_row, sign=1.0):
    if body >= 0:
        k = body * nc
        for c in range(nc):
            jac[r, k + c] += sign * block_row[c]


@njit(cache=True)
def phi(q, t, nc, kind, bi, bj, row, driver, ui, uj, pi, gj, const, drive, m):
    """Constraint residuals Φ(q, t), shape (m,)."""
    out = np.zeros(m)
    dim = 2 if nc == PLANAR_NC else 3
    theta, _ = _drive(drive, t)
    a, b, w = np.empty(3), np.empty(3), np.empty(3)
    for k in range(kind.shape[0]):
        r, i, j = row[k], bi[k], bj[k]
        kd = kind[k]
        if kd == POINT:
            point_into(a, q, nc, i, ui[k])
            point_into(b, q, nc, j, uj[k])
            for x in range(dim):
                out[r + x] = a[x] - b[x]
        elif kd == DOT_VV or kd == DRIVE_ROT:
            _second_vector_into(w, k, kd, uj, gj, theta)
            rotate_into(a, q, nc, i, ui[k])
            rotate_into(b, q, nc, j, w)
            out[r] = _dot(a, b)
        elif kd == DOT_VD:
            point_into(b, q, nc, j, uj[k])
            point_into(w, q, nc, i, pi[k])
            rotate_into(a, q, nc, i, ui[k])
            out[r] = a[0] * (b[0] - w[0]) + a[1] * (b[1] - w[1]) + a[2] * (b[2] - w[2]) \
                - const[k] - driver[k] * theta
        elif kd == ANGLE:
            phi_j = q[j * nc + 2] if j >= 0 else 0.0
            phi_i = q[i * nc + 2] if i >= 0 else 0.0
            out[r] = phi_j - phi_i - const[k] - driver[k] * theta
        else:  # NORM
            out[r] = _euler_square(q, i * nc + 3) - 1.0
    return out


@njit(cache=True, inline="always")
def _euler_square(x, start):
    """x[start:start + 4] · x[start:start + 4] (θᵀθ or θ̇ᵀθ̇ of one body) without a BLAS call."""
    return x[start] * x[start] + x[start + 1] * x[start + 1] + x[start + 2] * x[start + 2] \
        + x[start + 3] * x[start + 3]


@njit(cache=True, inline="always")
def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True, inline="always")
def _second_vector_into(out, k, kind, tab_uj, tab_gj, theta):
    """The vector on body j of a DOT_VV row (ū_j) or of a DRIVE_ROT row (sin θ_d f̄_j +
    cos θ_d ḡ_j), written into ``out`` (3,)."""
    if kind == DOT_VV:
        out[:] = tab_uj[k]
        return
    s, c = np.sin(theta), np.cos(theta)
    for x in range(3):
        out[x] = s * tab_uj[k, x] + c * tab_gj[k, x]


@njit(cache=True, inline="always")
def _add_vector_times_jacobian(jac, r, nc, body, vector, block, sign):
    """jac[r, body block] += sign · vectorᵀ block, block (3, nc)."""
    if body < 0:
        return
    k = body * nc
    for c in range(nc):
        jac[r, k + c] += sign * (vector[0] * block[0, c] + vector[1] * block[1, c]
                                 + vector[2] * block[2, c])


@njit(cache=True)
def jacobian(q, t, nc, kind, bi, bj, row, driver, ui, uj, pi, gj, const, drive, m):
    """Constraint Jacobian Φ_q(q, t), shape (m, n)."""
    n = q.shape[0]
    jac = np.zeros((m, n))
    dim = 2 if nc == PLANAR_NC else 3
    theta, _ = _drive(drive, t)
    ji, jj = np.empty((3, nc)), np.empty((3, nc))
    a, b, w, d = np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    for k in range(kind.shape[0]):
        r, i, j = row[k], bi[k], bj[k]
        kd = kind[k]
        if kd == POINT:
            point_jacobian_into(ji, q, nc, i, ui[k])
            point_jacobian_into(jj, q, nc, j, uj[k])
            for x in range(dim):
                _add_block(jac, r + x, q, nc, i, ji[x])
                _add_block(jac, r + x, q, nc, j, jj[x], -1.0)
        elif kd == DOT_VV or kd == DRIVE_ROT:
            _second_vector_into(w, k, kd, uj, gj, theta)
            rotate_into(a, q, nc, i, ui[k])
            rotate_into(b, q, nc, j, w)
            rotate_jacobian_into(ji, q, nc, i, ui[k])
            rotate_jacobian_into(jj, q, nc, j, w)
            _add_vector_times_jacobian(jac, r, nc, i, b, ji, 1.0)
            _add_vector_times_jacobian(jac, r, nc, j, a, jj, 1.0)
        elif kd == DOT_VD:
            rotate_into(a, q, nc, i, ui[k])
            point_into(b, q, nc, j, uj[k])
            point_into(w, q, nc, i, pi[k])
            for x in range(3):
                d[x] = b[x] - w[x]
            rotate_jacobian_into(ji, q, nc, i, ui[k])
            _add_vector_times_jacobian(jac, r, nc, i, d, ji, 1.0)
            point_jacobian_into(ji, q, nc, i, pi[k])
            _add_vector_times_jacobian(jac, r, nc, i, a, ji, -1.0)
            point_jacobian_into(jj, q, nc, j, uj[k])
            _add_vector_times_jacobian(jac, r, nc, j, a, jj, 1.0)
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
def phi_t(q, t, nc, kind, bi, bj, row, driver, ui, uj, pi, gj, const, drive, m):
    """Explicit time derivative Φ_t(q, t), shape (m,); non-zero on the driver row only."""
    out = np.zeros(m)
    theta, rate = _drive(drive, t)
    for k in range(kind.shape[0]):
        r = row[k]
        if kind[k] == DRIVE_ROT:
            w_dot = _rot_target_rate(k, uj, gj, theta, rate)
            out[r] = rotate(q, nc, bi[k], ui[k]) @ rotate(q, nc, bj[k], w_dot)
        elif kind[k] == DOT_VD or kind[k] == ANGLE:
            out[r] = -driver[k] * rate
    return out


@njit(cache=True)
def gamma(q, v, t, nc, kind, bi, bj, row, driver, ui, uj, pi, gj, const, drive, m):
    """Acceleration right-hand side γ(q, q̇, t), shape (m,)  (000 eq. 1.16; 002 eq. 21–23)."""
    out = np.zeros(m)
    dim = 2 if nc == PLANAR_NC else 3
    theta, rate = _drive(drive, t)
    a_i, a_j, da_i, da_j = np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    qa_i, qa_j, w, w_dot = np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    for k in range(kind.shape[0]):
        r, i, j = row[k], bi[k], bj[k]
        kd = kind[k]
        if kd == POINT:
            rotate_quadratic_into(qa_j, q, v, nc, j, uj[k])
            rotate_quadratic_into(qa_i, q, v, nc, i, ui[k])
            for x in range(dim):
                out[r + x] = qa_j[x] - qa_i[x]
        elif kd == DOT_VV or kd == DRIVE_ROT:
            _second_vector_into(w, k, kd, uj, gj, theta)
            rotate_into(a_i, q, nc, i, ui[k])
            rotate_into(a_j, q, nc, j, w)
            rotate_rate_into(da_i, q, v, nc, i, ui[k])
            rotate_rate_into(da_j, q, v, nc, j, w)
            rotate_quadratic_into(qa_i, q, v, nc, i, ui[k])
            rotate_quadratic_into(qa_j, q, v, nc, j, w)
            acc = _dot(qa_i, a_j) + 2.0 * _dot(da_i, da_j) + _dot(a_i, qa_j)
            if kd == DRIVE_ROT:
                # Φ_t = a_iᵀ A_j ẇ:  2 Φ_qt q̇ = 2 (ȧ_iᵀ A_j ẇ + a_iᵀ Ȧ_j ẇ);  Φ_tt = −θ̇_d² Φ.
                c, s = np.cos(theta), np.sin(theta)
                for x in range(3):
                    w_dot[x] = rate * (c * uj[k, x] - s * gj[k, x])
                rotate_into(qa_j, q, nc, j, w_dot)
                rotate_rate_into(da_j, q, v, nc, j, w_dot)
                acc += 2.0 * (_dot(da_i, qa_j) + _dot(a_i, da_j))
                acc -= rate * rate * _dot(a_i, a_j)
            out[r] = -acc
        elif kd == DOT_VD:
            rotate_into(a_i, q, nc, i, ui[k])
            point_into(a_j, q, nc, j, uj[k])
            point_into(w, q, nc, i, pi[k])
            point_rate_into(da_j, q, v, nc, j, uj[k])
            point_rate_into(w_dot, q, v, nc, i, pi[k])
            rotate_quadratic_into(qa_j, q, v, nc, j, uj[k])
            rotate_quadratic_into(qa_i, q, v, nc, i, pi[k])
            total = 0.0
            for x in range(3):
                total += a_i[x] * (qa_j[x] - qa_i[x])
            rotate_quadratic_into(qa_i, q, v, nc, i, ui[k])
            rotate_rate_into(da_i, q, v, nc, i, ui[k])
            for x in range(3):
                total += qa_i[x] * (a_j[x] - w[x]) + 2.0 * da_i[x] * (da_j[x] - w_dot[x])
            out[r] = -total
        elif kd == NORM:
            out[r] = -2.0 * _euler_square(v, i * nc + 3)
    return out
