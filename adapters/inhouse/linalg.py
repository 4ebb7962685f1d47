"""Small dense solves compiled with numba: at these sizes (n ≤ ~50) SciPy's wrappers cost more than
the LAPACK call itself.  Always a factorisation (LAPACK gesv or gesdd), never an explicit inverse."""

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
