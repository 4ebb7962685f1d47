"""The mass matrix and the applied and inertial forces of a mechanism in absolute coordinates
(Rouvinen 2003, ch. 3).

Planar: M = diag(m, m, I_zz) per body, no quadratic-velocity terms.
Spatial with Euler parameters: per body M = diag(m I₃, Ḡᵀ J̄ Ḡ) (Rouvinen 2003, eq. 55–61, Ḡ = 2Ē of eq. 28)
and Q_v = (0, −Ḡᵀ(ω̄ × J̄ ω̄)) with ω̄ = Ḡ θ̇ (eq. 62–63, using Ḡ̇ θ̇ = 0).  The rotational block is
singular along θ; the normalisation constraint θᵀθ = 1 completes the augmented system
(:mod:`~mbh._adapters.inhouse.formulations.dynamics`).

Generalised forces (Rouvinen 2003, eq. 64–71): a world force F at body point ū gives Q_R = F,
Q_θ = Ḡᵀ(ū × AᵀF); a world torque n gives Q_θ = Ḡᵀ Aᵀ n.  Planar: Q_φ = (Aū × F)_z, n_z.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from mbh._adapters.inhouse.bodies import kernels
from mbh._adapters.inhouse.bodies.bodykin import PLANAR_NC, point_rate_xyz, point_xyz, rotate_xyz
from mbh._adapters.inhouse.bodies.constraints import layout_of
from mbh._adapters.inhouse.numerics.linalg import certified_solve, matvec, rmatvec, skippable
from mbh._harness.model.mechanism import (BodyForce, BodyTorque, JointActuation, Mechanism,
                                          SpringDamper)


@njit(cache=True, inline="always")
def g_bar(theta):
    """Ḡ = 2Ē of Rouvinen 2003, eq. 28, shape (3, 4): the array form of :func:`_g_bar_rows`."""
    return np.array(_g_bar_rows(theta, 0))


@njit(cache=True, inline="always")
def _g_bar_rows(q, start):
    """The rows of Ḡ = 2Ē (Rouvinen 2003, eq. 28) of θ = q[start:start + 4], three tuples (4): the form
    the force kernels use (tuples, not a scratch array: :mod:`mbh._adapters.inhouse.bodies.bodykin` says
    why)."""
    t0, t1, t2, t3 = q[start], q[start + 1], q[start + 2], q[start + 3]
    return ((-2.0 * t1, 2.0 * t0, 2.0 * t3, -2.0 * t2),
            (-2.0 * t2, -2.0 * t3, 2.0 * t0, 2.0 * t1),
            (-2.0 * t3, 2.0 * t2, -2.0 * t1, 2.0 * t0))


@njit(cache=True)
def _inertia_certified(mass, inertia, cut):
    """Whether a body's mass is positive and its inertia J̄ (3, 3) positive definite with
    λ_min > cut · λ_max: positive leading minors (Sylvester) make J̄ positive definite, and
    λ_min = det J̄ / (λ₂λ₃) ≥ det J̄ / (tr J̄)², so det J̄ > cut (tr J̄)³ gives λ_min > cut tr J̄
    ≥ cut λ_max.  A few flops per body, so the block solve below can refuse slender bars (a zero
    moment about their axis) and point masses before it divides by a vanishing determinant."""
    if not mass > 0.0 or not inertia[0, 0] > 0.0:
        return False
    if not inertia[0, 0] * inertia[1, 1] - inertia[0, 1] * inertia[1, 0] > 0.0:
        return False
    trace = inertia[0, 0] + inertia[1, 1] + inertia[2, 2]
    return _determinant_3x3(inertia) > cut * trace * trace * trace


@njit(cache=True)
def _determinant_3x3(a):
    """det of a (3, 3) matrix by cofactors along its first row."""
    return (a[0, 0] * (a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1])
            - a[0, 1] * (a[1, 0] * a[2, 2] - a[1, 2] * a[2, 0])
            + a[0, 2] * (a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0]))


@njit(cache=True, inline="always")
def _inverse_3x3_rows(a):
    """Inverse of a (3, 3) matrix by its adjugate, three row tuples (3) (no array to allocate on
    every right-hand side); only called on inertias that :func:`_inertia_certified` accepted
    (condition below 1/cut)."""
    det = _determinant_3x3(a)
    first = ((a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1]) / det,
             (a[0, 2] * a[2, 1] - a[0, 1] * a[2, 2]) / det,
             (a[0, 1] * a[1, 2] - a[0, 2] * a[1, 1]) / det)
    second = ((a[1, 2] * a[2, 0] - a[1, 0] * a[2, 2]) / det,
              (a[0, 0] * a[2, 2] - a[0, 2] * a[2, 0]) / det,
              (a[0, 2] * a[1, 0] - a[0, 0] * a[1, 2]) / det)
    third = ((a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0]) / det,
             (a[0, 1] * a[2, 0] - a[0, 0] * a[2, 1]) / det,
             (a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]) / det)
    return first, second, third


@njit(cache=True, inline="always")
def _euler_block_scales(theta, c):
    """(1/(4|θ|²), 1/(c|θ|⁴)) of :func:`_euler_block_inverse` for θ (4,) and c > 0."""
    size = theta[0] * theta[0] + theta[1] * theta[1] + theta[2] * theta[2] \
        + theta[3] * theta[3]
    normal = 1.0 / size
    return 1.0 / (4.0 * size), normal * normal / c


@njit(cache=True, inline="always")
def _times_g_bar(row, g):
    """rowᵀ Ḡ for a row tuple (3) and ``g`` = Ḡ as row tuples (:func:`_g_bar_rows`), a tuple (4)."""
    return (row[0] * g[0][0] + row[1] * g[1][0] + row[2] * g[2][0],
            row[0] * g[0][1] + row[1] * g[1][1] + row[2] * g[2][1],
            row[0] * g[0][2] + row[1] * g[1][2] + row[2] * g[2][2],
            row[0] * g[0][3] + row[1] * g[1][3] + row[2] * g[2][3])


@njit(cache=True, inline="always")
def _euler_inverse_entry(r, c, g, weighted, rotational_square, along_scale, theta):
    """Entry (r, c) of :func:`_euler_block_inverse`: w² (Ḡᵀ J̄⁻¹ Ḡ)_rc + a θ_r θ_c with
    ``weighted`` = J̄⁻¹ Ḡ as row tuples (3 of 4)."""
    return rotational_square * (g[0][r] * weighted[0][c] + g[1][r] * weighted[1][c]
                                + g[2][r] * weighted[2][c]) + along_scale * theta[r] * theta[c]


@njit(cache=True, inline="always")
def _euler_block_inverse(theta, g, inertia_inverse, scales):
    """B⁻¹ for the rotational block B = Ḡᵀ J̄ Ḡ + c θθᵀ of one body, four row tuples (4)
    (symmetric), θ (4,), ``g`` = Ḡ(θ) and ``inertia_inverse`` = J̄⁻¹ as row tuples
    (:func:`_g_bar_rows`, :func:`_inverse_3x3_rows`), ``scales`` = (w, a) =
    :func:`_euler_block_scales` (θ, c), c > 0.

    With E = [Ḡ; θᵀ] (4, 4): Ḡθ = 0 and ḠḠᵀ = 4|θ|² I₃ for every θ (Ḡ = 2Ē, Rouvinen 2003, eq. 28; unit
    length is not needed), so E Eᵀ = D⁻¹ with D = diag(I₃ / (4|θ|²), 1/|θ|²), B = Eᵀ diag(J̄, c) E
    and B⁻¹ = Eᵀ D diag(J̄⁻¹, 1/c) D E = w² Ḡᵀ J̄⁻¹ Ḡ + a θθᵀ (w = 1/(4|θ|²), a = 1/(c|θ|⁴)):
    no factorisation, and made once per body (10 entries, ~150 operations) it costs each row of
    Φ_q the body touches one 4 × 4 product (28 operations) instead of the three products with
    Ḡ, J̄⁻¹ and Ḡᵀ (78; the spatial four-bar's traced q̈ 8,113 → 7,264 operations).
    """
    rotational, along_scale = scales
    square = rotational * rotational
    weighted = (_times_g_bar(inertia_inverse[0], g), _times_g_bar(inertia_inverse[1], g),
                _times_g_bar(inertia_inverse[2], g))
    e00 = _euler_inverse_entry(0, 0, g, weighted, square, along_scale, theta)
    e01 = _euler_inverse_entry(0, 1, g, weighted, square, along_scale, theta)
    e02 = _euler_inverse_entry(0, 2, g, weighted, square, along_scale, theta)
    e03 = _euler_inverse_entry(0, 3, g, weighted, square, along_scale, theta)
    e11 = _euler_inverse_entry(1, 1, g, weighted, square, along_scale, theta)
    e12 = _euler_inverse_entry(1, 2, g, weighted, square, along_scale, theta)
    e13 = _euler_inverse_entry(1, 3, g, weighted, square, along_scale, theta)
    e22 = _euler_inverse_entry(2, 2, g, weighted, square, along_scale, theta)
    e23 = _euler_inverse_entry(2, 3, g, weighted, square, along_scale, theta)
    e33 = _euler_inverse_entry(3, 3, g, weighted, square, along_scale, theta)
    return ((e00, e01, e02, e03), (e01, e11, e12, e13), (e02, e12, e22, e23),
            (e03, e13, e23, e33))


@njit(cache=True, inline="always")
def _block_solve_into(out, i, k, x, mass, rotation_inverse):
    """out[i, k:k + 7] = M'_b⁻¹ x[k:k + 7] for one Euler-parameter body whose coordinates start
    at k: the translation divided by the mass, the rotation times ``rotation_inverse``
    (:func:`_euler_block_inverse`)."""
    for a in range(3):
        out[i, k + a] = x[k + a] / mass
    for r in range(4):
        row = rotation_inverse[r]
        out[i, k + 3 + r] = row[0] * x[k + 3] + row[1] * x[k + 4] + row[2] * x[k + 5] \
            + row[3] * x[k + 6]


@njit(cache=True)
def spatial_block_acceleration(q, jac, force, target, nc, masses, inertias, kind, bi, row,
                               sparsity_arrays, cut):
    """q̈ of the augmented system (Rouvinen 2003, eq. 77) for Euler-parameter bodies with a block-diagonal
    mass matrix, every constraint row included.

    The rotational block Ḡᵀ J̄ Ḡ is singular along θ; the normalisation row 2θᵀθ̈ = γ_θ fixes
    θᵀθ̈, so adding c θθᵀ to the block and c θ γ_θ/2 to the force leaves q̈ unchanged
    (c = 4 tr J̄ / 3, the mean of the block's other eigenvalues 4 J̄_i on the manifold).  The
    block-diagonal M' is solved body by body (:func:`_block_solve_into`) for the rows of Φ_q
    that touch the body (``sparsity_arrays``, :attr:`~mbh._adapters.inhouse.numerics.banded.Sparsity.arrays`),
    S = Φ_q M'⁻¹ Φ_qᵀ by :func:`~mbh._adapters.inhouse.numerics.linalg.certified_solve` (redundant rows
    included: S is then singular, and the certified pivoted factorisation solves it as the
    truncated SVD would).

    Returns
    -------
    accepted : bool
        False when a body's mass block has no certificate (:func:`_inertia_certified`: slender
        bars, point masses) or S has none; the caller then solves the M̃ form with the
        truncated SVD.
    acceleration : ndarray, shape (n,) or (0,)
    """
    for b in range(masses.shape[0]):
        if not _inertia_certified(masses[b], inertias[b], cut):
            return False, np.empty(0)
    body_row_start, body_rows = sparsity_arrays[1], sparsity_arrays[2]
    n, m = q.shape[0], jac.shape[0]
    loaded = force.copy()
    for k in range(kind.shape[0]):
        if kind[k] == kernels.NORM:
            start = bi[k] * nc + 3
            weight = 4.0 * np.trace(inertias[bi[k]]) / 3.0 * 0.5 * target[row[k]]
            for a in range(4):
                loaded[start + a] += weight * q[start + a]
    free = np.empty((1, n))  # M'⁻¹ (Q + the θ terms), one row so as to be written like `weighted`
    weighted = np.zeros((m, n))  # Φ_q M'⁻¹: row i is (M'⁻¹ Φ_q[i]ᵀ)ᵀ
    for b in range(masses.shape[0]):
        k = b * nc
        theta = q[k + 3:k + 7]
        rotation_inverse = _euler_block_inverse(
            theta, _g_bar_rows(q, k + 3), _inverse_3x3_rows(inertias[b]),
            _euler_block_scales(theta, 4.0 * np.trace(inertias[b]) / 3.0))
        _block_solve_into(free, 0, k, loaded, masses[b], rotation_inverse)
        for p in range(body_row_start[b], body_row_start[b + 1]):
            i = body_rows[p]
            _block_solve_into(weighted, i, k, jac[i], masses[b], rotation_inverse)
    free = free[0]
    certified, mu = certified_solve(_gram_of_rows(jac, weighted, sparsity_arrays[0], nc),
                                    target - matvec(jac, free), cut)
    if not certified:
        return False, np.empty(0)
    return True, free + rmatvec(weighted, mu)


@njit(cache=True)
def _gram_of_rows(jac, weighted, row_columns, nc):
    """S = Φ_q (Φ_q M'⁻¹)ᵀ, shape (m, m), from ``weighted`` = Φ_q M'⁻¹ (m, n), both with the
    row pattern ``row_columns``: entry (i, j ≤ i) sums over the columns of row i in increasing
    order (as a dense product would), skipping Φ_q's zeros; the upper triangle mirrors the lower
    one, the triangle the Cholesky factorisation reads, so S is exactly symmetric (half the
    products: 0.56 → 0.44 µs on slider_crank's 20 rows)."""
    m = jac.shape[0]
    gram = np.zeros((m, m))
    for i in range(m):
        first, second = row_columns[i, 0], row_columns[i, nc]
        if second >= 0 and second < first:
            first, second = second, first
        for start in (first, second):
            if start < 0:
                continue
            for c in range(start, start + nc):
                x = jac[i, c]
                if skippable(x):
                    continue
                for j in range(i + 1):
                    gram[i, j] += x * weighted[j, c]
    for i in range(m):
        for j in range(i):
            gram[j, i] = gram[i, j]
    return gram


@njit(cache=True)
def _mass_matrix(q, nc, masses, inertias):
    """M(q), shape (n, n) (Rouvinen 2003, eq. 55–61)."""
    n = q.shape[0]
    mass = np.zeros((n, n))
    for b in range(masses.shape[0]):
        k = b * nc
        for a in range(3 if nc != PLANAR_NC else 2):
            mass[k + a, k + a] = masses[b]
        if nc == PLANAR_NC:
            mass[k + 2, k + 2] = inertias[b, 2, 2]
            continue
        g, inertia = _g_bar_rows(q, k + 3), inertias[b]
        for r in range(4):  # (Ḡᵀ J̄) Ḡ in plain loops: the same sums traced (no BLAS call)
            left = (g[0][r] * inertia[0, 0] + g[1][r] * inertia[1, 0] + g[2][r] * inertia[2, 0],
                    g[0][r] * inertia[0, 1] + g[1][r] * inertia[1, 1] + g[2][r] * inertia[2, 1],
                    g[0][r] * inertia[0, 2] + g[1][r] * inertia[1, 2] + g[2][r] * inertia[2, 2])
            for c in range(4):
                mass[k + 3 + r, k + 3 + c] = left[0] * g[0][c] + left[1] * g[1][c] \
                    + left[2] * g[2][c]
    return mass


@njit(cache=True)
def planar_mass_diagonal(masses, inertias):
    """The diagonal (m, m, I_zz) per body of a planar M, shape (3 b,)."""
    diagonal = np.empty(3 * masses.shape[0])
    for b in range(masses.shape[0]):
        diagonal[3 * b] = diagonal[3 * b + 1] = masses[b]
        diagonal[3 * b + 2] = inertias[b, 2, 2]
    return diagonal


@njit(cache=True, inline="always")
def _inertial_forces(q, v, nc, masses, gravity, inertias):
    """Q_v + gravity, shape (n,) (Rouvinen 2003, eq. 62–63).  Inlined into :func:`forces_kernel`, as is
    :func:`_applied_forces`: a call of a compiled function with this many array arguments cost
    ~0.06 µs, a tenth of the forces of a four-bar."""
    force = np.zeros(q.shape[0])
    for b in range(masses.shape[0]):
        k = b * nc
        for a in range(3 if nc != PLANAR_NC else 2):
            force[k + a] = masses[b] * gravity[a]
        if nc == PLANAR_NC:
            continue
        g = _g_bar_rows(q, k + 3)
        omega = (g[0][0] * v[k + 3] + g[0][1] * v[k + 4] + g[0][2] * v[k + 5] + g[0][3] * v[k + 6],
                 g[1][0] * v[k + 3] + g[1][1] * v[k + 4] + g[1][2] * v[k + 5] + g[1][3] * v[k + 6],
                 g[2][0] * v[k + 3] + g[2][1] * v[k + 4] + g[2][2] * v[k + 5] + g[2][3] * v[k + 6])
        inertia = inertias[b]
        spin = (inertia[0, 0] * omega[0] + inertia[0, 1] * omega[1] + inertia[0, 2] * omega[2],
                inertia[1, 0] * omega[0] + inertia[1, 1] * omega[1] + inertia[1, 2] * omega[2],
                inertia[2, 0] * omega[0] + inertia[2, 1] * omega[1] + inertia[2, 2] * omega[2])
        _add_g_bar_transpose(force, k + 3, g, _cross(omega, spin), -1.0)
    return force


@njit(cache=True, inline="always")
def _cross(a, b):
    """a × b of two tuples (3), a tuple (3)."""
    return a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]


@njit(cache=True, inline="always")
def _add_g_bar_transpose(out, start, g, vector, sign):
    """out[start:start + 4] += sign · Ḡᵀ vector, g the rows of Ḡ (:func:`_g_bar_rows`), vector
    a tuple (3)."""
    for c in range(4):
        out[start + c] += sign * (g[0][c] * vector[0] + g[1][c] * vector[1]
                                  + g[2][c] * vector[2])


@njit(cache=True, inline="always")
def _add_point_force(out, q, nc, body, u, f):
    """Add the generalised force of world force f (a tuple (3)) at body point ū."""
    if body < 0:
        return
    k = body * nc
    arm = rotate_xyz(q, nc, body, u)
    if nc == PLANAR_NC:
        out[k] += f[0]
        out[k + 1] += f[1]
        out[k + 2] += arm[0] * f[1] - arm[1] * f[0]
        return
    for a in range(3):
        out[k + a] += f[a]
    _add_torque(out, q, nc, body, _cross(arm, f), 1.0)


@njit(cache=True, inline="always")
def _add_torque(out, q, nc, body, n, sign):
    """Add the generalised force of world torque sign · n (a tuple (3), sign = ±1) on a body."""
    if body < 0:
        return
    k = body * nc
    if nc == PLANAR_NC:
        out[k + 2] += sign * n[2]
        return
    # Ḡᵀ Aᵀ n: Aᵀ n = (2e₀² − 1) n + 2e (eᵀn) − 2e₀ (e × n) is the torque in body axes
    # (Rouvinen 2003, eq. 5 in the form of mbh._adapters.inhouse.bodies.bodykin, transposed; e = (θ₁, θ₂, θ₃)).
    e0, e1, e2, e3 = q[k + 3], q[k + 4], q[k + 5], q[k + 6]
    scale, along = 2.0 * e0 * e0 - 1.0, 2.0 * (e1 * n[0] + e2 * n[1] + e3 * n[2])
    local = (scale * n[0] + along * e1 - 2.0 * e0 * (e2 * n[2] - e3 * n[1]),
             scale * n[1] + along * e2 - 2.0 * e0 * (e3 * n[0] - e1 * n[2]),
             scale * n[2] + along * e3 - 2.0 * e0 * (e1 * n[1] - e2 * n[0]))
    _add_g_bar_transpose(out, k + 3, _g_bar_rows(q, k + 3), local, sign)


F_JOINT_TORQUE, F_JOINT_FORCE, F_POINT, F_TORQUE, F_SPRING = range(5)


@njit(cache=True, inline="always")
def _applied_forces(out, q, v, nc, kind, bi, bj, va, vb, vc, scalars):
    """Add the generalised forces of the load table (see :class:`Dynamics`) to ``out``."""
    for k in range(kind.shape[0]):
        i, j, kd = bi[k], bj[k], kind[k]
        if kd == F_JOINT_TORQUE:  # τ about the joint axis on body j, −τ on body i
            n = _scaled(rotate_xyz(q, nc, i, va[k]), scalars[k, 0])
            _add_torque(out, q, nc, j, n, 1.0)
            _add_torque(out, q, nc, i, n, -1.0)
        elif kd == F_JOINT_FORCE:  # f along the axis at the joint points
            f = _scaled(rotate_xyz(q, nc, i, va[k]), scalars[k, 0])
            _add_point_force(out, q, nc, j, vc[k], f)
            _add_point_force(out, q, nc, i, vb[k], (-f[0], -f[1], -f[2]))
        elif kd == F_POINT:
            _add_point_force(out, q, nc, i, vb[k], (va[k, 0], va[k, 1], va[k, 2]))
        elif kd == F_TORQUE:
            _add_torque(out, q, nc, i, (va[k, 0], va[k, 1], va[k, 2]), 1.0)
        else:  # F_SPRING: tension k(L − L0) + c L̇ pulls the points together
            p_j, p_i = point_xyz(q, nc, j, vc[k]), point_xyz(q, nc, i, vb[k])
            d = (p_j[0] - p_i[0], p_j[1] - p_i[1], p_j[2] - p_i[2])
            length = np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
            direction = (d[0] / length, d[1] / length, d[2] / length)
            r_j, r_i = point_rate_xyz(q, v, nc, j, vc[k]), point_rate_xyz(q, v, nc, i, vb[k])
            rate = direction[0] * (r_j[0] - r_i[0]) + direction[1] * (r_j[1] - r_i[1]) \
                + direction[2] * (r_j[2] - r_i[2])
            tension = scalars[k, 0] * (length - scalars[k, 2]) + scalars[k, 1] * rate
            pull = _scaled(direction, tension)
            _add_point_force(out, q, nc, i, vb[k], pull)
            _add_point_force(out, q, nc, j, vc[k], (-pull[0], -pull[1], -pull[2]))


@njit(cache=True, inline="always")
def _scaled(vector, factor):
    """factor · vector of a tuple (3), a tuple (3)."""
    return factor * vector[0], factor * vector[1], factor * vector[2]


@njit(cache=True)
def forces_kernel(q, v, nc, masses, inertias, gravity, kind, bi, bj, va, vb, vc, scalars):
    """Q_e + Q_v (n,), all loads included."""
    force = _inertial_forces(q, v, nc, masses, gravity, inertias)
    _applied_forces(force, q, v, nc, kind, bi, bj, va, vb, vc, scalars)
    return force


@njit(cache=True)
def mass_and_forces_kernel(q, v, nc, masses, inertias, gravity, kind, bi, bj, va, vb, vc, scalars):
    """M(q) (n, n) and Q_e + Q_v (n,), all loads included."""
    return (_mass_matrix(q, nc, masses, inertias),
            forces_kernel(q, v, nc, masses, inertias, gravity, kind, bi, bj, va, vb, vc, scalars))


class Dynamics:
    """Mass matrix and applied forces of a mechanism in absolute coordinates.

    The loads are compiled into a table evaluated by :func:`_applied_forces`: ``kind`` (k,),
    body indices ``bi, bj`` (k,), body-frame vectors ``va, vb, vc`` (k, 3) and ``scalars`` (k, 3):

    ==============  ==========================================================================
    kind            meaning
    ==============  ==========================================================================
    JOINT_TORQUE    τ = scalars[0] about axis va (on body i) acting on j, reaction on i
    JOINT_FORCE     f = scalars[0] along axis va (on i) at points vb (on i) / vc (on j)
    POINT           world force va at body point vb of body i
    TORQUE          world torque va on body i
    SPRING          points vb (i), vc (j); stiffness, damping, free length in scalars
    ==============  ==========================================================================
    """

    def __init__(self, mech: Mechanism):
        self.mech = mech
        self.layout = layout_of(mech)
        self.masses = mech.masses
        self.inertias = np.ascontiguousarray([b.inertia for b in mech.bodies])
        self.gravity = np.asarray(mech.gravity, dtype=float)
        rows = [self._load_row(f) for f in mech.forces]
        self._table = (
            np.array([r[0] for r in rows], dtype=np.int64),
            np.array([r[1] for r in rows], dtype=np.int64),
            np.array([r[2] for r in rows], dtype=np.int64),
            *(np.array([r[k] for r in rows], dtype=float).reshape(-1, 3) for k in (3, 4, 5, 6)),
        )

    def _load_row(self, force):
        """(kind, bi, bj, va, vb, vc, scalars) of one load."""
        index = self.mech.body_index
        zero = np.zeros(3)
        if isinstance(force, JointActuation):
            joint = self.mech.joint(force.joint)
            kind = F_JOINT_TORQUE if joint.type in ("revolute", "cylindrical") else F_JOINT_FORCE
            return (kind, index(joint.body1), index(joint.body2), joint.axis1, joint.point1,
                    joint.point2, (force.value, 0.0, 0.0))
        if isinstance(force, BodyForce):
            return (F_POINT, index(force.body), -1, force.force, force.point, zero, (0.0, 0.0, 0.0))
        if isinstance(force, BodyTorque):
            return (F_TORQUE, index(force.body), -1, force.torque, zero, zero, (0.0, 0.0, 0.0))
        if isinstance(force, SpringDamper):
            return (F_SPRING, index(force.body1), index(force.body2), zero, force.point1,
                    force.point2, (force.stiffness, force.damping, force.free_length))
        raise TypeError(f"unknown load {force!r}")

    def applied_forces(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Generalised forces of the load table alone (no gravity, no inertial terms), (n,)."""
        out = np.zeros(q.size)
        _applied_forces(out, q, v, self.layout.nc, *self._table)
        return out

    @property
    def kernel_args(self) -> tuple:
        """Arguments after (q, v) of :func:`mass_and_forces_kernel`."""
        return (self.layout.nc, self.masses, self.inertias, self.gravity, *self._table)

    def mass_and_forces(self, t: float, q: np.ndarray, v: np.ndarray):
        """M(q), shape (n, n), and Q_e + Q_v, shape (n,)  (loads are constant in t)."""
        return mass_and_forces_kernel(q, v, *self.kernel_args)
