"""Coordinate partitioning in joint coordinates (``partition`` with ``coords=joint``).

The treatment of :class:`~mbh._adapters.inhouse.formulations.partition.Partitioned` (Wehage–Haug;
Rouvinen 2003, eq. 78–89) over the tree's joint coordinates θ (n_θ,) and the closure equations
Φ_θ(θ) = Φ_cut(g(θ)) (m_c,) with C_θ = Φ_cut,q B (m_c, n_θ) (Arczewski 1995; module docstring of
:mod:`~mbh._adapters.inhouse.formulations.joint_coordinates`): the independent joint coordinates
θ_I (n_θ − rank C_θ of them, the mobility) are integrated, the dependent ones θ_D are solved by
Newton on Φ_θ = 0, and θ̈_I is read from the joint formulation's own acceleration (the
range-space solve of [M_θ C_θᵀ; C_θ 0]).  The split is full pivoting on C_θᵀ, chosen again when
the dependent block degrades, as in absolute coordinates.

Redundant closure rows (Bricard's loop: 5 rows of rank 4) are kept, unlike the absolute
treatment's start-time choice of rows: the dependent block C_θ,D (m_c, rank C_θ) has full column
rank at a split, and Newton's step, the dependent rates and the sensitivity ∂θ_D/∂θ_I are its
least-squares solutions over every row, exact where the rows are consistent (on the closure).
A split or block with fewer independent columns than the rank at the start fails the step (a
singular configuration), never a silent guess.  No placed passages of singular positions
(``passage`` has no effect, as for the other joint-coordinate treatments).
"""

from __future__ import annotations

import numpy as np

from mbh._adapters.inhouse.formulations.joint_coordinates import JointCoordinates
from mbh._adapters.inhouse.formulations.partition import CoordinatePartitioning, Partitioned
from mbh._adapters.inhouse.numerics.rank import RANK_TOLERANCE
from mbh._adapters.integrators.base import StepFailure


class JointPartition(Partitioned, JointCoordinates):
    """Coordinate partitioning over (θ_I, θ̇_I); parameters as
    :class:`~.partition.CoordinatePartitioning`."""

    name = "partition"
    description = ("joint coordinates with coordinate partitioning: integrate the independent θ, "
                   "solve the dependent ones by Newton on the closure equations")
    defaults = CoordinatePartitioning.defaults

    def __init__(self, mech, q0, dt, **params):
        super().__init__(mech, q0, dt, **params)
        self.split_rank = self.rank
        self._start_partition(self.kinematics.theta0)
        labels = self.kinematics.moves.coordinate_labels
        independent = ", ".join(labels[i] for i in self.independent)
        self.notes.append(
            f"coordinate partitioning over θ: {self.n} independent ({independent}) integrated at "
            f"the start, {self.dependent.size} dependent solved by Newton on all "
            f"{self.closure.m} closure equation(s) (least squares: redundant rows kept)"
            if self.closure.m else
            f"coordinate partitioning over θ: no closure equations, every θ ({independent}) "
            "integrated")

    def _split_jacobian(self, t, theta):
        return self.closure_jacobian(t, theta)

    def _split_residual(self, t, theta):
        return self.closure_residual(t, theta)

    def _split_point(self, q_full):
        """The θ last completed, whose image g(θ) is the absolute ``q_full`` the stepper passes
        (θ is not a function of q: angles are defined modulo 2π)."""
        return self._x

    @staticmethod
    def _dependent_solve(block, rhs):
        """Least-squares y of block @ y = rhs over every closure row, block (m_c, n_D), rhs
        (m_c,) or (m_c, k); a block whose numerical column rank (singular values above
        :data:`~mbh._adapters.inhouse.numerics.rank.RANK_TOLERANCE` × the largest) is below n_D
        fails the step."""
        solution, _, rank, _ = np.linalg.lstsq(block, rhs, rcond=RANK_TOLERANCE)
        if rank < block.shape[1]:
            raise StepFailure(f"dependent block of the closure Jacobian lost rank ({rank} < "
                              f"{block.shape[1]}): singular configuration")
        return solution

    def _record_indicator(self, jac):
        """No placed passages in joint coordinates: no ρ̂ to record."""
