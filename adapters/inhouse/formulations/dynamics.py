"""Equations of motion in absolute coordinates (Rouvinen 2003, ch. 3): the accelerations and
multipliers from the augmented system (Rouvinen 2003, eq. 76–77)

    [M   Φ_qᵀ] [q̈]   [Q_e + Q_v]
    [Φ_q  0  ] [λ] = [    γ    ]

with M and Q_e + Q_v of :mod:`~mbh._adapters.inhouse.formulations.mass_and_forces`, solved by
factorisations, never by explicit inverses.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from mbh._adapters.inhouse.bodies import kernels
from mbh._adapters.inhouse.bodies.bodykin import PLANAR_NC
from mbh._adapters.inhouse.formulations.mass_and_forces import (_mass_matrix, forces_kernel,
                                                                planar_mass_diagonal,
                                                                spatial_block_acceleration)
from mbh._adapters.inhouse.numerics.banded import (BANDED_MIN_ROWS, banded_spd_solve,
                                                   pattern_matvec, pattern_rmatvec)
from mbh._adapters.inhouse.numerics.linalg import (_cholesky, back_substitution, certified_solve,
                                                   column_gram, forward_substitution, matvec,
                                                   pivot_order, rmatvec, semidefinite_solve,
                                                   truncated_solve, weighted_gram)


@njit(cache=True)
def solve_augmented(mass, jacobian, force, gamma):
    """Solve the augmented system (Rouvinen 2003, eq. 77) by LU factorisation (LAPACK gesv).

    Returns
    -------
    acceleration : ndarray, shape (n,)
    multipliers : ndarray, shape (m,)
    """
    n, m = mass.shape[0], jacobian.shape[0]
    matrix = np.zeros((n + m, n + m))
    matrix[:n, :n] = mass
    matrix[:n, n:] = jacobian.T
    matrix[n:, :n] = jacobian
    rhs = np.concatenate((force, gamma))
    solution = np.linalg.solve(matrix, rhs)
    return solution[:n], solution[n:]


#: Singular values of the range-space matrix Φ_q M̃⁻¹ Φ_qᵀ below this fraction of the largest are
#: left out of the acceleration solve (:func:`range_space_acceleration`).  It scales as σ(Φ_q)²:
#: directions of Φ_q below ~1e-5 of its largest singular value.  On double_fourbar's first
#: singular passage 1e-10 is the most accurate cut tried; the plain LU solve of eq. 77 loses the
#: branch (figures: docs/measurements.md, section "In-house formulation").
ACCELERATION_CUT = 1e-10


@njit(cache=True)
def range_space_acceleration(mass, jacobian, force, gamma, cut):
    """q̈ of [M Φ_qᵀ; Φ_q 0][q̈; λ] = [Q; γ] (Rouvinen 2003, eq. 77), solved in the range space with the
    constraint directions of vanishing conditioning left out.

    With M̃ = M + ρ Φ_qᵀΦ_q (positive definite also for Euler parameters, whose M is singular
    along θ; ρ = tr M / ‖Φ_q‖²_F keeps both terms of one size) the system is equivalent to
    q̈ = M̃⁻¹(Q + Φ_qᵀμ) with (Φ_q M̃⁻¹ Φ_qᵀ) μ = γ − Φ_q M̃⁻¹ Q (μ = λ + ργ).  That matrix is
    solved by :func:`truncated_solve` at ``cut``: at a singular configuration the multiplier of
    the lost direction grows like 1/σ while its force Φ_qᵀμ stays finite, and a plain LU of
    eq. 77 turns round-off there into acceleration spikes (the error grows as dt shrinks).
    Redundant rows (σ = 0 everywhere) need no elimination beforehand.  Where the matrix is
    certified far from the cut (:func:`~mbh._adapters.inhouse.numerics.linalg.certified_spd_solve`, the common
    case) a Cholesky solve replaces the SVD, and where its redundant directions are certified
    below the cut and the others above it, a pivoted one
    (:func:`~mbh._adapters.inhouse.numerics.linalg.semidefinite_solve`); planar (diagonal) mass matrices use
    M⁻¹ directly.

    Parameters
    ----------
    mass : ndarray, shape (n, n)
    jacobian : ndarray, shape (m, n)
    force : ndarray, shape (n,)
    gamma : ndarray, shape (m,)
    cut : float
        Relative singular-value cut-off of Φ_q M̃⁻¹ Φ_qᵀ.

    Returns
    -------
    ndarray, shape (n,)
    """
    if jacobian.shape[0] > 0 and _is_positive_diagonal(mass):
        certified, acceleration = diagonal_mass_acceleration(1.0 / np.diag(mass), jacobian,
                                                             force, gamma, cut)
        if certified:
            return acceleration
    return augmented_mass_acceleration(mass, jacobian, force, gamma, cut, np.empty(0, np.int64))


@njit(cache=True)
def augmented_mass_acceleration(mass, jacobian, force, gamma, cut, pivots):
    """q̈ of :func:`range_space_acceleration` by its M̃ form, with the truncated SVD where the
    range-space matrix has no certificate, shape (n,).

    M̃ = L Lᵀ (Cholesky, plain loops) gives W = L⁻¹Φ_qᵀ (row i of ``weighted`` is L⁻¹Φ_q[i]ᵀ)
    and y = L⁻¹Q, so Φ_q M̃⁻¹ Φ_qᵀ = WᵀW, Φ_q M̃⁻¹ Q = Wᵀy and q̈ = L⁻ᵀ(y + Wμ): no LAPACK
    call, so the generated functions can trace it (slender spatial bodies, whose mass blocks
    :func:`spatial_block_acceleration` refuses, come here).  Where M̃ has a pivot that is not
    positive (a body free to spin about an axis of zero moment) LU solves it as before.
    ``pivots``: the start's pivot order of WᵀW where its rows are redundant
    (:func:`range_space_pivots`), else empty (:func:`_multipliers`).
    """
    positive, lower, weighted, reduced = _range_space_matrix(mass, jacobian)
    if not positive:
        return _lu_mass_acceleration(mass + _augmentation(mass, jacobian), jacobian, force,
                                     gamma, cut, pivots)
    free = forward_substitution(lower, force)
    if jacobian.shape[0] == 0:
        return back_substitution(lower, free)
    mu = _multipliers(reduced, gamma - matvec(weighted, free), cut, pivots)
    return back_substitution(lower, free + rmatvec(weighted, mu))


@njit(cache=True, inline="always")
def _augmentation(mass, jacobian):
    """ρ Φ_qᵀΦ_q (n, n) with ρ = tr M / ‖Φ_q‖²_F (0 without rows): M̃ = M + ρ Φ_qᵀΦ_q."""
    n, m = mass.shape[0], jacobian.shape[0]
    scale = 0.0
    for i in range(m):
        for c in range(n):
            scale += jacobian[i, c] * jacobian[i, c]
    trace = 0.0
    for c in range(n):
        trace += mass[c, c]
    rho = trace / scale if scale > 0.0 else 0.0
    return rho * column_gram(jacobian)


@njit(cache=True, inline="always")
def _range_space_matrix(mass, jacobian):
    """The M̃ form's factor and range-space matrix (:func:`augmented_mass_acceleration`):
    (positive, L (n, n) with M̃ = LLᵀ, W (m, n) with row i L⁻¹Φ_q[i]ᵀ, WWᵀ (m, m));
    ``positive`` False (W and WWᵀ empty) where M̃ has a pivot that is not positive."""
    n, m = mass.shape[0], jacobian.shape[0]
    positive, lower = _cholesky(mass + _augmentation(mass, jacobian))
    weighted = np.empty((m if positive else 0, n))
    reduced = np.zeros((m if positive else 0, m if positive else 0))
    if not positive:
        return positive, lower, weighted, reduced
    for i in range(m):
        weighted[i] = forward_substitution(lower, jacobian[i])
    for i in range(m):
        for j in range(i + 1):
            total = 0.0
            for c in range(n):
                total += weighted[i, c] * weighted[j, c]
            reduced[i, j] = reduced[j, i] = total
    return positive, lower, weighted, reduced


@njit(cache=True)
def range_space_pivots(mass, jacobian, cut):
    """The pivot order (rank,) int64 of the range-space matrix Φ_q M̃⁻¹ Φ_qᵀ of
    :func:`augmented_mass_acceleration` where its rows are redundant and the pivoted solve
    certifies it (:func:`~mbh._adapters.inhouse.numerics.linalg.pivot_order`); empty otherwise.
    Computed once at the start and passed to every later solve, it keeps the solve's path the
    same along a run (the generated functions' guards then hold)."""
    positive, _, _, reduced = _range_space_matrix(mass, jacobian)
    if not positive or jacobian.shape[0] == 0:
        return np.empty(0, np.int64)
    return pivot_order(reduced, cut)


@njit(cache=True)
def _multipliers(reduced, residual, cut, pivots):
    """μ of the range-space system ``reduced`` (m, m) μ = ``residual`` (m,): with the start's
    ``pivots`` (redundant rows, :func:`range_space_pivots`) the pivoted Cholesky in that order
    where certified; else Cholesky (plain or pivoted,
    :func:`~mbh._adapters.inhouse.numerics.linalg.certified_solve`) where certified, else the
    truncated SVD at ``cut``, shape (m,)."""
    if pivots.shape[0] > 0:
        certified, mu = semidefinite_solve(reduced, residual, cut, pivots)
        if certified:
            return mu
    certified, mu = certified_solve(reduced, residual, cut)
    if not certified:
        mu = truncated_solve(reduced, residual, cut)
    return mu


@njit(cache=True)
def _lu_mass_acceleration(augmented, jacobian, force, gamma, cut, pivots):
    """q̈ of :func:`augmented_mass_acceleration` for an M̃ (``augmented``, (n, n)) that is not
    positive definite: LU (LAPACK gesv) solves M̃ [free, columns] = [Q, Φ_qᵀ], shape (n,)."""
    n, m = augmented.shape[0], jacobian.shape[0]
    rhs = np.empty((n, m + 1))
    rhs[:, 0] = force
    rhs[:, 1:] = jacobian.T
    solved = np.linalg.solve(augmented, rhs)
    free, columns = solved[:, 0], np.ascontiguousarray(solved[:, 1:])
    if m == 0:
        return free
    return free + columns @ _multipliers(jacobian @ columns, gamma - jacobian @ free, cut,
                                         pivots)


@njit(cache=True)
def diagonal_mass_acceleration(inverse, jacobian, force, gamma, cut):
    """q̈ of :func:`range_space_acceleration` for a diagonal mass matrix (planar bodies), given
    M⁻¹'s diagonal ``inverse`` (n,): M⁻¹ is exact and cheap, S = Φ_q M⁻¹ Φ_qᵀ.  When S is
    certified far from the cut the solution is the same as the M̃ form's (unique; to round-off).

    Returns
    -------
    certified : bool
        False when S has no certificate (the caller then solves the M̃ form).
    acceleration : ndarray, shape (n,) or (0,)
    """
    certified, mu = certified_solve(weighted_gram(jacobian, inverse),
                                    gamma - matvec(jacobian, inverse * force), cut)
    if not certified:
        return False, np.empty(0)
    return True, inverse * (force + rmatvec(jacobian, mu))


@njit(cache=True)
def _is_positive_diagonal(matrix):
    """True when a square matrix is diagonal with positive entries (planar mass matrices)."""
    k = matrix.shape[0]
    for i in range(k):
        if not matrix[i, i] > 0.0:
            return False
        for j in range(k):
            if i != j and matrix[i, j] != 0.0:
                return False
    return True


@njit(cache=True)
def index1_acceleration(q, v, t, alpha, beta, rows, constraint_args, dynamics_args,
                        sparsity_arrays):
    """q̈ of the augmented index-1 form with Baumgarte terms, in one compiled call.

    Solves [M Φ_qᵀ; Φ_q 0][q̈; λ] = [Q; γ − 2αΦ̇ − β²Φ] on the constraint ``rows`` (Rouvinen 2003, eq. 77
    and 110; α = β = 0 is the unstabilised form) by :func:`range_space_acceleration`.
    ``constraint_args`` are :attr:`ConstraintSystem.kernel_args`, ``dynamics_args``
    :attr:`Dynamics.kernel_args`, ``sparsity_arrays`` :attr:`ConstraintSystem.sparsity`'s arrays:
    with every row kept, planar bodies and :data:`~mbh._adapters.inhouse.numerics.banded.BANDED_MIN_ROWS` rows
    or more, the range-space matrix is solved banded (:func:`~mbh._adapters.inhouse.numerics.banded.
    banded_spd_solve`), else by :func:`range_space_acceleration`.
    """
    every_row = rows.shape[0] == constraint_args[-1]
    jac = kernels.jacobian(q, t, constraint_args)
    target = kernels.gamma(q, v, t, constraint_args)
    if not every_row:
        jac, target = jac[rows], target[rows]
    row_columns = sparsity_arrays[0]
    if alpha != 0.0 or beta != 0.0:
        residual = kernels.phi(q, t, constraint_args)
        if every_row:
            target = target - 2.0 * alpha * pattern_matvec(jac, row_columns, v) \
                - beta * beta * residual
        else:
            target = target - 2.0 * alpha * (jac @ v) - beta * beta * residual[rows]
    force = forces_kernel(q, v, *dynamics_args)
    nc, masses, inertias = dynamics_args[0], dynamics_args[1], dynamics_args[2]
    if every_row and jac.shape[0] >= BANDED_MIN_ROWS and nc == PLANAR_NC:
        inverse = 1.0 / planar_mass_diagonal(masses, inertias)
        accepted, mu = banded_spd_solve(
            jac, inverse, target - pattern_matvec(jac, row_columns, inverse * force),
            ACCELERATION_CUT, sparsity_arrays)
        if accepted:
            return inverse * (force + pattern_rmatvec(jac, row_columns, mu))
    if every_row and nc != PLANAR_NC:
        accepted, acceleration = spatial_block_acceleration(
            q, jac, force, target, nc, masses, inertias, constraint_args[1], constraint_args[2],
            constraint_args[4], sparsity_arrays, ACCELERATION_CUT)
        if accepted:
            return acceleration
    if nc != PLANAR_NC or jac.shape[0] == 0:  # range_space_acceleration's M̃ branch: an Euler-
        # parameter M is singular, never positive diagonal (a test there would guard on zeros)
        return augmented_mass_acceleration(_mass_matrix(q, nc, masses, inertias), jac, force,
                                           target, ACCELERATION_CUT, np.empty(0, np.int64))
    diagonal = planar_mass_diagonal(masses, inertias)  # range_space_acceleration's diagonal
    if np.all(diagonal > 0.0):                          # branch without assembling M
        accepted, acceleration = diagonal_mass_acceleration(1.0 / diagonal, jac, force, target,
                                                            ACCELERATION_CUT)
        if accepted:
            return acceleration
    return augmented_mass_acceleration(_mass_matrix(q, nc, masses, inertias), jac, force, target,
                                       ACCELERATION_CUT, np.empty(0, np.int64))


@njit(cache=True)
def acceleration_jacobian(q, v, t, alpha, beta, rows, constraint_args, dynamics_args,
                          sparsity_arrays, a0):
    """[∂q̈/∂q, ∂q̈/∂q̇] of :func:`index1_acceleration` at (q, q̇, t) by forward differences, shape
    (n, 2n), in one compiled call: the differences of
    :func:`mbh._adapters.integrators.newton.first_order_jacobian` (step √ε · max(1, |y_j|)), 2n
    evaluations of the fused right-hand side.  ``a0`` is q̈ at (q, q̇), shape (n,)."""
    n = q.shape[0]
    out = np.empty((n, 2 * n))
    root_eps = np.sqrt(np.finfo(np.float64).eps)
    for j in range(2 * n):
        q_shift, v_shift = q.copy(), v.copy()
        if j < n:
            q_shift[j] += root_eps * max(1.0, abs(q[j]))
            step = q_shift[j] - q[j]
        else:
            v_shift[j - n] += root_eps * max(1.0, abs(v[j - n]))
            step = v_shift[j - n] - v[j - n]
        shifted = index1_acceleration(q_shift, v_shift, t, alpha, beta, rows, constraint_args,
                                      dynamics_args, sparsity_arrays)
        out[:, j] = (shifted - a0) / step
    return out
