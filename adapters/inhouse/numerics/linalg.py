"""Small dense solves compiled with numba: at these sizes (n ≤ ~50) SciPy's wrappers cost more than
the LAPACK call itself, and for the range-space matrices of the right-hand side and the projection
(a few to a few tens of rows) numba's own BLAS/LAPACK calls cost more than the arithmetic, so the
Cholesky factorisation, its substitutions and the products with the constraint Jacobian are plain
loops here.  Always a factorisation (LAPACK gesv or gesdd, or the Cholesky factor), never an
explicit inverse."""

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


@njit(cache=True, inline="always")
def skippable(x):
    """True for an exact zero, whose products a sum may leave out: they add ±0 and change no
    finite sum, so skipping them saves work and decides nothing.  (Traced code,
    :mod:`mbh._adapters.inhouse.codegen.tracing`, never skips: there every entry that is not a constant zero
    is kept.)"""
    return x == 0.0


@njit(cache=True, inline="always")
def larger(a, b):
    """max(a, b) of two floats.  (Traced code, :mod:`mbh._adapters.inhouse.codegen.tracing`,
    records it as one max node without a guard: which of the two is larger may change from call
    to call without changing the path.)"""
    return a if a > b else b


#: A Cholesky solve is used only when the condition-number bound of :func:`certified_spd_solve`
#: is this factor inside the truncation threshold, so that the bound's own round-off cannot
#: let through a matrix the truncated SVD would have cut.  The bound is rigorous in exact
#: arithmetic; its computed value is off by ~k·ε·κ relative (forming S, its Cholesky factor and
#: L⁻¹), ~2e-5 for k = 20 rows even at κ = 1e10, so a factor 2 is ample.  It was 10: on the double
#: four-bar (rk4+direct, 1e-2 s) the projections then took the SVD at 154 of 1001 samples, where
#: 25 truly truncate; at 2, at 65 (docs/measurements.md, "In-house step cost").
BOUND_MARGIN = 2.0


@njit(cache=True)
def _cholesky(matrix):
    """Lower-triangular L with L Lᵀ = matrix (k, k) from its lower triangle (the triangle LAPACK
    potrf reads through numpy's ``cholesky``), column by column.

    Returns
    -------
    positive : bool
        False at the first pivot that is not positive: potrf's rule for "not positive definite"
        (a NaN pivot too, which OpenBLAS's potrf lets through; :func:`certified_spd_solve`
        refused such a matrix by its NaN bound before, so its decision is unchanged); L is then
        incomplete.
    lower : ndarray, shape (k, k)
    """
    k = matrix.shape[0]
    lower = np.zeros((k, k))
    for j in range(k):
        pivot = matrix[j, j]
        for p in range(j):
            pivot -= lower[j, p] * lower[j, p]
        if not pivot > 0.0:
            return False, lower
        diagonal = np.sqrt(pivot)
        lower[j, j] = diagonal
        for i in range(j + 1, k):
            s = matrix[i, j]
            for p in range(j):
                s -= lower[i, p] * lower[j, p]
            lower[i, j] = s / diagonal
    return True, lower


@njit(cache=True)
def _cholesky_solve(lower, rhs):
    """x with lower @ lowerᵀ @ x = rhs, lower (k, k) lower triangular: forward then back
    substitution (numba offers no triangular solve)."""
    return back_substitution(lower, forward_substitution(lower, rhs))


@njit(cache=True)
def forward_substitution(lower, rhs):
    """x with lower @ x = rhs, lower (k, k) lower triangular with a non-zero diagonal, rhs (k,),
    shape (k,)."""
    k = rhs.shape[0]
    x = np.empty(k)
    for i in range(k):
        s = rhs[i]
        for j in range(i):
            s -= lower[i, j] * x[j]
        x[i] = s / lower[i, i]
    return x


@njit(cache=True)
def back_substitution(lower, rhs):
    """x with lowerᵀ @ x = rhs, lower (k, k) lower triangular with a non-zero diagonal, rhs (k,),
    shape (k,)."""
    k = rhs.shape[0]
    x = rhs.copy()
    for i in range(k - 1, -1, -1):
        s = x[i]
        for j in range(i + 1, k):
            s -= lower[j, i] * x[j]
        x[i] = s / lower[i, i]
    return x


