"""Rank analysis of a constraint Jacobian (Frączek & Wojtyra 2009, §1.3).

The Grübler–Kutzbach count it is compared with (eq. 1.39 / 1.40) is
:func:`mbh._harness.model.mechanism.grubler_mobility`.

* Rank mobility: w = N − rank Φ_q(q0) (eq. 1.48), valid away from singular configurations.
* Which equations are dependent: Gaussian elimination with full pivoting (eq. 1.49) on Φ_q; the
  rows never chosen as pivots are the redundant ones.
* The singularity measure: condition number and smallest singular value of the square system formed
  by the independent equations and the driver.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit


#: Pivots below this fraction of the largest |entry| count as zero.
RANK_TOLERANCE = 1e-9


@njit(cache=True)
def full_pivot_elimination(matrix, tol=RANK_TOLERANCE):
    """Gaussian elimination with full pivoting (Frączek & Wojtyra 2009, eq. 1.49), compiled (the compiled
    partitioning path calls it after every step).

    Parameters
    ----------
    matrix : ndarray, shape (m, n)
    tol : float
        Relative pivot threshold (fraction of max |matrix|).

    Returns
    -------
    rank : int
    independent_rows : ndarray of int, shape (rank,)
        Original indices of the pivot rows, in pivoting order; the other rows are linear
        combinations of them.
    """
    work = np.empty(matrix.shape)
    work[:] = matrix
    m, n = work.shape
    rows = np.arange(m)
    scale = np.abs(work).max() if m * n > 0 else 0.0
    rank = 0
    for step in range(min(m, n)):
        largest, r, c = -1.0, step, step
        for i in range(step, m):  # the first largest |entry| in row-major order
            for j in range(step, n):
                if abs(work[i, j]) > largest:
                    largest, r, c = abs(work[i, j]), i, j
        if largest <= tol * scale:
            break
        for j in range(n):
            work[step, j], work[r, j] = work[r, j], work[step, j]
        rows[step], rows[r] = rows[r], rows[step]
        for i in range(m):
            work[i, step], work[i, c] = work[i, c], work[i, step]
        for i in range(step + 1, m):
            factor = work[i, step] / work[step, step]
            for j in range(step, n):
                work[i, j] -= factor * work[step, j]
        rank += 1
    return rank, rows[:rank].copy()


@dataclass(frozen=True)
class JacobianRank:
    """Result of :func:`jacobian_rank`: the rank of the in-house formulation's own constraint
    Jacobian in absolute coordinates (not the measuring stick's rank analysis in twist
    coordinates, :mod:`mbh._harness.neutral.mobility`)."""

    n_coordinates: int
    n_equations: int
    rank: int
    mobility: int
    redundant: tuple[int, ...]
    redundant_labels: tuple[str, ...]
    condition: float
    smallest_singular_value: float


def jacobian_rank(jacobian: np.ndarray, labels, driver_row: np.ndarray) -> JacobianRank:
    """Mobility, redundant equations and singularity measure at one configuration.

    Parameters
    ----------
    jacobian : ndarray, shape (m, n)
        Φ_q of the joint (and normalisation) equations, without the driver.
    labels : sequence of str, length m
    driver_row : ndarray, shape (n,)
        The driver's Jacobian row, appended to the independent rows for the singularity measure.
    """
    m, n = jacobian.shape
    rank, independent = full_pivot_elimination(jacobian)
    redundant = tuple(sorted(set(range(m)) - set(independent.tolist())))
    square = np.vstack([jacobian[np.sort(independent)], driver_row])
    singular_values = np.linalg.svd(square, compute_uv=False)
    smallest = float(singular_values[-1]) if square.shape[0] == n else 0.0
    condition = float(singular_values[0] / smallest) if smallest > 0 else float("inf")
    return JacobianRank(
        n_coordinates=n, n_equations=m, rank=rank, mobility=n - rank, redundant=redundant,
        redundant_labels=tuple(labels[i] for i in redundant), condition=condition,
        smallest_singular_value=smallest,
    )
