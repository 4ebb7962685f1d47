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

The treatment itself (:class:`Partitioned`) is written over any coordinates x with constraints
c(x) = 0; :class:`CoordinatePartitioning` puts it over the absolute coordinates q and Φ(q), and
:class:`~mbh._adapters.inhouse.formulations.joint_partition.JointPartition` over the joint
coordinates θ and the closure equations Φ_θ(θ) (``coords=joint``).
"""

from __future__ import annotations

import numpy as np

from mbh._adapters.integrators.base import StepFailure
from mbh._adapters.inhouse.numerics.linalg import solve, solve_matrix
from mbh._adapters.inhouse.numerics.rank import full_pivot_elimination
from mbh._adapters.inhouse.formulations.stabilisation import Formulation


class Partitioned:
    """Coordinate partitioning over coordinates x (n_x,) with constraints c(x) = 0 (r_c rows),
    a mixin put before the formulation whose ``acceleration``, ``reduce`` and ``expand`` it wraps
    (their full-coordinate versions, reached by ``super()``).

    The subclass provides ``_split_jacobian(t, x)`` (r_c, n_x), ``_split_residual(t, x)`` (r_c,),
    ``_dependent_solve(block, rhs)`` (y with block @ y = rhs, block (r_c, n_D), rhs (r_c,) or
    (r_c, k)), ``_split_point(x_full)`` (the full coordinates the split is chosen at, from what
    the stepper passes), ``_record_indicator(jac)`` and ``split_rank``, the rank c_x must keep
    (a split needs n_D = ``split_rank`` dependent coordinates; fewer pivots mean a singular
    configuration).  Attributes: ``dependent``, ``independent`` (index arrays into x),
    ``repartitions``.
    """

    def _start_partition(self, x0: np.ndarray) -> None:
        """The first split, at the full coordinates ``x0`` (n_x,)."""
        self._x = np.array(x0, dtype=float)
        self.repartitions = -1  # the first choice below is not a re-partition
        self.choose_partition(x0)

    # -- the split -----------------------------------------------------------------------------
    def _best_split(self, x_full: np.ndarray):
        """Dependent coordinates chosen by full pivoting on c_xᵀ at the split point of
        ``x_full``, and c_x there."""
        jac = self._split_jacobian(0.0, self._split_point(x_full))
        rank, pivots = full_pivot_elimination(jac.T)
        if rank < self.split_rank:
            raise StepFailure(f"constraint Jacobian lost rank ({rank} < {self.split_rank}): "
                              "singular configuration")
        return np.sort(pivots), jac

    def choose_partition(self, x_full: np.ndarray) -> None:
        """Pick dependent coordinates as the full-pivoting pivot columns of c_x."""
        self.dependent, jac = self._best_split(x_full)
        self.independent = np.setdiff1d(np.arange(jac.shape[1]), self.dependent)
        self.n = self.independent.size
        self.repartitions += 1
        self._sensitivity = None

    def needs_repartition(self, x_full: np.ndarray) -> bool:
        """True when cond(c_x,D) of the current split exceeds ``cond_ratio`` × that of the split
        full pivoting would choose; ``_record_indicator`` sees c_x there."""
        best, jac = self._best_split(x_full)
        self._record_indicator(jac)
        if np.array_equal(best, self.dependent):
            return False
        current = np.linalg.cond(jac[:, self.dependent])
        return bool(current > self.params["cond_ratio"] * np.linalg.cond(jac[:, best]))

    # -- full ↔ reduced state --------------------------------------------------------------
    def reduce(self, q: np.ndarray, v: np.ndarray):
        """(x_I, ẋ_I) from a full state (the formulation's ``reduce`` first)."""
        x, rate = super().reduce(q, v)
        self._x = np.array(x, dtype=float)
        return x[self.independent].copy(), rate[self.independent].copy()

    def complete(self, t: float, x_ind: np.ndarray, v_ind: np.ndarray):
        """Full (x, ẋ) consistent with the constraints, from (x_I, ẋ_I) (eq. 80–84).

        Newton starts from the last solution moved along the sensitivity dx_D/dx_I there, so it
        usually needs one or two iterations.
        """
        x = self._x.copy()
        if self._sensitivity is not None:
            x[self.dependent] += self._sensitivity @ (x_ind - x[self.independent])
        x[self.independent] = x_ind
        for _ in range(int(self.params["newton_max_iter"])):
            residual = self._split_residual(t, x)
            if np.abs(residual).max(initial=0.0) < self.params["newton_tol"]:
                break
            self.counters["newton_iterations"] += 1
            jac = self._split_jacobian(t, x)
            x[self.dependent] -= self._dependent_solve(jac[:, self.dependent], residual)
        else:
            raise StepFailure(f"dependent coordinates did not converge (max |Φ| = "
                              f"{np.max(np.abs(residual)):.3g}) at t = {t:g}")
        jac = self._split_jacobian(t, x)
        self._sensitivity = self._dependent_solve(jac[:, self.dependent],
                                                  -np.ascontiguousarray(jac[:, self.independent]))
        self._x = x
        v = np.zeros(x.size)
        v[self.independent] = v_ind
        v[self.dependent] = self._sensitivity @ v_ind
        return x, v

    def expand(self, t: float, x_ind: np.ndarray, v_ind: np.ndarray):
        """The formulation's full state of :meth:`complete`."""
        return super().expand(t, *self.complete(t, x_ind, v_ind))

    # -- the reduced problem -------------------------------------------------------------------
    def acceleration(self, t, x_ind, v_ind):
        """ẍ_I: the formulation's full acceleration at the completed state, its independent
        entries (eq. 86–89)."""
        x, v = self.complete(t, x_ind, v_ind)
        return super().acceleration(t, x, v)[self.independent]


class CoordinatePartitioning(Partitioned, Formulation):
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
        self.split_rank = self.rows.size  # the independent rows of the rank analysis at q0
        self._start_partition(q0)

    def _split_jacobian(self, t, q):
        return self.jacobian(t, q)

    def _split_residual(self, t, q):
        return self.phi(t, q)

    @staticmethod
    def _split_point(q_full):
        return q_full

    @staticmethod
    def _dependent_solve(block, rhs):
        """A square dependent block (the independent rows only): LU."""
        block = np.ascontiguousarray(block)
        return solve(block, rhs) if rhs.ndim == 1 else solve_matrix(block, rhs)