@njit(cache=True)
def _inverse_frobenius_squared(lower):
    """‖L⁻¹‖_F² of a lower-triangular L (k, k), row by row of L⁻¹: row i is
    (e_iᵀ − Σ_{j<i} L_ij row_j) / L_ii, each row a sum of earlier rows (contiguous, independent
    entries) rather than a chain of dependent dot products."""
    k = lower.shape[0]
    inverse = np.zeros((k, k))
    total = 0.0
    for i in range(k):
        inverse[i, i] = 1.0
        for j in range(i):
            factor = lower[i, j]
            for c in range(j + 1):
                inverse[i, c] -= factor * inverse[j, c]
        for c in range(i + 1):
            inverse[i, c] /= lower[i, i]
            total += inverse[i, c] * inverse[i, c]
    return total


@njit(cache=True)
def _comparison_bound(lower):
    """A bound ≥ ‖L⁻¹‖₂² of a lower-triangular L (k, k) with a positive diagonal, in O(k²).

    The comparison matrix M(L) (|l_ii| on the diagonal, −|l_ij| below) has |L⁻¹| ≤ M(L)⁻¹
    entry by entry (N. J. Higham, *Accuracy and Stability of Numerical Algorithms*, 2nd ed., SIAM
    2002, §8.3), so ‖L⁻¹‖_∞ ≤ ‖M(L)⁻¹ e‖_∞ and ‖L⁻¹‖₁ ≤ ‖M(L)⁻ᵀ e‖_∞ (e the ones), and
    ‖L⁻¹‖₂² ≤ ‖L⁻¹‖₁ ‖L⁻¹‖_∞.  Both solves add only positive terms, so their round-off is
    relative (k ε), unlike a difference of large numbers.  It can overestimate by far more than
    :func:`_inverse_frobenius_squared` (by 2^k for some matrices); on the shipped scenes' range-
    space matrices it stays far inside the 1e9 that certifies (figures: docs/measurements.md,
    section "In-house formulation").
    """
    k = lower.shape[0]
    rows, columns = np.empty(k), np.empty(k)
    for i in range(k):
        s = 1.0
        for j in range(i):
            s += abs(lower[i, j]) * rows[j]
        rows[i] = s / lower[i, i]
    for i in range(k - 1, -1, -1):
        s = 1.0
        for j in range(i + 1, k):
            s += abs(lower[j, i]) * columns[j]
        columns[i] = s / lower[i, i]
    return np.max(rows) * np.max(columns)


@njit(cache=True)
def _frobenius(matrix):
    """‖matrix‖_F of a 2-D array."""
    total = 0.0
    for i in range(matrix.shape[0]):
        for j in range(matrix.shape[1]):
            total += matrix[i, j] * matrix[i, j]
    return np.sqrt(total)


@njit(cache=True)
def certified_spd_solve(matrix, rhs, cut):
    """Cholesky solve of a symmetric positive-definite matrix @ x = rhs, matrix (k, k), rhs (k,),
    when its condition number is certified below 1/(BOUND_MARGIN · cut).

    Certificate: κ₂(S) = ‖S‖₂ ‖S⁻¹‖₂ ≤ ‖S‖_F ‖L⁻¹‖₂² with S = LLᵀ, and ‖L⁻¹‖₂² is bounded
    first by :func:`_comparison_bound` (O(k²)) and, only when that bound is too loose, by
    ‖L⁻¹‖_F² (:func:`_inverse_frobenius_squared`, O(k³): on a 20-row S as much as the
    factorisation); either bound below the limit certifies.  Below it no singular value falls
    under ``cut`` × the largest, so :func:`truncated_solve` at ``cut`` would keep every direction
    and return the same solution (to round-off); the Cholesky solve costs a fraction of the SVD.
    The factorisation is written out (:func:`_cholesky`): at these sizes a LAPACK call costs more
    than the arithmetic.

    Returns
    -------
    certified : bool
        False when the matrix is not positive definite or the bound fails; x is then empty.
    x : ndarray, shape (k,) or (0,)
    """
    k = rhs.shape[0]
    if k == 0:
        return True, np.empty(0)
    positive, lower = _cholesky(matrix)
    if not positive:
        return False, np.empty(0)
    if not _condition_certified(_frobenius(matrix), lower, cut):
        return False, np.empty(0)
    return True, _cholesky_solve(lower, rhs)


