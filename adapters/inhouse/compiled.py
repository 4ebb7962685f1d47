"""The compiled stepping path: whole runs of a fixed-step explicit Nyström method with the
``none``, ``baumgarte`` or ``direct`` formulation in one numba loop, no Python per step.

The same arithmetic as the Python path (:func:`adapters.integrators.nystrom.nystrom_step` on
:class:`~adapters.inhouse.stabilisation.Formulation`), so the two agree to round-off: the stages
of the tableau (c, A, Ā, b, b̄), each stage's q̈ from the fused right-hand side
(:func:`~adapters.inhouse.dynamics.index1_acceleration`: mass matrix, forces, Φ_q, γ and the
range-space solve of 002 eq. 77, with Baumgarte's γ − 2αΦ̇ − β²Φ of eq. 110), then for ``direct``
the position projection (eq. 127, iterated to ``proj_tol``) and the velocity projection
(eq. 137) with the truncated pseudo-inverse, then the divergence check of
:meth:`adapters.integrators.base.Integrator.step`.

A run stops at the first step that fails: the state stays at the last good step and the status
code says why (:data:`RUNNING`, :data:`DIVERGED_NONFINITE`, :data:`DIVERGED_LIMIT`,
:data:`FAILED_LINALG`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from adapters.inhouse import kernels
from adapters.inhouse.dynamics import index1_acceleration
from adapters.inhouse.banded import min_norm_correction, pattern_matvec

RUNNING, DIVERGED_NONFINITE, DIVERGED_LIMIT, FAILED_LINALG = range(4)

#: Stabilisation codes of :func:`run_steps`.
PLAIN, PROJECTED = 0, 1

#: Index of each cost counter in the ``counters`` array of :func:`run_steps`.
RHS_EVALS, JACOBIAN_EVALS, FACTORIZATIONS, NEWTON_ITERATIONS = range(4)


@njit(cache=True)
def _rows_max_abs(values):
    biggest = 0.0
    for x in values:
        biggest = max(biggest, abs(x))
    return biggest


@njit(cache=True)
def _project(q, v, t, rows, proj_tol, proj_max_iter, cut, constraint_args, sparsity_arrays,
             counters):
    """Direct violation correction (002 eq. 127 and 137) with the truncated pseudo-inverse;
    the loop of :meth:`~adapters.inhouse.stabilisation.DirectCorrection.project`."""
    for _ in range(proj_max_iter):
        residual = kernels.phi(q, t, *constraint_args)[rows]
        if _rows_max_abs(residual) < proj_tol:
            break
        counters[NEWTON_ITERATIONS] += 1
        counters[JACOBIAN_EVALS] += 1
        counters[FACTORIZATIONS] += 1
        jac = np.ascontiguousarray(kernels.jacobian(q, t, *constraint_args)[rows])
        q = q - min_norm_correction(jac, residual, cut, sparsity_arrays)
    counters[JACOBIAN_EVALS] += 1
    counters[FACTORIZATIONS] += 1
    jac = np.ascontiguousarray(kernels.jacobian(q, t, *constraint_args)[rows])
    v = v - min_norm_correction(jac, pattern_matvec(jac, sparsity_arrays[0], v), cut,
                                sparsity_arrays)
    return q, v


@njit(cache=True)
def _acceleration(q, v, t, gains, rows, constraint_args, dynamics_args, sparsity_arrays,
                  counters):
    counters[RHS_EVALS] += 1
    counters[JACOBIAN_EVALS] += 1
    counters[FACTORIZATIONS] += 1
    return index1_acceleration(q, v, t, gains[0], gains[1], rows, constraint_args, dynamics_args,
                               sparsity_arrays)


@njit(cache=True)
def _nystrom_step(q, v, t, h, c, a, abar, b, bbar, gains, rows, constraint_args, dynamics_args,
                  sparsity_arrays, counters):
    """One step of :func:`adapters.integrators.nystrom.nystrom_step` (same operation order)."""
    stages = np.empty((c.shape[0], v.shape[0]))
    for i in range(c.shape[0]):
        dq = (c[i] * h) * v
        v_stage = v
        for j in range(i):
            if abar[i, j] != 0.0:
                dq = dq + (h * h * abar[i, j]) * stages[j]
            if a[i, j] != 0.0:
                v_stage = v_stage + (h * a[i, j]) * stages[j]
        stages[i] = _acceleration(q + dq, v_stage, t + c[i] * h, gains, rows, constraint_args,
                                  dynamics_args, sparsity_arrays, counters)
    dq = h * v
    v_new = v
    for j in range(c.shape[0]):
        if bbar[j] != 0.0:
            dq = dq + (h * h * bbar[j]) * stages[j]
        if b[j] != 0.0:
            v_new = v_new + (h * b[j]) * stages[j]
    return q + dq, v_new


@njit(cache=True)
def run_steps(q, v, t0, dt, first, last, tableau, gains, stabilisation, proj_tol, proj_max_iter,
              cut, limit, rows, constraint_args, dynamics_args, sparsity_arrays, counters):
    """Steps ``first + 1 … last`` of a fixed-step run from the state (q, q̇) after step ``first``.

    Parameters
    ----------
    q, v : ndarray, shape (n,)
        State after step ``first`` (t = t0 + first·dt); not modified.
    t0, dt : float
        Start time and step, s.  Step k ends at t0 + k·dt (no accumulated drift).
    first, last : int
    tableau : tuple (c (s,), A (s, s), Ā (s, s), b (s,), b̄ (s,))
        :class:`~adapters.integrators.nystrom.NystromTableau` arrays.
    gains : ndarray, shape (2,)
        Baumgarte (α, β), 1/s; zeros for the plain form.
    stabilisation : int
        :data:`PLAIN` or :data:`PROJECTED` (``direct``).
    proj_tol, proj_max_iter, cut : float, int, float
        Projection tolerance, iteration limit and truncation of the pseudo-inverse.
    limit : float
        Divergence limit on the 2-norms of q and q̇.
    rows : ndarray of int, shape (r,)
        Constraint rows in the solves.
    constraint_args, dynamics_args, sparsity_arrays : tuple
        :attr:`ConstraintSystem.kernel_args`, :attr:`Dynamics.kernel_args`,
        :attr:`ConstraintSystem.sparsity`'s arrays.
    counters : ndarray of int64, shape (4,)
        Incremented in place (:data:`RHS_EVALS` …).

    Returns
    -------
    q, v : ndarray, shape (n,)
        The last good state.
    done : int
        Index of the last good step.
    status : int
        :data:`RUNNING` when step ``last`` was reached, else the code of the failure in step
        ``done + 1``.
    """
    c, a, abar, b, bbar = tableau
    for k in range(first, last):
        t = t0 + k * dt
        t_new = t0 + (k + 1) * dt
        try:
            q_new, v_new = _nystrom_step(q, v, t, t_new - t, c, a, abar, b, bbar, gains, rows,
                                         constraint_args, dynamics_args, sparsity_arrays,
                                         counters)
            if stabilisation == PROJECTED:
                q_new, v_new = _project(q_new, v_new, t_new, rows, proj_tol, proj_max_iter, cut,
                                        constraint_args, sparsity_arrays, counters)
        except Exception:  # noqa: BLE001 — LAPACK failures end the run as "failed"
            return q, v, k, FAILED_LINALG
        squared_q, squared_v = q_new @ q_new, v_new @ v_new
        if not np.isfinite(squared_q + squared_v):
            return q, v, k, DIVERGED_NONFINITE
        if max(squared_q, squared_v) > limit * limit:
            return q, v, k, DIVERGED_LIMIT
        q, v = q_new, v_new
    return q, v, last, RUNNING
