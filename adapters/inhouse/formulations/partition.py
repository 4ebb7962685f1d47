"""Coordinate partitioning (Wehage–Haug; Rouvinen 2003, §3.2, eq. 78–89).

The coordinates split into independent ones q_I (as many as the mobility) and dependent ones q_D.
Only (q_I, q̇_I) are integrated; at every evaluation the dependent coordinates are recovered by
Newton–Raphson on Φ(q_D; q_I) = 0 (eq. 80–82), their velocities from Φ_qD q̇_D = −Φ_qI q̇_I
(eq. 84), and q̈_I is read from the augmented solution (eq. 86–89).  The constraints therefore hold
to the Newton tolerance at every step, with no drift and no stabilisation parameter.

The split comes from Gaussian elimination with full pivoting on Φ_qᵀ (the pivot columns of Φ_q are
the dependent coordinates, Frączek & Wojtyra 2009, eq. 1.49) and is chosen again whenever the dependent block's
condition number exceeds ``cond_ratio`` times that of the split full pivoting would choose at the
current configuration (checked after every step): an independent coordinate that reaches an
extremum (the four-bar coupler's x, an Euler parameter, the slider at dead centre) makes the block
singular there.  Switching late costs accuracy long before it costs the branch: near the fold the
reduced ODE's derivatives grow, and the Runge–Kutta error constant with them, so the default
``cond_ratio`` switches at a 1 % advantage (figures: docs/measurements.md, section "In-house
formulation").  A re-partition restarts the integrator (multistep
history is lost).
"""

from __future__ import annotations

import numpy as np

from mbh._adapters.integrators.base import StepFailure
from mbh._adapters.inhouse.numerics.linalg import solve, solve_matrix
from mbh._adapters.inhouse.numerics.rank import full_pivot_elimination
from mbh._adapters.inhouse.formulations.stabilisation import Formulation


class CoordinatePartitioning(Formulation):
    name = "partition"
    description = ("coordinate partitioning (Rouvinen 2003, eq. 78–89): integrate the independent "
                   "coordinates, solve the dependent ones by Newton; re-partition when the "
                   "dependent block is cond_ratio times worse conditioned than the best split")
    defaults = {"newton_tol": 1e-13, "newton_max_iter": 20, "cond_ratio": 1.01, "passage": 1}
    keeps_redundant_rows = False
    #: Passages of singular positions are placed (:mod:`mbh._adapters.inhouse.formulations.fold`; ρ̂ is measured on
    #: the Φ_q of the re-partition check, with every row kept only: a start that dropped
    #: redundant rows places none).  At a crossing every dependent block is singular, so the
    #: reduced equations lose accuracy near it like the index-1 ones do.  The clearance is
    #: chosen on double_fourbar, where 1e-3 reaches the error floor that larger clearances keep.
    #: On parallelogram_fourbar the error still grows at each of its 12 crossings (each passage
    #: of that bifurcation adds an energy error that the motion turns into a crank-angle error
    #: growing between crossings); why partition's step does that there is not found yet.
    #: Figures: docs/measurements.md, section "In-house formulation".
    places_passages = True
    passage_clearance = 1e-3

    def __init__(self, mech, q0, dt, **params):
        super().__init__(mech, q0, dt, **params)
        self._q = np.array(q0, dtype=float)
        self.repartitions = -1  # the first choice below is not a re-partition
        self.choose_partition(self._q)

    # -- the split -----------------------------------------------------------------------------
    def _best_split(self, q: np.ndarray):
        """Dependent coordinates chosen by full pivoting at q, and Φ_q there."""
        jac = self.jacobian(0.0, q)
        rank, pivots = full_pivot_elimination(jac.T)
        if rank < jac.shape[0]:
            raise StepFailure(f"constraint Jacobian lost rank ({rank} < {jac.shape[0]}): "
                              "singular configuration")
        return np.sort(pivots), jac

    def choose_partition(self, q: np.ndarray) -> None:
        """Pick dependent coordinates as the full-pivoting pivot columns of Φ_q at q."""
        self.dependent, jac = self._best_split(q)
        self.independent = np.setdiff1d(np.arange(jac.shape[1]), self.dependent)
        self.n = self.independent.size
        self.repartitions += 1
        self._sensitivity = None

    def needs_repartition(self, q_full: np.ndarray) -> bool:
        """True when cond(Φ_qD) of the current split exceeds ``cond_ratio`` × that of the split
        full pivoting would choose at q_full; ρ̂ of Φ_q there is recorded for the placed
        passages (the compiled loop's ``split_check`` does the same)."""
        best, jac = self._best_split(q_full)
        self._record_indicator(jac)
        if np.array_equal(best, self.dependent):
            return False
        current = np.linalg.cond(jac[:, self.dependent])
        return bool(current > self.params["cond_ratio"] * np.linalg.cond(jac[:, best]))

    # -- full ↔ reduced state --------------------------------------------------------------
    def reduce(self, q: np.ndarray, v: np.ndarray):
        """(q_I, q̇_I) from a full state."""
        self._q = np.array(q, dtype=float)
        return q[self.independent].copy(), v[self.independent].copy()

    def expand(self, t: float, q_ind: np.ndarray, v_ind: np.ndarray):
        """Full (q, q̇) consistent with the constraints, from (q_I, q̇_I) (eq. 80–84).

        Newton starts from the last solution moved along the sensitivity dq_D/dq_I there, so it
        usually needs one or two iterations.
        """
        q = self._q.copy()
        if self._sensitivity is not None:
            q[self.dependent] += self._sensitivity @ (q_ind - q[self.independent])
        q[self.independent] = q_ind
        for _ in range(int(self.params["newton_max_iter"])):
            residual = self.phi(t, q)
            if np.max(np.abs(residual)) < self.params["newton_tol"]:
                break
            self.counters["newton_iterations"] += 1
            jac = self.jacobian(t, q)
            q[self.dependent] -= solve(np.ascontiguousarray(jac[:, self.dependent]), residual)
        else:
            raise StepFailure(f"dependent coordinates did not converge (max |Φ| = "
                              f"{np.max(np.abs(residual)):.3g}) at t = {t:g}")
        jac = self.jacobian(t, q)
        block = np.ascontiguousarray(jac[:, self.dependent])
        self._sensitivity = solve_matrix(block, -np.ascontiguousarray(jac[:, self.independent]))
        self._q = q
        v = np.zeros(q.size)
        v[self.independent] = v_ind
        v[self.dependent] = self._sensitivity @ v_ind
        return q, v

    # -- the reduced problem -------------------------------------------------------------------
    def acceleration(self, t, q_ind, v_ind):
        q, v = self.expand(t, q_ind, v_ind)
        return super().acceleration(t, q, v)[self.independent]