@njit(cache=True)
def _condition_certified(size, lower, cut):
    """True when ``size`` ‖L⁻¹‖₂² (size = ‖S‖_F, L = ``lower`` (k, k) its Cholesky factor, or
    that of a principal submatrix of S) is certified below 1/(BOUND_MARGIN · cut): by
    :func:`_comparison_bound` first, else by ‖L⁻¹‖_F² (:func:`certified_spd_solve`)."""
    return (size * _comparison_bound(lower) * BOUND_MARGIN * cut < 1.0
            or size * _inverse_frobenius_squared(lower) * BOUND_MARGIN * cut < 1.0)


#: :func:`semidefinite_solve` leaves out only directions whose eigenvalues it certifies below this
#: fraction of ‖S‖_F (and below the cut): redundant rows, whose directions are null to round-off.
#: A direction that is merely small, as at a singular position, stays with the truncated SVD,
#: which decided it before, so that singular passages keep their results to the bit.  Measured
#: ‖S N‖_F / ‖S‖_F (2026-11-28, rk4+direct and ab5+baumgarte runs, acceleration and projection
#: solves): redundant rows 7e-18 … 5.1e-14 (Bricard's mechanism, a four-bar of four parallel
#: revolutes); the small directions at the double and parallelogram four-bars' singular
#: positions 6.5e-8 … 2.1e-5.  The test is 4 √k ‖S N‖_F < NULL_LEVEL ‖S‖_F: ~800 times above the
#: first (k = 35), ~700 times below the second (k = 8 and 14).
NULL_LEVEL = 1e-9


@njit(cache=True)
def _pivoted_cholesky(matrix, cut, pivots):
    """Cholesky factorisation of a symmetric positive semi-definite matrix (k, k) with diagonal
    pivoting (LAPACK pstrf's choice: the largest remaining diagonal of the Schur complement
    next), left-looking, stopped when no remaining diagonal exceeds ``cut`` × the largest
    diagonal of the matrix.  Given ``pivots`` (r,) int64, r ≥ 1, the rows are taken in that
    order instead (the order an earlier factorisation chose, :func:`pivot_order`), and r of them
    at most: no comparison of one diagonal with another, so the path, and with it a generated
    function's guards (:mod:`~mbh._adapters.inhouse.codegen.tracing`), does not change where two
    of them swap their order along a run.  ``pivots`` empty: the largest remaining each time.
    Rows are never moved: ``factor[i, j]`` is entry j of row i of the factor, for the rows taken
    (the first ``rank`` of ``order``) and the rows left.

    Returns
    -------
    rank : int
        Number of pivots taken.
    order : ndarray, int64, shape (k,)
        The rows taken, in the order taken, then the rows left in increasing order.
    factor : ndarray, shape (k, k)
        Columns 0 … rank − 1: row i of L₁₁ for a row taken, of L₂₁ for a row left
        (P S Pᵀ ≈ [L₁₁; L₂₁][L₁₁; L₂₁]ᵀ, P the permutation ``order``).
    """
    k = matrix.shape[0]
    factor = np.zeros((k, k))
    remaining = np.empty(k)
    largest = 0.0
    for i in range(k):
        remaining[i] = matrix[i, i]
        largest = larger(largest, remaining[i])
    taken = np.zeros(k, np.bool_)
    order = np.empty(k, np.int64)
    rank = 0
    given = pivots.shape[0]
    for j in range(k if given == 0 else min(given, k)):
        if given:
            p = pivots[j]
        else:
            p = -1
            for i in range(k):
                if not taken[i] and (p < 0 or remaining[i] > remaining[p]):
                    p = i
        if not remaining[p] > cut * largest:
            break
        taken[p] = True
        order[j] = p
        diagonal = np.sqrt(remaining[p])
        factor[p, j] = diagonal
        for i in range(k):
            if taken[i]:
                continue
            s = matrix[i, p]
            for c in range(j):
                s -= factor[i, c] * factor[p, c]
            factor[i, j] = s / diagonal
            remaining[i] -= factor[i, j] * factor[i, j]
        rank = j + 1
    left = rank
    for i in range(k):
        if not taken[i]:
            order[left] = i
            left += 1
    return rank, order, factor


