"""One step of a fixed-step explicit Nyström method on the kernels' path, for the compiled loops
(:mod:`~mbh._adapters.inhouse.stepping.compiled`): the fused right-hand side
(:func:`~mbh._adapters.inhouse.formulations.dynamics.index1_acceleration`), the stages' combination,
``direct``'s position and velocity projections (Rouvinen 2003, eq. 127 and 137), the recovery of
the dependent coordinates of coordinate partitioning (eq. 78–89, :func:`expand`) and its
re-partition check (:func:`split_check`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from mbh._adapters.inhouse.bodies import kernels
from mbh._adapters.inhouse.numerics.banded import (conditioning_indicator, min_norm_correction,
                                     min_norm_correction_and_indicator, pattern_matvec)
from mbh._adapters.inhouse.codegen.generated import (ACCELERATION, POSITION_CORRECTION,
                                        RESIDUAL_SIZE, VELOCITY_CORRECTION)
from mbh._adapters.inhouse.numerics.rank import full_pivot_elimination
from mbh._adapters.inhouse.stepping.loop_codes import (CONSTRAINT_ARGS, DYNAMICS_ARGS,
                                                       FACTORIZATIONS, FAILED_RANK, GAINS,
                                                       GENERATED, JACOBIAN_EVALS, KERNEL_CALLS,
                                                       NEWTON_ITERATIONS, PARTITIONED, REPARTITION,
                                                       RHS_EVALS, RIGHT_HAND_SIDE, ROWS,
                                                       RUNNING, SPARSITY, STEP_ENDS,
                                                       STEP_END_KERNELS)
from mbh._adapters.inhouse.stepping.native_call import call_native


@njit(cache=True)
def _max_abs(values):
    biggest = 0.0
    for x in values:
        biggest = max(biggest, abs(x))
    return biggest


@njit(cache=True)
def _kept_rows(values, rows):
    """``values[rows]`` (contiguous) of Φ (m,) or Φ_q (m, n); ``values`` itself, no copy, when
    every row is kept (``rows`` is then 0 … m − 1)."""
    if rows.shape[0] == values.shape[0]:
        return values
    return np.ascontiguousarray(values[rows])


@njit(cache=True)
def rows_jacobian(q, t, rows, constraint_args, counters):
    counters[JACOBIAN_EVALS] += 1
    return _kept_rows(kernels.jacobian(q, t, constraint_args), rows)


@njit(cache=True)
def project_state(q, v, t, rows, proj_tol, proj_max_iter, cut, constraint_args, sparsity_arrays,
             generated, counters):
    """Direct violation correction (Rouvinen 2003, eq. 127 and 137) with the truncated pseudo-inverse;
    the loop of :meth:`~mbh._adapters.inhouse.formulations.stabilisation.DirectCorrection.project` (and its stop
    when an iteration no longer reduces max |Φ|).  Also returns the conditioning indicator ρ̂ of
    the corrected configuration (:func:`~mbh._adapters.inhouse.numerics.banded.conditioning_indicator`).
    Each part comes from its generated function (``generated``, :mod:`.generated`) where that
    serves, else from the kernels."""
    n = q.shape[0]
    scratch = np.empty(n + 1)
    previous = np.inf
    counters[STEP_ENDS] += 1
    handed_back = 0
    for _ in range(proj_max_iter):
        if generated[RESIDUAL_SIZE](q, v, t, scratch) == 1:
            size = scratch[0]
        else:
            handed_back = 1
            size = _max_abs(_kept_rows(kernels.phi(q, t, constraint_args), rows))
        if size < proj_tol or not size < previous:
            break
        previous = size
        counters[NEWTON_ITERATIONS] += 1
        counters[FACTORIZATIONS] += 1
        corrected = np.empty(n)
        if generated[POSITION_CORRECTION](q, v, t, corrected) == 1:
            counters[JACOBIAN_EVALS] += 1
            q = corrected
        else:
            handed_back = 1
            residual = _kept_rows(kernels.phi(q, t, constraint_args), rows)
            jac = rows_jacobian(q, t, rows, constraint_args, counters)
            q = q - min_norm_correction(jac, residual, cut, sparsity_arrays)
    counters[FACTORIZATIONS] += 1
    if generated[VELOCITY_CORRECTION](q, v, t, scratch) == 1:
        counters[JACOBIAN_EVALS] += 1
        counters[STEP_END_KERNELS] += handed_back
        return q, scratch[:n].copy(), scratch[n]
    counters[STEP_END_KERNELS] += 1
    jac = rows_jacobian(q, t, rows, constraint_args, counters)
    correction, indicator = min_norm_correction_and_indicator(
        jac, pattern_matvec(jac, sparsity_arrays[0], v), cut, sparsity_arrays)
    return q, v - correction, indicator


@njit(cache=True)
def expand(q_ind, v_ind, t, rows, constraint_args, partition, counters):
    """Full (q, q̇) from the independent (q_I, q̇_I) (Rouvinen 2003, eq. 80–84), as
    :meth:`~mbh._adapters.inhouse.formulations.partition.CoordinatePartitioning.expand` does it: Newton from the
    last solution moved along the sensitivity dq_D/dq_I, then q̇_D from it.

    ``partition`` = (independent (ni,), dependent (nd,), last (n,), sensitivity (nd, ni),
    has_sensitivity (1,), newton_tol, newton_max_iter, cond_ratio, failure (3,)); ``last``,
    ``sensitivity`` and ``has_sensitivity`` are updated in place.  A Newton failure writes
    (1, max |Φ|, t) into ``failure`` and raises.
    """
    independent, dependent, last, sensitivity, has_sensitivity, tol, max_iter, _, failure = \
        partition
    q = last.copy()
    if has_sensitivity[0]:
        q[dependent] += sensitivity @ (q_ind - q[independent])
    q[independent] = q_ind
    converged = False
    residual = np.zeros(0)
    for _ in range(max_iter):
        residual = _kept_rows(kernels.phi(q, t, constraint_args), rows)
        if _max_abs(residual) < tol:
            converged = True
            break
        counters[NEWTON_ITERATIONS] += 1
        jac = rows_jacobian(q, t, rows, constraint_args, counters)
        q[dependent] -= np.linalg.solve(np.ascontiguousarray(jac[:, dependent]), residual)
    if not converged:
        failure[0], failure[1], failure[2] = 1.0, _max_abs(residual), t
        raise ValueError("dependent coordinates did not converge")
    jac = rows_jacobian(q, t, rows, constraint_args, counters)
    sensitivity[:] = np.linalg.solve(np.ascontiguousarray(jac[:, dependent]),
                                     -np.ascontiguousarray(jac[:, independent]))
    has_sensitivity[0] = 1
    last[:] = q
    v = np.zeros(q.shape[0])
    v[independent] = v_ind
    v[dependent] = sensitivity @ v_ind
    return q, v


@njit(cache=True, inline="always")
def count_evaluation(counters):
    """One right-hand side, counted when attempted, as the integrators count."""
    counters[RHS_EVALS] += 1
    counters[JACOBIAN_EVALS] += 1
    counters[FACTORIZATIONS] += 1


@njit(cache=True, inline="always")
def kernel_acceleration(q, v, t, model, counters):
    """q̈ of the index-1 form by the kernel
    (:func:`~mbh._adapters.inhouse.formulations.dynamics.index1_acceleration`, called through its
    entry ``model[RIGHT_HAND_SIDE]``: :mod:`.native_call`), for a call the generated right-hand
    side declined (a guard failed, or ``NEVER``)."""
    counters[KERNEL_CALLS] += 1
    gains = model[GAINS]
    return call_native(model[RIGHT_HAND_SIDE], (q, v, t, gains[0], gains[1], model[ROWS],
                                                model[CONSTRAINT_ARGS], model[DYNAMICS_ARGS],
                                                model[SPARSITY]))


@njit(cache=True, inline="always")
def _partitioned_acceleration(q_ind, v_ind, t, model, partition, counters):
    """q̈ of the independent coordinates: the full state by :func:`expand`, then its q̈ from the
    generated right-hand side where it serves, else from the kernel."""
    counters[RHS_EVALS] += 1  # before expand, whose Newton failure ends the step
    q, v = expand(q_ind, v_ind, t, model[ROWS], model[CONSTRAINT_ARGS], partition, counters)
    counters[JACOBIAN_EVALS] += 1
    counters[FACTORIZATIONS] += 1
    a = np.empty(q.shape[0])
    if model[GENERATED][ACCELERATION](q, v, t, a) == 0:
        a = kernel_acceleration(q, v, t, model, counters)
    return a[partition[0]]


@njit(cache=True)
def kernel_nystrom_step(q, v, t, h, tableau, model, partition, stabilisation, counters):
    """One step of :func:`mbh._adapters.integrators.nystrom.nystrom_step`, entry by entry in the same
    operation order (so to the same bits), without a temporary array per tableau coefficient.

    Each stage's q̈ is written in place by the generated right-hand side
    (``model[GENERATED]``), called here rather than through a function that takes the model:
    passing its ~40 arrays cost more than the four-bar's q̈ itself (figures: docs/measurements.md, section "In-house step cost")."""
    c, velocity_table, position_table = tableau
    count, n = c.shape[0], q.shape[0]
    state, stage, new = np.empty((1, 2, n)), np.empty((1, 2, n)), np.empty((1, 2, n))
    hold_state(state, 0, q, v)
    q_stage, v_stage = stage[0, 0], stage[0, 1]
    stages = np.empty((count, n))
    generated = model[GENERATED][ACCELERATION]
    for i in range(count):
        combine_stages(stage, 0, state, 0, stages, c[i] * h, h * h, position_table, h, velocity_table, i)
        t_stage = t + c[i] * h
        if stabilisation == PARTITIONED:
            stages[i] = _partitioned_acceleration(q_stage, v_stage, t_stage, model, partition,
                                                  counters)
            continue
        count_evaluation(counters)
        if generated(q_stage, v_stage, t_stage, stages[i]) == 0:
            stages[i] = kernel_acceleration(q_stage, v_stage, t_stage, model, counters)
    combine_stages(new, 0, state, 0, stages, h, h * h, position_table, h, velocity_table, count)
    return new[0, 0], new[0, 1]


