"""Sparse range-space solves for large mechanisms: the matrices Φ_q W Φ_qᵀ (W diagonal: M⁻¹ of
planar bodies, or I for the minimum-norm projection) are banded once their rows are put in
reverse Cuthill–McKee order, and are factorised by LAPACK's banded Cholesky (dpbtrf, dpbtrs),
called from compiled code through SciPy's LAPACK.

A constraint row touches at most two bodies, so Φ_q W Φ_qᵀ couples only rows that share a body.
:class:`Sparsity` records, once per mechanism, the columns each row can touch, the rows each body
carries and a row order that keeps those couplings near the diagonal; every product with Φ_q
then costs O(rows), and the factorisation O(rows · bandwidth²) instead of O(rows³): on the
N-four-bar the bandwidth stays the same for every N.

The dense path's certificate (:func:`~mbh._adapters.inhouse.numerics.linalg.certified_spd_solve`) needs
‖L⁻¹‖_F, an O(rows²) computation; here an estimate of the 2-norm condition number takes its place
(Gershgorin's bound on λ_max over an inverse-iteration estimate of λ_min, O(rows · bandwidth) per
iteration).  LAPACK's dpbcon estimates the 1-norm condition number instead, which exceeds the
2-norm one by up to the number of rows and rejected most projections on the N-four-bar at N = 64.
Past the margin the caller falls back to the dense truncated SVD exactly as the dense path does.
"""

from __future__ import annotations

from dataclasses import dataclass

import llvmlite.binding
import numpy as np
import scipy.sparse
from numba import njit, types
from numba.extending import get_cython_function_address
from scipy.sparse.csgraph import reverse_cuthill_mckee

from mbh._adapters.inhouse.numerics.linalg import (gram_condition_bound, min_norm_solve,
                                                   min_norm_solve_and_bound)

#: From this many constraint rows on the banded solves are used: on n_fourbar@N the dense and
#: banded solves cost about the same near 26 rows, and the banded ones win from there on
#: (figures: docs/measurements.md, section "In-house step cost").
BANDED_MIN_ROWS = 30


def _lapack(name: str, n_args: int):
    """A LAPACK routine of scipy.linalg.cython_lapack as an external function of pointers
    (registered under its own symbol, so that numba can cache the functions that call it)."""
    symbol = f"mbh_lapack_{name}"
    llvmlite.binding.add_symbol(symbol, get_cython_function_address("scipy.linalg.cython_lapack",
                                                                    name))
    return types.ExternalFunction(symbol, types.void(*([types.voidptr] * n_args)))


_dpbtrf = _lapack("dpbtrf", 6)   # uplo, n, kd, ab, ldab, info
_dpbtrs = _lapack("dpbtrs", 9)   # uplo, n, kd, nrhs, ab, ldab, b, ldb, info

#: Inverse iterations of the smallest-eigenvalue estimate of :func:`banded_spd_solve`.
INVERSE_ITERATIONS = 8
#: A banded Cholesky solve is used only when the condition-number estimate is this factor inside
#: the truncation threshold.  Unlike the dense path's bound
#: (:data:`~mbh._adapters.inhouse.numerics.linalg.BOUND_MARGIN`) the estimate can fall short of κ₂ (the
#: inverse iterations may not have converged), so the factor is wider.
ESTIMATE_MARGIN = 10.0


@dataclass(frozen=True)
class Sparsity:
    """Where Φ_q of a mechanism can be non-zero, and a banded order of its rows.

    Attributes
    ----------
    row_columns : ndarray of int64, shape (m, w)
        Columns row r can touch (the coordinates of its one or two bodies), −1 padded.
    body_row_start, body_rows : ndarray of int64, shapes (b + 1,), (k,)
        Rows touching body i are ``body_rows[body_row_start[i]:body_row_start[i + 1]]``.
    body_columns : ndarray of int64, shape (b, nc)
        Coordinates of each body.
    position : ndarray of int64, shape (m,)
        Place of row r in the reverse Cuthill–McKee order.
    bandwidth : int
        Largest |position[r] − position[s]| over rows that share a body.
    """

    row_columns: np.ndarray
    body_row_start: np.ndarray
    body_rows: np.ndarray
    body_columns: np.ndarray
    position: np.ndarray
    bandwidth: int

    @property
    def arrays(self) -> tuple:
        return (self.row_columns, self.body_row_start, self.body_rows, self.body_columns,
                self.position, self.bandwidth)


