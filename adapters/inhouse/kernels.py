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
"""

from __future__ import annotations

import numpy as np
from numba import njit

from adapters.inhouse.bodykin import (
    PLANAR_NC,
    point,
    point_jacobian,
    point_rate,
    rotate,
    rotate_jacobian,
    rotate_quadratic,
    rotate_rate,
)

POINT, DOT_VV, DOT_VD, ANGLE, NORM, DRIVE_ROT = range(6)


@njit(cache=True)
def _drive(drive, t):
    """θ_d, θ̇_d at time t for ``drive = (value, rate)`` (linear in t, so θ̈_d = 0)."""
    return drive[0] + drive[1] * t, drive[1]


@njit(cache=True)
def _rot_target(k, tab_uj, tab_gj, theta):
    return np.sin(theta) * tab_uj[k] + np.cos(theta) * tab_gj[k]


@njit(cache=True)
def _rot_target_rate(k, tab_uj, tab_gj, theta, rate):
    return rate * (np.cos(theta) * tab_uj[k] - np.sin(theta) * tab_gj[k])


@njit(cache=True)
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
    for k in range(kind.shape[0]):
        r, i, j = row[k], bi[k], bj[k]
        kd = kind[k]
        if kd == POINT:
            d = point(q, nc, i, ui[k]) - point(q, nc, j, uj[k])
            out[r:r + dim] = d[:dim]
        elif kd == DOT_VV:
            out[r] = rotate(q, nc, i, ui[k]) @ rotate(q, nc, j, uj[k])
        elif kd == DOT_VD:
            d = point(q, nc, j, uj[k]) - point(q, nc, i, pi[k])
            out[r] = rotate(q, nc, i, ui[k]) @ d - const[k] - driver[k] * theta
        elif kd == ANGLE:
            phi_j = q[j * nc + 2] if j >= 0 else 0.0
            phi_i = q[i * nc + 2] if i >= 0 else 0.0
            out[r] = phi_j - phi_i - const[k] - driver[k] * theta
        elif kd == NORM:
            s = q[i * nc + 3:i * nc + 7]
            out[r] = s @ s - 1.0
        else:  # DRIVE_ROT
            w = _rot_target(k, uj, gj, theta)
            out[r] = rotate(q, nc, i, ui[k]) @ rotate(q, nc, j, w)
    return out


@njit(cache=True)
def jacobian(q, t, nc, kind, bi, bj, row, driver, ui, uj, pi, gj, const, drive, m):
    """Constraint Jacobian Φ_q(q, t), shape (m, n)."""
    n = q.shape[0]
    jac = np.zeros((m, n))
    dim = 2 if nc == PLANAR_NC else 3
    theta, _ = _drive(drive, t)
    for k in range(kind.shape[0]):
        r, i, j = row[k], bi[k], bj[k]
        kd = kind[k]
        if kd == POINT:
            ji = point_jacobian(q, nc, i, ui[k])
            jj = point_jacobian(q, nc, j, uj[k])
            for a in range(dim):
                _add_block(jac, r + a, q, nc, i, ji[a])
                _add_block(jac, r + a, q, nc, j, jj[a], -1.0)
        elif kd == DOT_VV or kd == DRIVE_ROT:
            wj = uj[k] if kd == DOT_VV else _rot_target(k, uj, gj, theta)
            a_i = rotate(q, nc, i, ui[k])
            a_j = rotate(q, nc, j, wj)
            _add_block(jac, r, q, nc, i, a_j @ rotate_jacobian(q, nc, i, ui[k]))
            _add_block(jac, r, q, nc, j, a_i @ rotate_jacobian(q, nc, j, wj))
        elif kd == DOT_VD:
            a_i = rotate(q, nc, i, ui[k])
            d = point(q, nc, j, uj[k]) - point(q, nc, i, pi[k])
            _add_block(jac, r, q, nc, i, d @ rotate_jacobian(q, nc, i, ui[k])
                       - a_i @ point_jacobian(q, nc, i, pi[k]))
            _add_block(jac, r, q, nc, j, a_i @ point_jacobian(q, nc, j, uj[k]))
        elif kd == ANGLE:
            if j >= 0:
                jac[r, j * nc + 2] += 1.0
            if i >= 0:
                jac[r, i * nc + 2] -= 1.0
        else:  # NORM
            jac[r, i * nc + 3:i * nc + 7] = 2.0 * q[i * nc + 3:i * nc + 7]
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
    for k in range(kind.shape[0]):
        r, i, j = row[k], bi[k], bj[k]
        kd = kind[k]
        if kd == POINT:
            g = rotate_quadratic(q, v, nc, j, uj[k]) - rotate_quadratic(q, v, nc, i, ui[k])
            out[r:r + dim] = g[:dim]
        elif kd == DOT_VV or kd == DRIVE_ROT:
            wj = uj[k] if kd == DOT_VV else _rot_target(k, uj, gj, theta)
            a_i, a_j = rotate(q, nc, i, ui[k]), rotate(q, nc, j, wj)
            da_i, da_j = rotate_rate(q, v, nc, i, ui[k]), rotate_rate(q, v, nc, j, wj)
            acc = (rotate_quadratic(q, v, nc, i, ui[k]) @ a_j + 2.0 * da_i @ da_j
                   + a_i @ rotate_quadratic(q, v, nc, j, wj))
            if kd == DRIVE_ROT:
                # Φ_t = a_iᵀ A_j ẇ:  2 Φ_qt q̇ = 2 (ȧ_iᵀ A_j ẇ + a_iᵀ Ȧ_j ẇ);  Φ_tt = −θ̇_d² Φ.
                w_dot = _rot_target_rate(k, uj, gj, theta, rate)
                acc += 2.0 * (da_i @ rotate(q, nc, j, w_dot) + a_i @ rotate_rate(q, v, nc, j, w_dot))
                acc -= rate * rate * (a_i @ a_j)
            out[r] = -acc
        elif kd == DOT_VD:
            a_i = rotate(q, nc, i, ui[k])
            d = point(q, nc, j, uj[k]) - point(q, nc, i, pi[k])
            dd = point_rate(q, v, nc, j, uj[k]) - point_rate(q, v, nc, i, pi[k])
            ddd = rotate_quadratic(q, v, nc, j, uj[k]) - rotate_quadratic(q, v, nc, i, pi[k])
            out[r] = -(rotate_quadratic(q, v, nc, i, ui[k]) @ d
                       + 2.0 * rotate_rate(q, v, nc, i, ui[k]) @ dd + a_i @ ddd)
        elif kd == NORM:
            s = v[i * nc + 3:i * nc + 7]
            out[r] = -2.0 * (s @ s)
    return out
