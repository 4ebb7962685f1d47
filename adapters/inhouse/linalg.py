"""Small dense solves compiled with numba: at these sizes (n ≤ ~50) SciPy's wrappers cost more than
the LAPACK call itself.  Always a factorisation (LAPACK gesv, potrf or gesdd), never an explicit
inverse; the triangular substitutions after a Cholesky factorisation are written out because numba
offers no triangular solve."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def solve(matrix, rhs):
    """x with matrix @ x = rhs, matrix (k, k), rhs (k,); raises on a singular matrix."""
    return np.linalg.solve(matrix, rhs)


@njit(cache=True)
def solve_matrix(matrix, rhs):
    """X with matrix @ X = rhs, matrix (k, k), rhs (k, r)."""
    return np.linalg.solve(matrix, rhs)


@njit(cache=True)
def truncated_solve(matrix, rhs, cut):
    """Minimum-norm least-squares x of matrix @ x ≈ rhs with the singular values below
    ``cut`` × the largest left out (a truncated SVD: LAPACK gesdd), matrix (m, n), rhs (m,).

    Near a singular configuration the directions with tiny singular values are the ones a plain
    solve divides by ≈ 0; dropping them leaves those rows unenforced instead of amplifying the
    round-off and drift in them.  Exactly redundant rows (σ = 0) are dropped the same way.
    """
    left, values, right = np.linalg.svd(matrix, full_matrices=False)
    keep = values > cut * values[0]
    coefficients = (left[:, keep].T @ rhs) / values[keep]
    return right[keep].T @ coefficients


#: A Cholesky solve is used only when the condition-number bound of :func:`certified_spd_solve`
#: is this factor inside the truncation threshold, so that the bound's own round-off cannot
#: let through a matrix the truncated SVD would have cut.
CERTIFICATE_MARGIN = 10.0


@njit(cache=True)
def _forward(lower, rhs):
    """y with lower @ y = rhs (forward substitution), lower (k, k) lower triangular."""
    k = rhs.shape[0]
    y = np.empty(k)
    for i in range(k):
        s = rhs[i]
        for j in range(i):
            s -= lower[i, j] * y[j]
        y[i] = s / lower[i, i]
    return y


@njit(cache=True)
def _backward_transposed(lower, rhs):
    """x with lowerᵀ @ x = rhs (back substitution)."""
    k = rhs.shape[0]
    x = np.empty(k)
    for i in range(k - 1, -1, -1):
        s = rhs[i]
        for j in range(i + 1, k):
            s -= lower[j, i] * x[j]
        x[i] = s / lower[i, i]
    return x


@njit(cache=True)
def _inverse_frobenius_squared(lower):
    """‖L⁻¹‖_F² of a lower-triangular L (k, k), column by column of L⁻¹ (forward substitution)."""
    k = lower.shape[0]
    total = 0.0
    column = np.empty(k)
    for c in range(k):
        for i in range(k):
            if i < c:
                column[i] = 0.0
                continue
            s = 1.0 if i == c else 0.0
            for j in range(c, i):
                s -= lower[i, j] * column[j]
            column[i] = s / lower[i, i]
            total += column[i] * column[i]
    return total


@njit(cache=True)
def certified_spd_solve(matrix, rhs, cut):
    """Cholesky solve of a symmetric positive-definite matrix @ x = rhs, matrix (k, k), rhs (k,),
    when its condition number is certified below 1/(CERTIFICATE_MARGIN · cut).

    Certificate: κ₂(S) = ‖S‖₂ ‖S⁻¹‖₂ ≤ ‖S‖_F ‖L⁻¹‖_F² with S = LLᵀ.  Below that bound no singular
    value falls under ``cut`` × the largest, so :func:`truncated_solve` at ``cut`` would keep every
    direction and return the same solution (to round-off); the Cholesky solve costs a fraction of
    the SVD.

    Returns
    -------
    certified : bool
        False when the matrix is not positive definite or the bound fails; x is then empty.
    x : ndarray, shape (k,) or (0,)
    """
    k = rhs.shape[0]
    if k == 0:
        return True, np.empty(0)
    try:
        lower = np.linalg.cholesky(matrix)
    except Exception:  # noqa: BLE001 — not positive definite: no certificate
        return False, np.empty(0)
    bound = np.sqrt(np.sum(matrix * matrix)) * _inverse_frobenius_squared(lower)
    if not bound * CERTIFICATE_MARGIN * cut < 1.0:
        return False, np.empty(0)
    return True, _backward_transposed(lower, _forward(lower, rhs))


@njit(cache=True)
def min_norm_solve(matrix, rhs, cut):
    """:func:`truncated_solve` of a wide matrix (m, n), m ≤ n, rhs (m,), by the normal equations
    x = Aᵀ(AAᵀ)⁻¹ rhs when :func:`certified_spd_solve` certifies AAᵀ at cut² (σ(AAᵀ) = σ(A)²), else
    by the truncated SVD itself."""
    certified, y = certified_spd_solve(matrix @ matrix.T, rhs, cut * cut)
    if certified:
        return matrix.T @ y
    return truncated_solve(matrix, rhs, cut)