def sparsity(row_bodies: np.ndarray, n_bodies: int, nc: int) -> Sparsity:
    """The :class:`Sparsity` of constraint rows whose bodies are ``row_bodies`` (m, 2) (−1: none)."""
    m = row_bodies.shape[0]
    row_columns = np.full((m, 2 * nc), -1, dtype=np.int64)
    members: list[list[int]] = [[] for _ in range(n_bodies)]
    for r, bodies in enumerate(row_bodies):
        for slot, body in enumerate(b for b in dict.fromkeys(bodies.tolist()) if b >= 0):
            row_columns[r, slot * nc:(slot + 1) * nc] = np.arange(body * nc, (body + 1) * nc)
            members[body].append(r)
    start = np.cumsum([0] + [len(rows) for rows in members]).astype(np.int64)
    rows = np.array([r for group in members for r in group], dtype=np.int64)
    pairs = [(r, s) for group in members for r in group for s in group]
    graph = scipy.sparse.coo_matrix((np.ones(len(pairs)), tuple(np.array(pairs).T)),
                                    shape=(m, m)).tocsr()
    order = reverse_cuthill_mckee(graph, symmetric_mode=True)
    position = np.empty(m, dtype=np.int64)
    position[order] = np.arange(m)
    bandwidth = max((abs(int(position[r] - position[s])) for r, s in pairs), default=0)
    columns = np.arange(n_bodies * nc, dtype=np.int64).reshape(n_bodies, nc)
    return Sparsity(row_columns, start, rows, columns, position, bandwidth)


@njit(cache=True)
def pattern_matvec(matrix, row_columns, x):
    """matrix @ x reading only the pattern's columns of each row, shape (m,)."""
    out = np.zeros(matrix.shape[0])
    for r in range(matrix.shape[0]):
        for c in row_columns[r]:
            if c >= 0:
                out[r] += matrix[r, c] * x[c]
    return out


@njit(cache=True)
def pattern_rmatvec(matrix, row_columns, y):
    """matrixᵀ @ y reading only the pattern's columns of each row, shape (n,)."""
    out = np.zeros(matrix.shape[1])
    for r in range(matrix.shape[0]):
        for c in row_columns[r]:
            if c >= 0:
                out[c] += matrix[r, c] * y[r]
    return out


@njit(cache=True)
def _banded_product(matrix, weights, body_row_start, body_rows, body_columns, position,
                    bandwidth):
    """Lower band of P (A W Aᵀ) Pᵀ in LAPACK's storage: shape (kd + 1, m), Fortran order, entry
    (i, j), i ≥ j, at [i − j, j]; and the 1-norm of the whole symmetric matrix."""
    m = matrix.shape[0]
    band = np.zeros((m, bandwidth + 1)).T  # a Fortran-ordered (kd + 1, m) view
    for body in range(body_columns.shape[0]):
        rows = body_rows[body_row_start[body]:body_row_start[body + 1]]
        for r in rows:
            for s in rows:
                i, j = position[r], position[s]
                if i < j:
                    continue
                total = 0.0
                for c in body_columns[body]:
                    total += matrix[r, c] * weights[c] * matrix[s, c]
                band[i - j, j] += total
    column_sums = np.zeros(m)
    for j in range(m):
        for d in range(bandwidth + 1):
            if j + d < m:
                value = abs(band[d, j])
                column_sums[j] += value
                if d > 0:
                    column_sums[j + d] += value
    return band, column_sums.max() if m else 0.0


@njit(cache=True)
def _band_arguments(m, bandwidth):
    """The scalar arguments of dpbtrf/dpbtrs as the one-element arrays their pointers need:
    uplo = "L", n = m, kd = bandwidth, nrhs = 1 (``one``), ldab = bandwidth + 1 (``lead``) and
    ``info``."""
    return (np.array([ord("L")], dtype=np.uint8), np.array([m], dtype=np.int32),
            np.array([bandwidth], dtype=np.int32), np.array([bandwidth + 1], dtype=np.int32),
            np.array([1], dtype=np.int32), np.zeros(1, dtype=np.int32))


@njit(cache=True)
def _banded_factor(matrix, weights, sparsity_arrays):
    """Banded Cholesky of S = A W Aᵀ (rows in the order of ``sparsity_arrays``) with the estimate
    of its 2-norm condition number that :func:`banded_spd_solve` certifies: the largest absolute
    row sum of S (≥ λ_max) times the estimate of 1/λ_min from :data:`INVERSE_ITERATIONS` steps of
    inverse iteration with the factor (the Rayleigh quotient of S⁻¹, converging to 1/λ_min from
    below).

    Returns
    -------
    positive : bool
        False when S is not positive definite (the other returns are then meaningless).
    band : ndarray, shape (kd + 1, m)
        The factor in LAPACK's banded storage.
    condition : float
        The estimate of κ₂(S).
    """
    _, body_row_start, body_rows, body_columns, position, bandwidth = sparsity_arrays
    m = matrix.shape[0]
    band, norm = _banded_product(matrix, weights, body_row_start, body_rows, body_columns,
                                 position, bandwidth)
    lower, size, kd, lead, one, info = _band_arguments(m, bandwidth)
    _dpbtrf(lower.ctypes, size.ctypes, kd.ctypes, band.ctypes, lead.ctypes, info.ctypes)
    if info[0] != 0:
        return False, band, np.inf
    vector = np.ones(m) / np.sqrt(m)
    inverse_estimate = 0.0
    for _ in range(INVERSE_ITERATIONS):
        image = vector.copy()
        _dpbtrs(lower.ctypes, size.ctypes, kd.ctypes, one.ctypes, band.ctypes, lead.ctypes,
                image.ctypes, size.ctypes, info.ctypes)
        inverse_estimate = vector @ image
        vector = image / np.sqrt(image @ image)
    return True, band, norm * inverse_estimate