@njit(cache=True)
def _null_basis(factor, order, lower):
    """Orthonormal columns spanning the null space of P S Pᵀ = [L₁₁; L₂₁][L₁₁; L₂₁]ᵀ
    (:func:`_pivoted_cholesky`), in the matrix's own row order, shape (k, k − rank): for each row
    left, x = [−L₁₁⁻ᵀ l₂₁; e] (Lᵀx = 0), then modified Gram–Schmidt."""
    k, rank = order.shape[0], lower.shape[0]
    basis = np.zeros((k, k - rank))
    for c in range(k - rank):
        left = order[rank + c]
        x = back_substitution(lower, -factor[left, :rank])
        for i in range(rank):
            basis[order[i], c] = x[i]
        basis[left, c] = 1.0
    for c in range(k - rank):
        for e in range(c):
            _remove_component(basis[:, c], basis[:, e])
        norm = 0.0
        for i in range(k):
            norm += basis[i, c] * basis[i, c]
        norm = np.sqrt(norm)
        for i in range(k):
            basis[i, c] /= norm
    return basis


@njit(cache=True)
def _product_frobenius(matrix, columns):
    """‖matrix @ columns‖_F, matrix (k, k), columns (k, d), in plain loops (no BLAS call)."""
    total = 0.0
    for c in range(columns.shape[1]):
        for i in range(matrix.shape[0]):
            s = 0.0
            for j in range(matrix.shape[1]):
                s += matrix[i, j] * columns[j, c]
            total += s * s
    return np.sqrt(total)


@njit(cache=True)
def _remove_component(vector, unit):
    """vector −= (unitᵀ vector) unit, in place; vector, unit (k,)."""
    dot = 0.0
    for i in range(vector.shape[0]):
        dot += unit[i] * vector[i]
    for i in range(vector.shape[0]):
        vector[i] -= dot * unit[i]