@njit(cache=True, inline="always")
def combine_stages(out, o, states, s, stages, velocity_weight, h2, position_table, h, velocity_table,
             row):
    """Line ``row`` of the Nyström tableau (a stage, or the update for row = s, see
    :func:`step_tableau`) from the state (q, q̇) = ``states[s]`` into ``out[o]``:
    q + (velocity_weight·q̇ + Σ_j (h2·Ā⁺_row,j)·k_j) and q̇ + Σ_j (h·A⁺_row,j)·k_j over the
    stages k_j, j < row, with a non-zero weight, summed in order j = 0, 1, …

    ``out`` and ``states`` (·, 2, n) hold (q, q̇) pairs, ``stages`` (s, n), the tables (s + 1, s).
    Every entry is indexed in place, no row or slice taken out: in numba each one costs atomic
    reference counts, which were a third of the pendulum's step (docs/speed.md)."""
    for e in range(states.shape[2]):
        dq, ve = velocity_weight * states[s, 1, e], states[s, 1, e]
        for j in range(row):
            if position_table[row, j] != 0.0:
                dq = dq + (h2 * position_table[row, j]) * stages[j, e]
            if velocity_table[row, j] != 0.0:
                ve = ve + (h * velocity_table[row, j]) * stages[j, e]
        out[o, 0, e] = states[s, 0, e] + dq
        out[o, 1, e] = ve


