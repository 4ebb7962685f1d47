"""The compiled stepping path: whole runs of a fixed-step explicit Nyström method with the
``none``, ``baumgarte``, ``direct`` or ``partition`` formulation in one numba loop, no Python per
step.

The same arithmetic as the Python path (:func:`mbh._adapters.integrators.nystrom.nystrom_step` on
:class:`~mbh._adapters.inhouse.formulations.stabilisation.Formulation`), so the two agree to round-off: the stages
of the tableau (c, A, Ā, b, b̄), each stage's q̈ from the fused right-hand side
(:func:`~mbh._adapters.inhouse.formulations.dynamics.index1_acceleration`: mass matrix, forces, Φ_q, γ and the
range-space solve of Rouvinen 2003, eq. 77, with Baumgarte's γ − 2αΦ̇ − β²Φ of eq. 110), then for ``direct``
the position projection (eq. 127, iterated to ``proj_tol``) and the velocity projection
(eq. 137) with the truncated pseudo-inverse, then the divergence check of
:meth:`mbh._adapters.integrators.base.Integrator.step`.

Coordinate partitioning (:class:`~mbh._adapters.inhouse.formulations.partition.CoordinatePartitioning`, Rouvinen 2003
eq. 78–89) integrates the independent coordinates; every stage first recovers the dependent ones
by Newton–Raphson (:func:`expand`), and before every step but the first the split is checked as
the Python path checks it.  A step that needs a new split returns :data:`REPARTITION` to the
caller, which chooses it (rare: a few times per run) and calls again.

Where :mod:`mbh._adapters.inhouse.codegen.generated` made them for the formulation (``loop=generated``, the
default), the right-hand side, the projection's parts and ρ̂ come from functions generated for
it, the same numbers as the kernels at a fraction of the cost; each hands a call back to the
kernels when one of its guards fails (counted as ``kernel_calls``).

A run stops at the first step that fails: the state stays at the last good step and the status
code says why (:data:`RUNNING`, :data:`DIVERGED_NONFINITE`, :data:`DIVERGED_LIMIT`,
:data:`FAILED_LINALG`, :data:`FAILED_NEWTON`, :data:`FAILED_RANK`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from mbh._adapters.inhouse.numerics.banded import (conditioning_indicator)
from mbh._adapters.inhouse.formulations.fold import passage_times, plan_passage
from mbh._adapters.inhouse.codegen.generated import (ACCELERATION, INDICATOR, POSITION_CORRECTION,
                                        RESIDUAL_SIZE, VELOCITY_CORRECTION)
from mbh._adapters.inhouse.stepping.loop_codes import (CONSTRAINT_ARGS, DECLINED, DIVERGED_LIMIT,
                                                       DIVERGED_NONFINITE, FACTORIZATIONS,
                                                       FAILED_LINALG, FAILED_NEWTON, GENERATED,
                                                       GENERATED_STEPS, JACOBIAN_EVALS,
                                                       NEWTON_ITERATIONS, PARTITIONED, PLAIN,
                                                       PROJECTED, RHS_EVALS, ROWS, RUNNING,
                                                       SPARSITY, STEP_ENDS, STEP_END_KERNELS)
from mbh._adapters.inhouse.stepping.kernel_step import (combine_stages, hold_state,
                                                        kernel_nystrom_step, project_state,
                                                        rows_jacobian, split_check)


@njit(cache=True, inline="always")
def _generated_projection(states, s, t, proj_tol, proj_max_iter, generated, scratch):
    """:func:`project_state` of the state (q, q̇) = ``states[s]`` ((·, 2, n)), corrected in place, by
    its generated parts alone (same operations, same bits): ``accepted`` False as soon as one
    declines a call (``states[s]`` is then partly corrected).  Each part writes into
    ``scratch`` (n + 1,), the run's buffer, and the state is copied from it: no array is made.

    Returns
    -------
    indicator : float
        ρ̂ of the corrected configuration.
    iterations : int
        Position corrections made (each one Φ_q and one factorisation, as :func:`project_state`
        counts them).
    accepted : bool
    """
    q, v = states[s, 0], states[s, 1]
    n = q.shape[0]
    previous = np.inf
    iterations = 0
    for _ in range(proj_max_iter):
        if generated[RESIDUAL_SIZE](q, v, t, scratch) == 0:
            return 0.0, iterations, False
        size = scratch[0]
        if size < proj_tol or not size < previous:
            break
        previous = size
        iterations += 1
        if generated[POSITION_CORRECTION](q, v, t, scratch) == 0:
            return 0.0, iterations, False
        for e in range(n):
            q[e] = scratch[e]
    if generated[VELOCITY_CORRECTION](q, v, t, scratch) == 0:
        return 0.0, iterations, False
    for e in range(n):
        v[e] = scratch[e]
    return scratch[n], iterations, True


@njit(cache=True)
def _generated_run(k, targets, reached, t0, dt, tableau, generated, stabilisation, projection,
                   limit, passage, counters, buffers, q_out, v_out):
    """The steps of :func:`run_samples` from step ``k`` on the generated functions alone, in one
    flat loop that keeps the state at each target as :func:`run_samples` does: the steps of
    :func:`_step_and_check` (the same operations, so the same bits; the counters and ρ̂ updated
    as it updates them) until the last target, a step before which a passage is planned
    (:func:`plan_passage`), a step one of the functions declines, or a diverged step.
    Partitioning is not run here (its stages need :func:`expand`).

    The loop takes the arrays it uses before its first step: a step makes no array, takes no
    row out of one and passes none into a compiled function of its own, except the projection
    of ``direct`` (:func:`_generated_projection`) and ρ̂, which take the new state's rows.  Each
    array passed, unpacked, made or cut out costs numba atomic reference counts; in the
    pendulum's step those took more time than its five generated calls (docs/speed.md).  The
    state is read and written entry by entry in the two slots of ``buffers[3]``, which it goes
    to in turn, never to the one holding the current state.

    Parameters
    ----------
    k : int
        The last step taken.
    reached : int
        Number of ``targets`` whose state is kept in ``q_out``, ``v_out`` already.
    generated : tuple
        The generated functions (``model[GENERATED]``), every one the formulation calls made.
    buffers : tuple
        :func:`_step_buffers`; the state after step ``k`` in slot 0 of ``buffers[3]``.
    (the others as :func:`run_samples`)

    Returns
    -------
    slot : int
        The slot of ``buffers[3]`` that holds the state after step ``k`` returned.
    k, reached : int
    status : int
        :data:`RUNNING` (every target reached, or a passage planned before step k + 1),
        :data:`DECLINED` (step k + 1 declined, nothing of it kept) or the divergence code of
        step k + 1.
    """
    c, velocity_table, position_table = tableau
    placement, rho_zone, indicators = passage[0], passage[1], passage[2]
    acceleration, indicator = generated[ACCELERATION], generated[INDICATOR]
    stages, stage, scratch, states = buffers
    q_stage, v_stage = stage[0, 0], stage[0, 1]
    measure = placement[0] > 0.0
    count = c.shape[0]
    current = 0
    while True:
        reached = _keep_targets(states, current, k, targets, reached, q_out, v_out)
        if reached == targets.shape[0]:
            return current, k, reached, RUNNING
        t = t0 + k * dt
        if measure and plan_passage(t, dt, t0 + targets[reached] * dt, indicators[1],
                                    indicators[0], rho_zone, placement)[1] > 0.0:
            return current, k, reached, RUNNING
        t_new = t0 + (k + 1) * dt
        h = t_new - t
        for i in range(count):
            combine_stages(stage, 0, states, current, stages, c[i] * h, h * h, position_table, h,
                     velocity_table, i)
            if acceleration(q_stage, v_stage, t + c[i] * h, stages[i]) == 0:
                return current, k, reached, DECLINED
        new = 1 - current
        combine_stages(states, new, states, current, stages, h, h * h, position_table, h,
                 velocity_table, count)
        jacobians, factorizations, iterations = count, count, 0
        rho = 0.0
        accepted = True
        if stabilisation == PROJECTED:
            rho, iterations, accepted = _generated_projection(
                states, new, t_new, projection[0], projection[1], generated, scratch)
            jacobians += iterations + 1
            factorizations += iterations + 1
        elif measure:
            accepted = indicator(states[new, 0], states[new, 1], t_new, scratch) == 1
            jacobians += 1
            rho = scratch[0]
        if not accepted:
            return current, k, reached, DECLINED
        counters[RHS_EVALS] += count
        counters[JACOBIAN_EVALS] += jacobians
        counters[FACTORIZATIONS] += factorizations
        counters[NEWTON_ITERATIONS] += iterations
        if stabilisation == PROJECTED or measure:
            counters[STEP_ENDS] += 1
            indicators[0], indicators[1] = indicators[1], rho
        status = _divergence(states[new, 0], states[new, 1], limit)
        if status != RUNNING:
            return current, k, reached, status
        current, k = new, k + 1


@njit(cache=True)
def run_generated_samples(q, v, t0, dt, first, targets, tableau, generated, stabilisation,
                          projection, limit, passage, counters, q_out, v_out):
    """:func:`run_samples` on the generated functions alone, for as long as they serve: the
    steps of :func:`_generated_run` from the state (q, q̇) after step ``first``, keeping the state
    at each target.  It calls no kernel, so it compiles in seconds where :func:`run_samples`, which
    holds the kernels' path for every step a generated function declines, takes a minute or more:
    the stepper calls this first and :func:`run_samples` only from where it stopped, compiling
    that only when a run needs it (docs/speed.md, "What a first run compiles").

    Parameters and the first four results are :func:`run_samples`'; ``generated`` is its
    ``model[GENERATED]`` (every function the formulation calls generated), ``stabilisation``
    :data:`PLAIN` or :data:`PROJECTED`.

    Returns
    -------
    q, v : ndarray, shape (n,)
        The state after step ``done`` (new arrays).
    done : int
    status : int
        :data:`RUNNING` when every target was reached; :data:`DECLINED` when the full path must
        go on from step ``done`` (a generated function declined step ``done + 1``, nothing of it
        kept, or a passage is planned before it); else the divergence code of step ``done + 1``.
    reached : int
    """
    buffers = _step_buffers(tableau, q)
    states = buffers[3]
    hold_state(states, 0, q, v)
    # No target reached yet, typed int64 as run_samples passes it: a literal 0 had numba compile
    # _generated_run a second time, for Literal[int](0).
    slot, k, reached, status = _generated_run(first, targets, np.int64(0), t0, dt, tableau,
                                              generated, stabilisation, projection, limit,
                                              passage, counters, buffers, q_out, v_out)
    if status == RUNNING and reached < targets.shape[0]:  # a passage is planned
        status = DECLINED
    return states[slot, 0].copy(), states[slot, 1].copy(), k, status, reached


@njit(cache=True, inline="always")
def _hold_and_keep(states, q, v, k, targets, reached, q_out, v_out):
    """Hold the state (q, q̇) after step ``k`` in slot 0 of ``states`` and keep it as
    :func:`_keep_targets` does: the top of a stepping loop; the new count of targets reached."""
    hold_state(states, 0, q, v)
    return _keep_targets(states, 0, k, targets, reached, q_out, v_out)


@njit(cache=True, inline="always")
def _keep_targets(states, s, k, targets, reached, q_out, v_out):
    """Keep (q, q̇) = ``states[s]``, the state after step ``k``, in the rows of ``q_out``,
    ``v_out`` of every target from ``reached`` on that is at most ``k``, entry by entry (a row
    assignment took 35 ns a step more on the pendulum); the new count of targets reached."""
    while reached < targets.shape[0] and targets[reached] <= k:
        for e in range(states.shape[2]):
            q_out[reached, e] = states[s, 0, e]
            v_out[reached, e] = states[s, 1, e]
        reached += 1
    return reached


@njit(cache=True)
def _step_buffers(tableau, q):
    """The buffers of a run's generated steps (:func:`_generated_run`), made once per run: the
    stages (s, n), a stage's q and q̇ (1, 2, n), the outputs of ρ̂ and of the projection's parts
    (n + 1,), and two slots for a state (q, q̇) (2, 2, n)."""
    n = q.shape[0]
    return (np.empty((tableau[0].shape[0], n)), np.empty((1, 2, n)), np.empty(n + 1),
            np.empty((2, 2, n)))


@njit(cache=True, inline="always")
def _squared_norm(x):
    """Σ x_i² of a vector (n,), summed in order: ``x @ x`` calls BLAS, and the pendulum's step
    took 765 ns with two such calls against 734–741 ns with this loop.  Its last bits may differ
    from BLAS's, which can matter only to a state whose norm is within round-off of the
    divergence limit."""
    total = 0.0
    for value in x:
        total += value * value
    return total


@njit(cache=True, inline="always")
def _divergence(q_new, v_new, limit):
    """:data:`RUNNING`, or the divergence code of a state (q, q̇) that is not finite or whose q
    or q̇ has a 2-norm over ``limit``."""
    squared_q, squared_v = _squared_norm(q_new), _squared_norm(v_new)
    if not np.isfinite(squared_q + squared_v):
        return DIVERGED_NONFINITE
    if max(squared_q, squared_v) > limit * limit:
        return DIVERGED_LIMIT
    return RUNNING


@njit(cache=True)
def _checked(q, v, q_new, v_new, limit):
    """(q_new, v_new, RUNNING), or the old state (q, v) and the divergence code of the new one
    (:func:`_divergence`)."""
    status = _divergence(q_new, v_new, limit)
    if status != RUNNING:
        return q, v, status
    return q_new, v_new, RUNNING


@njit(cache=True)
def _exception_code(partition):
    """The failure code of an exception in a step: :data:`FAILED_NEWTON` when :func:`expand`
    recorded a Newton failure, else :data:`FAILED_LINALG`."""
    return FAILED_NEWTON if partition[8][0] != 0.0 else FAILED_LINALG


@njit(cache=True)
def _step_and_check(q, v, t, t_new, tableau, model, stabilisation, projection, partition, limit,
                    passage, counters):
    """One step of the method from (q, q̇) at t to t_new with the ``direct`` correction after it;
    the new ρ̂ goes to ``passage[2][1]`` (the old one to ``passage[2][0]``) when it is measured
    (``direct`` always, from its projection's Φ_q; ``none`` and ``baumgarte`` with passages on).

    Returns
    -------
    q_new, v_new : ndarray
    status : int
        :data:`RUNNING`, or the code of the failure (the state is then not usable).
    """
    proj_tol, proj_max_iter, cut = projection
    try:
        q_new, v_new = kernel_nystrom_step(q, v, t, t_new - t, tableau, model, partition,
                                     stabilisation, counters)
        if stabilisation == PROJECTED:
            q_new, v_new, rho = project_state(q_new, v_new, t_new, model[ROWS], proj_tol, proj_max_iter,
                                         cut, model[CONSTRAINT_ARGS], model[SPARSITY],
                                         model[GENERATED], counters)
            passage[2][0], passage[2][1] = passage[2][1], rho
        elif stabilisation == PLAIN and passage[0][0] > 0.0:  # ρ̂ needs Φ_q at the step's end
            scratch = np.empty(1)
            counters[STEP_ENDS] += 1
            if model[GENERATED][INDICATOR](q_new, v_new, t_new, scratch) == 1:
                counters[JACOBIAN_EVALS] += 1
                rho = scratch[0]
            else:
                counters[STEP_END_KERNELS] += 1
                rho = conditioning_indicator(
                    rows_jacobian(q_new, t_new, model[ROWS], model[CONSTRAINT_ARGS], counters),
                    model[SPARSITY])
            passage[2][0], passage[2][1] = passage[2][1], rho
    except Exception:  # noqa: BLE001 — LAPACK or Newton failures end the run as "failed"
        return q, v, _exception_code(partition)
    return _checked(q, v, q_new, v_new, limit)


@njit(cache=True)
def run_samples(q, v, t0, dt, first, targets, tableau, model, stabilisation, projection,
                partition, check_due, limit, passage, counters, q_out, v_out):
    """Steps ``first + 1`` on of a fixed-step run from the state (q, q̇) after step ``first``,
    through every step index of ``targets``, keeping the state at each: a whole run in one call.
    Partitioning calls it for one target at a time, since its reading of a state moves its
    Newton start.

    Parameters
    ----------
    q, v : ndarray, shape (n,)
        Integrated state after step ``first`` (t = t0 + first·dt): every coordinate, or the
        independent ones when partitioning; not modified.
    t0, dt : float
        Start time and step, s.  Step k ends at t0 + k·dt (no accumulated drift).
    first : int
    targets : ndarray of int64, shape (k,)
        Increasing step indices, none before ``first``.
    tableau : tuple (c (s,), A⁺ (s + 1, s), Ā⁺ (s + 1, s))
        :func:`step_tableau` of the :class:`~mbh._adapters.integrators.nystrom.NystromTableau`.
    model : tuple
        (gains (2,) Baumgarte (α, β) in 1/s or zeros, rows (r,) constraint rows in the solves,
        :attr:`ConstraintSystem.kernel_args`, :attr:`Dynamics.kernel_args`,
        :attr:`ConstraintSystem.sparsity`'s arrays, the five generated functions of
        :func:`.generated.functions`, whether the generated steps run, bool: every function the
        formulation calls was generated (:data:`GENERATED_STEPS`), and the right-hand side
        kernel's entry (:data:`RIGHT_HAND_SIDE`, :mod:`.native_call`)).
    stabilisation : int
        :data:`PLAIN`, :data:`PROJECTED` (``direct``) or :data:`PARTITIONED`.
    projection : tuple (proj_tol, proj_max_iter, cut)
        Projection tolerance, iteration limit and truncation of the pseudo-inverse.
    partition : tuple
        The state of :func:`expand` (empty arrays unless partitioning).
    check_due : ndarray of int64, shape (1,)
        Whether the split is checked before the next step; updated in place.
    limit : float
        Divergence limit on the 2-norms of q and q̇.
    passage : tuple (placement (3,), rho_zone, indicators (2,), count (1,) int64)
        Placed passages of singular positions (:mod:`mbh._adapters.inhouse.formulations.fold`; zero placement
        turns them off): (c*, g/2) of the tableau and the formulation's clearance,
        :data:`~mbh._adapters.inhouse.formulations.fold.FOLD_ZONE` × ρ̂ at the start, ρ̂ at the last two grid
        points (updated in place) and the number of passages placed (incremented in place).
    counters : ndarray of int64, shape (5,)
        Incremented in place (:data:`RHS_EVALS` …).
    q_out, v_out : ndarray, shape (k, n)
        Row i receives the state after step ``targets[i]``; rows from ``reached`` on are left
        as they were.

    Returns
    -------
    q, v : ndarray
        The last good state.
    done : int
        Index of the last good step.
    status : int
        :data:`RUNNING` when every target was reached, :data:`REPARTITION` when the split must be
        chosen again before step ``done + 1``, else the code of the failure in that step.
    reached : int
        Number of targets whose state was stored.

    One call for a whole run: a call per sample, passing the model's ~40 arrays each time, cost
    0.15 ms of a 2.75 ms four-bar run (400 samples, rk4+baumgarte at 5 ms).  The stepping loop is
    written here, not in a function that a one-target entry would call as well: numba compiles a
    called function into a library of its own and then the caller's library again with all of it
    linked in, so a wrapper of a few lines cost as much compile time as the loop
    (docs/speed.md).  A placed passage ends by the next target.
    """
    placement, rho_zone, indicators, passages = passage
    buffers = _step_buffers(tableau, q)
    states = buffers[3]
    k = first
    reached = 0
    while True:
        reached = _hold_and_keep(states, q, v, k, targets, reached, q_out, v_out)
        if reached == targets.shape[0]:
            return q, v, k, RUNNING, reached
        t = t0 + k * dt
        if stabilisation == PARTITIONED and check_due[0]:
            try:
                verdict = split_check(q, v, t, model, partition, passage, counters)
            except Exception:  # noqa: BLE001 — LAPACK or Newton failures end the run as "failed"
                return q, v, k, _exception_code(partition), reached
            if verdict != RUNNING:
                return q, v, k, verdict, reached
            check_due[0] = 0
        lead, length = 0.0, 0.0
        if placement[0] > 0.0:
            lead, length = plan_passage(t, dt, t0 + targets[reached] * dt, indicators[1],
                                        indicators[0], rho_zone, placement)
        if length > 0.0:  # a placed passage; an ordinary step below, without its array of ends
            ends, k_end = passage_times(t0, dt, k, lead, length)
            q_new, v_new, t_start = q, v, t
            for t_end in ends:
                q_new, v_new, status = _step_and_check(
                    q_new, v_new, t_start, t_end, tableau, model, stabilisation, projection,
                    partition, limit, passage, counters)
                if status != RUNNING:
                    return q, v, k, status, reached
                t_start = t_end
            passages[0] += 1
            q, v, k = q_new, v_new, k_end
        else:
            status = DECLINED
            # On to the end, a passage (planned again at the top, with the same inputs) or a
            # declined step.
            if stabilisation != PARTITIONED and model[GENERATED_STEPS]:
                slot, k, reached, status = _generated_run(
                    k, targets, reached, t0, dt, tableau, model[GENERATED], stabilisation,
                    projection, limit, passage, counters, buffers, q_out, v_out)
                q, v = states[slot, 0], states[slot, 1]
            if status == DECLINED:  # one step on the full path
                q_new, v_new, status = _step_and_check(
                    q, v, t0 + k * dt, t0 + (k + 1) * dt, tableau, model, stabilisation,
                    projection, partition, limit, passage, counters)
                if status == RUNNING:
                    q, v, k = q_new, v_new, k + 1
            if status != RUNNING:
                return q, v, k, status, reached
        check_due[0] = 1