@njit(cache=True)
def semidefinite_solve(matrix, rhs, cut, pivots):
    """:func:`truncated_solve` at ``cut`` of a symmetric positive semi-definite matrix (k, k)
    whose spectrum splits cleanly: some eigenvalues certified above the cut and the others
    certified below it (redundant constraint rows: S = Φ_q W Φ_qᵀ is singular wherever Φ_q's
    rows are dependent), by a pivoted Cholesky factorisation instead of the SVD (35 × 35:
    ~9 µs against LAPACK gesdd's ~82 µs).

    With the pivoted factor (:func:`_pivoted_cholesky`) and N an orthonormal basis of its null
    space (:func:`_null_basis`), the truncated solution is x = (I − NNᵀ) x_p, where x_p solves
    the kept rows of S x = (I − NNᵀ) rhs with zeros on the rows left: the right-hand side's part
    along N is the least-squares residual the truncated SVD leaves, and N's part of x_p is what
    the minimum norm removes.

    Certificate (both parts, else no result):
    - above the cut: λ_min(L₁₁L₁₁ᵀ) ≥ 1/‖L₁₁⁻¹‖₂² (bounded as in :func:`certified_spd_solve`)
      exceeds BOUND_MARGIN · cut · ‖S‖_F; by interlacing, S's rank-th eigenvalue is at least
      that of its principal submatrix L₁₁L₁₁ᵀ, so the truncated SVD keeps rank directions;
    - below it: 2 √k ‖S N‖_F · BOUND_MARGIN < min(cut, NULL_LEVEL) · ‖S‖_F; S then has
      k − rank eigenvalues within 2‖S N‖_F of zero (a residual bound for the orthonormal N),
      below cut · λ_max(S) (λ_max ≥ ‖S‖_F/√k), which the truncated SVD drops; and null to
      round-off (:data:`NULL_LEVEL`), not merely small.

    ``pivots`` (r,) int64: the rows to take, in order (:func:`pivot_order` at an earlier state,
    as the joint-coordinate model passes its start's); empty: the factorisation chooses them.
    Either way the certificate decides whether the result stands.

    Returns
    -------
    certified : bool
        False when the factorisation takes every row or none, or either bound fails.
    x : ndarray, shape (k,) or (0,)
    """
    k = rhs.shape[0]
    rank, order, factor = _pivoted_cholesky(matrix, cut, pivots)
    if rank == 0 or rank == k:
        return False, np.empty(0)
    lower = np.empty((rank, rank))
    for i in range(rank):
        for j in range(rank):
            lower[i, j] = factor[order[i], j] if j <= i else 0.0
    size = _frobenius(matrix)
    if not _condition_certified(size, lower, cut):
        return False, np.empty(0)
    basis = _null_basis(factor, order, lower)
    if not 2.0 * np.sqrt(k) * _product_frobenius(matrix, basis) * BOUND_MARGIN \
            < min(cut, NULL_LEVEL) * size:
        return False, np.empty(0)
    projected = rhs.copy()
    for c in range(k - rank):
        _remove_component(projected, basis[:, c])
    kept = np.empty(rank)
    for i in range(rank):
        kept[i] = projected[order[i]]
    solved = _cholesky_solve(lower, kept)
    x = np.zeros(k)
    for i in range(rank):
        x[order[i]] = solved[i]
    for c in range(k - rank):
        _remove_component(x, basis[:, c])
    return True, x


@njit(cache=True)
def pivot_order(matrix, cut):
    """The rows the pivoted factorisation of :func:`semidefinite_solve` takes in a symmetric
    positive semi-definite matrix (k, k) with redundant rows, in the order taken, shape
    (rank,) int64, when it certifies the matrix that way; empty otherwise (every row taken, or
    no certificate).  Passed back to :func:`semidefinite_solve` at later states, it fixes the
    order where the certificate still holds."""
    rank, order, _ = _pivoted_cholesky(matrix, cut, np.empty(0, np.int64))
    pivots = order[:rank].copy()
    certified, _ = semidefinite_solve(matrix, np.zeros(matrix.shape[0]), cut, pivots)
    return pivots if certified else np.empty(0, np.int64)


@njit(cache=True)
def certified_solve(matrix, rhs, cut):
    """:func:`certified_spd_solve`, else :func:`semidefinite_solve`: the solution of
    :func:`truncated_solve` at ``cut`` for a symmetric positive (semi-)definite matrix (k, k)
    whenever either certifies it, without the SVD.

    Returns
    -------
    certified : bool
    x : ndarray, shape (k,) or (0,)
    """
    certified, x = certified_spd_solve(matrix, rhs, cut)
    if certified:
        return True, x
    return semidefinite_solve(matrix, rhs, cut, np.empty(0, np.int64))


@njit(cache=True)
def _certified_factor(matrix):
    """The Cholesky factor of a symmetric matrix (k, k) and the Frobenius form of the
    certificate's bound, ‖S‖_F ‖L⁻¹‖_F² ≥ κ₂(S) (:func:`certified_spd_solve`): the form whose
    value the conditioning indicator ρ̂ is made of, so the projections keep it.

    Returns
    -------
    positive : bool
        False when the matrix is not positive definite (L incomplete, the bound inf).
    lower : ndarray, shape (k, k)
    bound : float
    """
    positive, lower = _cholesky(matrix)
    if not positive:
        return False, lower, np.inf
    return True, lower, _frobenius(matrix) * _inverse_frobenius_squared(lower)