@njit(cache=True, inline="always")
def hold_state(states, s, q, v):
    """Copy the state (q, q̇), both (n,), into ``states[s]`` ((·, 2, n))."""
    for e in range(q.shape[0]):
        states[s, 0, e] = q[e]
        states[s, 1, e] = v[e]


def step_tableau(tableau) -> tuple:
    """The tableau of a Nyström method as the compiled loop takes it: (c (s,), A⁺ (s + 1, s),
    Ā⁺ (s + 1, s)), A and Ā with b and b̄ appended as their last rows, so that the update is
    combined as a stage s + 1 would be (:func:`combine_stages`, ``row`` = s)."""
    return (np.ascontiguousarray(tableau.c, dtype=float),
            np.ascontiguousarray(np.vstack((tableau.a, tableau.b)), dtype=float),
            np.ascontiguousarray(np.vstack((tableau.abar, tableau.bbar)), dtype=float))


@njit(cache=True)
def split_check(q_ind, v_ind, t, model, partition, passage, counters):
    """The re-partition check of the Python path (``needs_repartition`` on the expanded state):
    RUNNING to keep the split, REPARTITION when the dependent block is ``cond_ratio`` times worse
    conditioned than the split full pivoting picks, FAILED_RANK when Φ_q lost rank.  With placed
    passages on, ρ̂ of the Φ_q it factors goes to ``passage[2][1]`` (the old one to
    ``passage[2][0]``)."""
    rows, constraint_args, dependent = model[ROWS], model[CONSTRAINT_ARGS], partition[1]
    q, _ = expand(q_ind, v_ind, t, rows, constraint_args, partition, counters)
    jac = rows_jacobian(q, 0.0, rows, constraint_args, counters)
    rank, pivots = full_pivot_elimination(jac.T)
    if rank < jac.shape[0]:
        partition[8][1] = rank
        return FAILED_RANK
    if passage[0][0] > 0.0:
        passage[2][0], passage[2][1] = passage[2][1], conditioning_indicator(
            jac, model[SPARSITY])
    best = np.sort(pivots)
    if best.shape[0] == dependent.shape[0] and np.all(best == dependent):
        return RUNNING
    current = np.linalg.cond(np.ascontiguousarray(jac[:, dependent]))
    if current > partition[7] * np.linalg.cond(np.ascontiguousarray(jac[:, best])):
        return REPARTITION
    return RUNNING