@njit(cache=True)
def banded_spd_solve(matrix, weights, rhs, cut, sparsity_arrays):
    """Solve (A W Aᵀ) x = rhs by banded Cholesky when the estimated 2-norm condition number of
    S = A W Aᵀ (:func:`_banded_factor`) is below 1/(ESTIMATE_MARGIN · cut), A (m, n) holding
    the pattern of ``sparsity_arrays`` (:attr:`Sparsity.arrays`), W = diag(weights) (n,) positive.

    Returns
    -------
    accepted : bool
        False when the matrix is not positive definite or its estimated condition too large.
    x : ndarray, shape (m,) or (0,)
    """
    accepted, x, _, _ = banded_spd_solve_and_condition(matrix, weights, rhs, cut, sparsity_arrays)
    return accepted, x


@njit(cache=True)
def banded_spd_solve_and_condition(matrix, weights, rhs, cut, sparsity_arrays):
    """:func:`banded_spd_solve` and, from the same factorisation, its estimate of κ₂(A W Aᵀ).

    Returns
    -------
    accepted : bool
    x : ndarray, shape (m,) or (0,)
    positive : bool
        False when A W Aᵀ is not positive definite (the estimate is then inf).
    condition : float
    """
    position, bandwidth = sparsity_arrays[4], sparsity_arrays[5]
    m = matrix.shape[0]
    positive, band, condition = _banded_factor(matrix, weights, sparsity_arrays)
    if not (positive and ESTIMATE_MARGIN * cut * condition < 1.0):
        return False, np.empty(0), positive, condition
    lower, size, kd, lead, one, info = _band_arguments(m, bandwidth)
    permuted = np.empty(m)
    for r in range(m):
        permuted[position[r]] = rhs[r]
    _dpbtrs(lower.ctypes, size.ctypes, kd.ctypes, one.ctypes, band.ctypes, lead.ctypes,
            permuted.ctypes, size.ctypes, info.ctypes)
    solution = np.empty(m)
    for r in range(m):
        solution[r] = permuted[position[r]]
    return True, solution, positive, condition


@njit(cache=True)
def conditioning_indicator(matrix, sparsity_arrays):
    """ρ̂ = κ̂(Φ_q Φ_qᵀ)^(-1/2), an estimate of σ_min/σ_max of Φ_q = ``matrix`` (m, n) from the
    certificates' condition estimates (:func:`~mbh._adapters.inhouse.numerics.linalg.gram_condition_bound`
    below :data:`BANDED_MIN_ROWS` rows, :func:`_banded_factor` from there on); 0 when Φ_q Φ_qᵀ
    is not positive definite (rank lost, or redundant rows kept).  Near a singular position
    σ_min/σ_max falls linearly with the distance to it, and so does ρ̂: the same fraction of it
    to within a factor that varies smoothly (between 1/m and 1).
    """
    if matrix.shape[0] >= BANDED_MIN_ROWS:
        positive, _, condition = _banded_factor(matrix, np.ones(matrix.shape[1]),
                                                sparsity_arrays)
    else:
        positive, condition = gram_condition_bound(matrix)
    return _indicator(positive, condition)


@njit(cache=True, inline="always")
def _indicator(positive, condition):
    """ρ̂ of a condition estimate of Φ_q Φ_qᵀ (:func:`conditioning_indicator`)."""
    if not positive or not condition < np.inf:
        return 0.0
    return 1.0 / np.sqrt(condition)


@njit(cache=True)
def min_norm_correction(matrix, rhs, cut, sparsity_arrays):
    """Φ_q⁺ r of the projections (Rouvinen 2003, eq. 126) as :func:`~mbh._adapters.inhouse.numerics.linalg.min_norm_solve`
    does it, with the banded normal equations Aᵀ(AAᵀ)⁻¹ r for :data:`BANDED_MIN_ROWS` rows or
    more; ``matrix`` (m, n) has every row of ``sparsity_arrays``.  Shape (n,)."""
    return min_norm_correction_and_indicator(matrix, rhs, cut, sparsity_arrays)[0]


@njit(cache=True)
def min_norm_correction_and_indicator(matrix, rhs, cut, sparsity_arrays):
    """:func:`min_norm_correction` and, from the same factorisation of Φ_q Φ_qᵀ, ρ̂ of
    :func:`conditioning_indicator` (the velocity projection's Φ_q is the one whose ρ̂ the placed
    passages need: one factorisation instead of two).

    Returns
    -------
    correction : ndarray, shape (n,)
    indicator : float
    """
    if matrix.shape[0] >= BANDED_MIN_ROWS:
        accepted, y, positive, condition = banded_spd_solve_and_condition(
            matrix, np.ones(matrix.shape[1]), rhs, cut * cut, sparsity_arrays)
        if accepted:
            return pattern_rmatvec(matrix, sparsity_arrays[0], y), _indicator(positive, condition)
        return min_norm_solve(matrix, rhs, cut), _indicator(positive, condition)
    correction, positive, bound = min_norm_solve_and_bound(matrix, rhs, cut)
    return correction, _indicator(positive, bound)