@njit(cache=True)
def gram_condition_bound(matrix):
    """The Frobenius form of :func:`certified_spd_solve`'s bound on κ₂(A Aᵀ), A = ``matrix``
    (m, n): ‖S‖_F ‖L⁻¹‖_F² with S = A Aᵀ = L Lᵀ (:func:`_certified_factor`).

    Returns
    -------
    positive : bool
        False when A Aᵀ is not positive definite (the bound is then inf).
    bound : float
    """
    positive, _, bound = _certified_factor(weighted_gram(matrix, np.ones(matrix.shape[1])))
    return positive, bound


@njit(cache=True)
def weighted_gram(matrix, weights):
    """A W Aᵀ for A = ``matrix`` (m, n) and W = diag(``weights``) (n,), shape (m, m), exactly
    symmetric (the lower triangle is accumulated and mirrored).  Plain loops, no BLAS call; the
    zero entries of each row of A (a constraint row touches at most two bodies) are skipped."""
    m, n = matrix.shape
    gram = np.zeros((m, m))
    for i in range(m):
        for c in range(n):
            if skippable(matrix[i, c]):
                continue
            scaled = matrix[i, c] * weights[c]
            for j in range(i + 1):
                gram[i, j] += scaled * matrix[j, c]
        for j in range(i):
            gram[j, i] = gram[i, j]
    return gram


@njit(cache=True)
def column_gram(matrix):
    """AᵀA for A = ``matrix`` (m, n), shape (n, n), exactly symmetric: row by row of A, the lower
    triangle accumulated and mirrored, A's zeros skipped (plain loops, no BLAS call)."""
    m, n = matrix.shape
    gram = np.zeros((n, n))
    for r in range(m):
        for i in range(n):
            x = matrix[r, i]
            if skippable(x):
                continue
            for j in range(i + 1):
                gram[i, j] += x * matrix[r, j]
    for i in range(n):
        for j in range(i):
            gram[j, i] = gram[i, j]
    return gram


@njit(cache=True)
def matvec(matrix, x):
    """matrix @ x, matrix (m, n), x (n,), shape (m,); plain loops, no BLAS call."""
    m, n = matrix.shape
    out = np.empty(m)
    for i in range(m):
        total = 0.0
        for c in range(n):
            total += matrix[i, c] * x[c]
        out[i] = total
    return out


@njit(cache=True)
def rmatvec(matrix, y):
    """matrixᵀ @ y, matrix (m, n), y (m,), shape (n,); plain loops, no BLAS call."""
    m, n = matrix.shape
    out = np.zeros(n)
    for i in range(m):
        for c in range(n):
            out[c] += matrix[i, c] * y[i]
    return out


@njit(cache=True)
def min_norm_solve(matrix, rhs, cut):
    """:func:`truncated_solve` of a wide matrix (m, n), m ≤ n, rhs (m,), by the normal equations
    x = Aᵀ(AAᵀ)⁻¹ rhs when the Frobenius form of the certificate (:func:`_certified_factor`)
    certifies AAᵀ at cut² (σ(AAᵀ) = σ(A)²), else x = Aᵀ(AAᵀ)⁺ rhs where
    :func:`semidefinite_solve` certifies AAᵀ at cut² (redundant rows), else by the truncated SVD
    itself, shape (n,)."""
    return min_norm_solve_and_bound(matrix, rhs, cut)[0]


@njit(cache=True)
def min_norm_solve_and_bound(matrix, rhs, cut):
    """:func:`min_norm_solve` and, from the same factorisation, the bound of
    :func:`gram_condition_bound` on κ₂(AAᵀ).

    Returns
    -------
    x : ndarray, shape (n,)
    positive : bool
        False when AAᵀ is not positive definite (the bound is then inf).
    bound : float
    """
    gram = weighted_gram(matrix, np.ones(matrix.shape[1]))
    positive, lower, bound = _certified_factor(gram)
    if positive and bound * BOUND_MARGIN * (cut * cut) < 1.0:
        return rmatvec(matrix, _cholesky_solve(lower, rhs)), positive, bound
    certified, y = semidefinite_solve(gram, rhs, cut * cut, np.empty(0, np.int64))
    if certified:
        return rmatvec(matrix, y), positive, bound
    return truncated_solve(matrix, rhs, cut), positive, bound
