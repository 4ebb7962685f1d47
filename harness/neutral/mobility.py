"""Rank analysis of the neutral joint equations at one configuration (Frączek & Wojtyra 2009, §1.3).

* Grübler–Kutzbach mobility: w = 6n − Σ (relative freedoms removed) in space (Frączek & Wojtyra 2009, eq. 1.39),
  w = 3n − Σ in the plane (eq. 1.40), from the joint classes of :mod:`mbh._harness.model.mechanism`.
* Rank mobility: w = N − rank J (eq. 1.48) with J the Jacobian of the joint rows with respect to
  the body twists (N = 6 per spatial body, 3 per planar body; no Euler-parameter normalisation rows,
  since twists have no redundant coordinates).
* The redundant rows, by name: a rank-revealing QR factorisation with column pivoting of Jᵀ
  (scipy.linalg.qr), whose pivot order picks the independent rows first; the rows left over are
  linear combinations of them.  Which rows are left over is a choice of the pivoting; the rows
  that take part in a dependency at all (any of which could be the one dropped) are the support of
  the left null space of J, reported with them: on Bricard's mechanism the one redundancy spans
  all 30 rows of the six joints, so no joint is redundant by itself.
* The singularity measure: the condition number and smallest singular value of the system formed by
  the independent rows and the driver row (square for a mechanism of mobility 1).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from mbh._harness.neutral.equations import JointEquations
from mbh._harness.model.mechanism import Mechanism, grubler_mobility

#: A pivot |R_kk| of the QR factorisation of Jᵀ below this fraction of the largest counts as zero.
#: Round-off puts dependent rows' pivots at ~1e-16·|J| (≤ 1e-15 on the shipped scenes' redundant
#: variants); a configuration within ~1e-9 rad (or m per m of link) of a singular position
#: is counted as singular, which is the accuracy a start must have anyway.
RANK_TOLERANCE = 1e-9
#: A configuration whose condition number of [independent rows; driver row] exceeds this is
#: singular: ``mbh check`` warns and the assembly refuses the start.  Near a singular position the
#: condition grows like c/δ with δ the distance to it (c ≈ 9 on the N-four-bar), so the limit
#: refuses starts within ~1e-5 rad of a singular position, where the velocities lose more than 6
#: of their 16 digits; the shipped scenes are far below it (figures: docs/measurements.md,
#: section "Assembly and rank analysis").
CONDITION_LIMIT = 1e6
#: A joint row whose component in the left null space of J (the norm of its row of an orthonormal
#: basis, between 0 and 1) exceeds this takes part in a dependency: rows outside every dependency
#: are at round-off (~1e-16), dependent rows at ≥ 1/√30 ≈ 0.18 on the shipped scenes (figures:
#: docs/measurements.md, section "Assembly and rank analysis").
DEPENDENCE_TOLERANCE = 1e-9


def dependent_rows(matrix: np.ndarray, rank: int, tol: float = DEPENDENCE_TOLERANCE) -> np.ndarray:
    """Indices (sorted) of the rows of ``matrix`` (m, n) of rank ``rank`` that take part in a linear
    dependency: those with a component above ``tol`` in the left null space (the last m − rank
    left singular vectors).  Dropping any one of them keeps the rank; the others are essential.
    """
    if rank >= matrix.shape[0]:
        return np.zeros(0, dtype=int)
    left = np.linalg.svd(matrix, full_matrices=True)[0][:, rank:]
    return np.flatnonzero(np.linalg.norm(left, axis=1) > tol)


def independent_rows(matrix: np.ndarray, tol: float = RANK_TOLERANCE) -> np.ndarray:
    """Indices (sorted) of a maximal set of linearly independent rows of ``matrix`` (m, n).

    QR with column pivoting of the transpose: the |R_kk| decrease, and the rows pivoted while
    |R_kk| > tol·|R_00| are independent.
    """
    if matrix.size == 0:
        return np.zeros(0, dtype=int)
    _, r, pivots = scipy.linalg.qr(matrix.T, mode="economic", pivoting=True)
    diagonal = np.abs(np.diag(r))
    rank = int(np.count_nonzero(diagonal > tol * diagonal[0])) if diagonal[0] > 0 else 0
    return np.sort(pivots[:rank])


@dataclass(frozen=True)
class RankReport:
    """Result of :func:`rank_analysis`.

    Attributes
    ----------
    n_coordinates : int
        Twist coordinates: 6 per spatial body, 3 per planar body.
    n_equations : int
        Joint rows (without the driver).
    rank, mobility, grubler_mobility : int
    redundant_labels : tuple of str
        The joint rows that are linear combinations of the others (the QR pivoting's choice).
    dependent_labels : tuple of str
        Every joint row that takes part in a dependency (:func:`dependent_rows`): any of them could
        be dropped instead of those in ``redundant_labels``.
    independent : tuple of int
        Indices of the independent joint rows.
    condition : float
        Condition number of [independent rows; driver row] (see :func:`rank_analysis`), ∞ when
        that system is rank-deficient.
    smallest_singular_value : float
    """

    n_coordinates: int
    n_equations: int
    rank: int
    mobility: int
    grubler_mobility: int
    redundant_labels: tuple[str, ...]
    dependent_labels: tuple[str, ...]
    independent: tuple[int, ...]
    condition: float
    smallest_singular_value: float

    @property
    def singular(self) -> bool:
        """The configuration is singular: the mobility exceeds what the joints allow
        (max(Grübler, 1): rank lost at a flattened position), or the condition number is above
        :data:`CONDITION_LIMIT`."""
        rank_lost = self.mobility > max(self.grubler_mobility, 1)
        return rank_lost or not self.condition <= CONDITION_LIMIT

    def fields(self) -> dict:
        """The report as ``mbh check`` prints it (plain ints, floats, strings)."""
        fields = {
            "n_coordinates": self.n_coordinates, "n_equations": self.n_equations,
            "rank": self.rank, "mobility": self.mobility, "grubler_mobility": self.grubler_mobility,
            "redundant_equations": len(self.redundant_labels),
            "redundant_equation_labels": list(self.redundant_labels),
            "dependent_equation_labels": list(self.dependent_labels),
            "jacobian_condition": self.condition,
            "smallest_singular_value": self.smallest_singular_value,
        }
        warning = self.warning()
        return fields if warning is None else fields | {"warning": warning}

    def warning(self) -> str | None:
        """A sentence for ``mbh check`` when the configuration is singular, else None."""
        if not self.singular:
            return None
        return ("singular configuration: the constraint Jacobian has condition "
                f"{self.condition:.3g} "
                f"(limit {CONDITION_LIMIT:.0e}) and rank mobility {self.mobility} against "
                f"{max(self.grubler_mobility, 1)} expected; the assembly branch is ambiguous")


def rank_analysis(mech: Mechanism, position: np.ndarray, quaternion: np.ndarray,
                  drive=None) -> RankReport:
    """Mobility, redundant rows and singularity measure at one configuration.

    Parameters
    ----------
    position : ndarray, shape (n_bodies, 3)
    quaternion : ndarray, shape (n_bodies, 4)
    drive : (value, rate), optional
        Passed to :class:`JointEquations` (only the driver row's gradient matters here).

    Notes
    -----
    The condition number is σ_max/σ_min of S = [independent rows; driver row], with σ_min the
    min(rows, columns)-th singular value: for mobility 1 S is square and σ_min → 0 at a singular
    position; for a mechanism of higher mobility S has fewer rows than columns and the measure says
    whether the driver row is independent of the joints.
    """
    equations = JointEquations(mech, with_driver=True, drive=drive)
    jacobian = equations.jacobian(position, quaternion)
    joint_rows = jacobian[:equations.n_joint_rows]
    independent = independent_rows(joint_rows)
    redundant = sorted(set(range(equations.n_joint_rows)) - set(independent.tolist()))
    square = np.vstack([joint_rows[independent], jacobian[equations.n_joint_rows:]])
    singular_values = np.linalg.svd(square, compute_uv=False)
    smallest = float(singular_values[min(square.shape) - 1])
    condition = float(singular_values[0] / smallest) if smallest > 0 else float("inf")
    n = jacobian.shape[1]
    return RankReport(
        n_coordinates=n, n_equations=equations.n_joint_rows, rank=int(independent.size),
        mobility=n - int(independent.size), grubler_mobility=grubler_mobility(mech),
        redundant_labels=tuple(equations.labels[i] for i in redundant),
        dependent_labels=tuple(equations.labels[i]
                               for i in dependent_rows(joint_rows, int(independent.size))),
        independent=tuple(int(i) for i in independent), condition=condition,
        smallest_singular_value=smallest,
    )
