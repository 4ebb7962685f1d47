"""Small dense solves compiled with numba: at these sizes (n ≤ ~50) SciPy's wrappers cost more than
the LAPACK call itself.  Always a factorisation (LAPACK gesv), never an explicit inverse."""

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
def min_norm_correction(jacobian, residual):
    """Φ_q⁺ r = Φ_qᵀ (Φ_q Φ_qᵀ)⁻¹ r for a full-row-rank Φ_q (m, n), r (m,)  (seed 002 eq. 126)."""
    return jacobian.T @ np.linalg.solve(jacobian @ jacobian.T, residual)
