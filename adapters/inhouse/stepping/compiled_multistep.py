"""The compiled stepping path of the linear multistep methods (Adams–Bashforth, Adams–Moulton,
Gear/BDF: :class:`~mbh._adapters.integrators.multistep.LinearMultistep`) with the ``none``,
``baumgarte`` and ``direct`` formulations: a whole run in one numba call, as
:mod:`mbh._adapters.inhouse.stepping.compiled` runs the explicit one-step methods.

The step is :class:`~mbh._adapters.integrators.multistep.LinearMultistep`'s on y = (q, q̇),
f = (q̇, q̈) (Rouvinen 2003, eq. 94), in the same order: f at the step's start goes into the
history; until the history holds the points the method reads, a classical RK4 step
(:func:`mbh._adapters.inhouse.stepping.kernel_step.kernel_nystrom_step`, eqs. 102–106); then ψ of eq. 107 and, for an
implicit method (β₀ ≠ 0), Newton's iteration on y − hβ₀ f(t_{n+1}, y) − ψ = 0 from the explicit
Euler predictor, as :class:`~mbh._adapters.integrators.newton.NewtonSolver` iterates it: the
iteration matrix I − hβ₀ J with J by forward differences at the last accepted state, kept
across iterations and steps, refreshed when an iteration converges slowly, the convergence test
on the scaled correction.  ``direct`` then projects the new state (eqs. 127, 137).  Each q̈ comes
from the generated right-hand side where it serves, else from the kernels (``kernel_calls``).

The explicit methods (β₀ = 0) run in a loop of their own, :func:`run_explicit_samples`: the
same steps without the Newton code, which cost their steps ~0.45 µs each in the implicit
methods' loop even where it never ran, and without an array made per step.

The numbers agree with the Python path's to the Newton tolerance, not to the bit: the LU
factorisation is written out here (partial pivoting, LAPACK's choice of pivots, its own order
of summation), and the Jacobian's differences amplify the round-off by which the generated q̈
differs from the kernels' by 1/√ε.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from mbh._adapters.inhouse.stepping.compiled import _checked, _divergence, _hold_and_keep
from mbh._adapters.inhouse.stepping.kernel_step import (count_evaluation, kernel_acceleration,
                                                        kernel_nystrom_step, project_state,
                                                        step_tableau)
from mbh._adapters.inhouse.stepping.loop_codes import (CONSTRAINT_ARGS, FACTORIZATIONS,
                                                       FAILED_LINALG, FAILED_NEWTON, GENERATED,
                                                       JACOBIAN_EVALS, NEWTON_ITERATIONS, PLAIN,
                                                       PROJECTED, RHS_EVALS, ROWS, RUNNING,
                                                       SPARSITY)
from mbh._adapters.inhouse.codegen.generated import ACCELERATION
from mbh._adapters.integrators.multistep import LinearMultistep, points_read
from mbh._adapters.integrators.newton import SLOW_RATE
from mbh._adapters.integrators.nystrom import RK4

#: Slots of the Newton state array (``newton`` of :func:`method_arguments`): whether J is held,
#: and hβ₀ of the factorised iteration matrix (NaN: none factorised).
HAS_JACOBIAN, FACTORED_GAMMA = range(2)


def method_arguments(method_class: type[LinearMultistep], params: dict, n: int) -> tuple:
    """The method as :func:`run_samples` takes it, with the run's own history and Newton state.

    Parameters
    ----------
    method_class : type[LinearMultistep]
    params : dict
        Its resolved parameters (``tol``, ``max_iter`` of an implicit method).
    n : int
        Number of coordinates.

    Returns
    -------
    tuple
        (α (p + 1,), β (k + 1,), (tol, max_iter, the slow rate of
        :data:`~mbh._adapters.integrators.newton.SLOW_RATE`: a module the kernels' fingerprint does
        not cover, so it comes as an argument), the RK4 start tableau of
        :func:`~mbh._adapters.inhouse.stepping.kernel_step.step_tableau`, history (points, 2, 2n): (y, f) of the
        last steps' starts, newest first, held (1,) int64: points in it, J (2n, 2n), the LU
        factors of I − hβ₀J (2n, 2n), their row pivots (2n,) int64, Newton state (2,)); the
        arrays after the first four are updated in place.
    """
    alpha = np.ascontiguousarray(method_class.alpha, dtype=float)
    beta = np.ascontiguousarray(method_class.beta, dtype=float)
    newton = (float(params.get("tol", 1.0)), int(params.get("max_iter", 1)), SLOW_RATE)
    size = 2 * n
    state = np.zeros(2)
    state[FACTORED_GAMMA] = np.nan
    return (alpha, beta, newton, step_tableau(RK4.tableau),
            np.zeros((points_read(alpha, beta), 2, size)), np.zeros(1, dtype=np.int64),
            np.zeros((size, size)), np.zeros((size, size)), np.zeros(size, dtype=np.int64),
            state)


@njit(cache=True)
def lu_factor_into(lu, pivots):
    """LU factorisation with partial pivoting of the square matrix in ``lu`` (m, m), in place:
    unit lower factor below the diagonal, upper factor on and above it; ``pivots`` (m,) int64
    receives the row swapped with row i at step i (LAPACK getrf's convention, its choice of the
    largest |entry| in the column).  False when a pivot is zero (the factors are then unusable)."""
    m = lu.shape[0]
    for i in range(m):
        pivot = i
        for r in range(i + 1, m):
            if abs(lu[r, i]) > abs(lu[pivot, i]):
                pivot = r
        pivots[i] = pivot
        if pivot != i:
            for c in range(m):
                lu[i, c], lu[pivot, c] = lu[pivot, c], lu[i, c]
        if lu[i, i] == 0.0:
            return False
        for r in range(i + 1, m):
            factor = lu[r, i] / lu[i, i]
            lu[r, i] = factor
            if factor != 0.0:
                for c in range(i + 1, m):
                    lu[r, c] -= factor * lu[i, c]
    return True


@njit(cache=True)
def lu_solve_into(lu, pivots, x):
    """Solve A x = b in place (``x`` (m,) holds b on entry) from :func:`lu_factor_into`'s
    factors of A."""
    m = lu.shape[0]
    for i in range(m):
        p = pivots[i]
        if p != i:
            x[i], x[p] = x[p], x[i]
    for i in range(m):
        total = x[i]
        for c in range(i):
            total -= lu[i, c] * x[c]
        x[i] = total
    for i in range(m - 1, -1, -1):
        total = x[i]
        for c in range(i + 1, m):
            total -= lu[i, c] * x[c]
        x[i] = total / lu[i, i]


@njit(cache=True, inline="always")
def _acceleration_into(q, v, t, model, counters, out):
    """q̈ (n,) into ``out``: the generated right-hand side where it serves, else the kernels'
    (counted in ``kernel_calls``); the evaluation itself is not counted here."""
    if model[GENERATED][ACCELERATION](q, v, t, out) == 0:
        out[:] = kernel_acceleration(q, v, t, model, counters)


@njit(cache=True)
def _refresh_jacobian(jacobian, t, y, a, model, counters):
    """J = ∂f/∂y = [[0, I], [∂q̈/∂q, ∂q̈/∂q̇]] (2n, 2n) at (t, y) into ``jacobian``, by the
    forward differences of :func:`mbh._adapters.integrators.newton.first_order_jacobian` (step
    √ε·max(1, |y_j|)); ``a`` is q̈ there.  Counted as the Python path counts it: 2n right-hand
    sides, 2n + 1 Jacobians (the formulation's and the integrator's), 2n factorisations."""
    size = y.shape[0]
    n = size // 2
    root_eps = np.sqrt(np.finfo(np.float64).eps)
    jacobian[:, :] = 0.0
    for i in range(n):
        jacobian[i, n + i] = 1.0
    shifted = y.copy()
    column = np.empty(n)
    for j in range(size):
        shifted[j] = y[j] + root_eps * max(1.0, abs(y[j]))
        step = shifted[j] - y[j]
        _acceleration_into(shifted[:n], shifted[n:], t, model, counters, column)
        for i in range(n):
            jacobian[n + i, j] = (column[i] - a[i]) / step
        shifted[j] = y[j]
    counters[RHS_EVALS] += size
    counters[JACOBIAN_EVALS] += size + 1
    counters[FACTORIZATIONS] += size


@njit(cache=True)
def _factor(lu, pivots, jacobian, gamma, state, counters):
    """The LU factors of I − γJ into ``lu``, ``pivots``; γ noted in ``state``.  False when the
    matrix is singular (scipy's ``lu_factor`` then warns, and the Python path's iteration
    diverges to a non-finite correction)."""
    size = jacobian.shape[0]
    for i in range(size):
        for j in range(size):
            lu[i, j] = (1.0 if i == j else 0.0) - gamma * jacobian[i, j]
    state[FACTORED_GAMMA] = gamma
    counters[FACTORIZATIONS] += 1
    return lu_factor_into(lu, pivots)


@njit(cache=True, inline="always")
def _iterate(t, psi, gamma, lu, pivots, newton, stop_when_slow, model, counters, buffers):
    """:meth:`NewtonSolver._iterate <mbh._adapters.integrators.newton.NewtonSolver._iterate>` from
    the guess in ``buffers``' iterate (2n,), in place: whether it converged (scaled correction
    ≤ ``tol``)."""
    tol, max_iter, slow_rate = newton
    _, _, y_new, dy, a = buffers
    size = y_new.shape[0]
    n = size // 2
    previous = -1.0
    for _ in range(max_iter):
        count_evaluation(counters)
        _acceleration_into(y_new[:n], y_new[n:], t, model, counters, a)
        for i in range(size):
            f = y_new[n + i] if i < n else a[i - n]
            dy[i] = -(y_new[i] - gamma * f - psi[i])
        lu_solve_into(lu, pivots, dy)
        counters[NEWTON_ITERATIONS] += 1
        scaled = 0.0  # max |dy_i| / (1 + |y_i|), NaN when one is (as np.max gives it)
        for i in range(size):
            y_new[i] = y_new[i] + dy[i]
            ratio = abs(dy[i]) / (1.0 + abs(y_new[i]))
            if ratio > scaled or ratio != ratio:
                scaled = ratio
        if not np.isfinite(scaled):
            return False
        if scaled <= tol:
            return True
        if stop_when_slow and previous >= 0.0 and scaled > slow_rate * previous:
            return False
        previous = scaled
    return False


@njit(cache=True, inline="always")
def _newton_solve(t, gamma, t_start, y_start, f_start, dt, method, model, counters, buffers):
    """:meth:`NewtonSolver.solve <mbh._adapters.integrators.newton.NewtonSolver.solve>`: y solving
    y − γ f(t, y) − ψ = 0 (ψ in ``buffers``) into ``buffers``' iterate from the explicit Euler
    predictor y_start + dt·f_start, J at the last accepted state (t_start, y_start, f there);
    False when the iteration did not converge even with a fresh J."""
    newton, jacobian, lu, pivots, state = method[2], method[6], method[7], method[8], method[9]
    a_start, psi, y_new = buffers[0], buffers[1], buffers[2]
    fresh = state[HAS_JACOBIAN] == 0.0
    if fresh:
        _refresh_jacobian(jacobian, t_start, y_start, a_start, model, counters)
        state[HAS_JACOBIAN], state[FACTORED_GAMMA] = 1.0, np.nan
    factored = True
    if not state[FACTORED_GAMMA] == gamma:
        factored = _factor(lu, pivots, jacobian, gamma, state, counters)
    while True:
        for e in range(y_new.shape[0]):
            y_new[e] = y_start[e] + dt * f_start[e]
        converged = factored and _iterate(t, psi, gamma, lu, pivots, newton, not fresh, model,
                                          counters, buffers)
        if converged or fresh:
            return converged
        _refresh_jacobian(jacobian, t_start, y_start, a_start, model, counters)
        factored = _factor(lu, pivots, jacobian, gamma, state, counters)
        fresh = True


@njit(cache=True, inline="always")
def _start_step(q, v, t, method, model, counters, a):
    """The start of every step: q̈ at (q, q̇, t) into ``a`` (n,) and (y, f) = ((q, q̇), (q̇, q̈))
    pushed into the history (:func:`method_arguments`), entry by entry; whether the history now
    holds every point the method reads (else the step is an RK4 start step)."""
    history, held = method[4], method[5]
    n = q.shape[0]
    count_evaluation(counters)
    _acceleration_into(q, v, t, model, counters, a)
    points = history.shape[0]
    for j in range(points - 1, 0, -1):
        for e in range(2 * n):
            history[j, 0, e] = history[j - 1, 0, e]
            history[j, 1, e] = history[j - 1, 1, e]
    for e in range(n):
        history[0, 0, e], history[0, 0, n + e] = q[e], v[e]
        history[0, 1, e], history[0, 1, n + e] = v[e], a[e]
    held[0] = min(held[0] + 1, points)
    return held[0] == points


@njit(cache=True, inline="always")
def _explicit_part(alpha, beta, history, dt, e):
    """Entry ``e`` of ψ = Σ_j (−α_j y_{n+1−j} + h β_j f_{n+1−j}) (eq. 107) over the history,
    summed in the Python path's order (j = 1, 2, …, the α term before the β term)."""
    total = 0.0
    for j in range(1, history.shape[0] + 1):
        if j < alpha.shape[0]:
            total -= alpha[j] * history[j - 1, 0, e]
        if j < beta.shape[0]:
            total += dt * beta[j] * history[j - 1, 1, e]
    return total


@njit(cache=True, inline="always")
def _multistep_step(q, v, t, t_new, dt, method, model, partition, counters, buffers):
    """One step of an implicit method (β₀ ≠ 0), as :meth:`MultistepIntegrator._step_impl
    <mbh._adapters.integrators.multistep.MultistepIntegrator._step_impl>` takes it, from (q, q̇) at
    t: the new (q, q̇), each (n,), and False when Newton's iteration failed.  ``buffers`` (q̈ at the start
    (n,), ψ, the Newton iterate and its correction (2n,) each, q̈ at the iterate (n,)) are the
    run's, overwritten."""
    alpha, beta, start_tableau, history = method[0], method[1], method[3], method[4]
    a, psi, y_new = buffers[0], buffers[1], buffers[2]
    n = q.shape[0]
    if not _start_step(q, v, t, method, model, counters, a):
        # The treatment typed int64, as the one-step loop passes it: the global PLAIN alone is a
        # Literal[int](0), for which numba compiled kernel_nystrom_step (and its right-hand
        # side) a second time.
        q_new, v_new = kernel_nystrom_step(q, v, t, dt, start_tableau, model, partition,
                                           np.int64(PLAIN), counters)
        return q_new, v_new, True
    for e in range(2 * n):
        psi[e] = _explicit_part(alpha, beta, history, dt, e)
    converged = _newton_solve(t_new, dt * beta[0], t, history[0, 0], history[0, 1], dt, method,
                              model, counters, buffers)
    return y_new[:n].copy(), y_new[n:].copy(), converged


@njit(cache=True, inline="always")
def _projected(q, v, t, projection, model, counters):
    """``direct``'s projection of the new state (q, q̇) at t (eqs. 127, 137) by
    :func:`~mbh._adapters.inhouse.stepping.kernel_step.project_state`, ``projection`` (proj_tol, proj_max_iter, cut):
    the corrected (q, q̇), new arrays."""
    proj_tol, proj_max_iter, cut = projection
    q_new, v_new, _ = project_state(q, v, t, model[ROWS], proj_tol, proj_max_iter, cut,
                               model[CONSTRAINT_ARGS], model[SPARSITY], model[GENERATED],
                               counters)
    return q_new, v_new


@njit(cache=True)
def run_samples(q, v, t0, dt, first, targets, method, model, stabilisation, projection,
                partition, check_due, limit, passage, counters, q_out, v_out):
    """A fixed-step run of an implicit linear multistep method (Adams–Moulton, BDF: β₀ ≠ 0;
    the explicit ones run on :func:`run_explicit_samples`) from the state after step ``first``
    through every step index of ``targets``, keeping the state at each: the arguments and
    results of :func:`mbh._adapters.inhouse.stepping.compiled.run_samples`, with ``method``
    (:func:`method_arguments`) in the tableau's place; ``stabilisation`` is
    :data:`~mbh._adapters.inhouse.stepping.loop_codes.PLAIN` or :data:`~mbh._adapters.inhouse.stepping.loop_codes.PROJECTED`,
    ``check_due`` and ``passage`` are not read (no partitioning, no placed passages: the
    Python path places none for multistep methods).  A Newton failure ends the run with
    :data:`~mbh._adapters.inhouse.stepping.loop_codes.FAILED_NEWTON`, any other exception in a step with
    :data:`~mbh._adapters.inhouse.stepping.loop_codes.FAILED_LINALG`."""
    n = q.shape[0]
    states = np.empty((1, 2, n))
    buffers = (np.empty(n), np.empty(2 * n), np.empty(2 * n), np.empty(2 * n), np.empty(n))
    k = first
    reached = 0
    while True:
        reached = _hold_and_keep(states, q, v, k, targets, reached, q_out, v_out)
        if reached == targets.shape[0]:
            return q, v, k, RUNNING, reached
        t, t_new = t0 + k * dt, t0 + (k + 1) * dt
        try:
            q_new, v_new, converged = _multistep_step(q, v, t, t_new, dt, method, model,
                                                      partition, counters, buffers)
            if converged and stabilisation == PROJECTED:
                q_new, v_new = _projected(q_new, v_new, t_new, projection, model, counters)
        except Exception:  # noqa: BLE001 — LAPACK failures end the run as "failed"
            return q, v, k, FAILED_LINALG, reached
        if not converged:
            return q, v, k, FAILED_NEWTON, reached
        q, v, status = _checked(q, v, q_new, v_new, limit)
        if status != RUNNING:
            return q, v, k, status, reached
        k += 1


@njit(cache=True)
def run_explicit_samples(q, v, t0, dt, first, targets, method, model, stabilisation, projection,
                         partition, check_due, limit, passage, counters, q_out, v_out):
    """:func:`run_samples` for an explicit method (Adams–Bashforth, β₀ = 0): the same steps
    and numbers, in a loop without Newton's iteration that makes no array a step.  The new
    state is written into one of two slots, in turn, never the one holding the current state;
    only the RK4 start steps and ``direct``'s projection return new arrays.  On the spatial
    four-bar (ab5) a step took 1.81 µs here against 2.33 µs in :func:`run_samples`, where the
    explicit methods ran before: its Newton code cost their steps ~0.45 µs even where it never
    ran."""
    n = q.shape[0]
    alpha, beta, start_tableau, history = method[0], method[1], method[3], method[4]
    states = np.empty((1, 2, n))
    a = np.empty(n)
    slots = np.empty((2, 2, n))
    q_slots, v_slots = (slots[0, 0], slots[1, 0]), (slots[0, 1], slots[1, 1])
    current = -1  # the slot holding (q, v), -1 for none
    k = first
    reached = 0
    while True:
        reached = _hold_and_keep(states, q, v, k, targets, reached, q_out, v_out)
        if reached == targets.shape[0]:
            return q, v, k, RUNNING, reached
        t, t_new = t0 + k * dt, t0 + (k + 1) * dt
        try:
            if _start_step(q, v, t, method, model, counters, a):
                made = 1 if current == 0 else 0
                q_new, v_new = q_slots[made], v_slots[made]
                for e in range(n):
                    q_new[e] = _explicit_part(alpha, beta, history, dt, e)
                    v_new[e] = _explicit_part(alpha, beta, history, dt, n + e)
            else:
                q_new, v_new = kernel_nystrom_step(q, v, t, dt, start_tableau, model, partition,
                                                   np.int64(PLAIN), counters)  # as above
                made = -1
            if stabilisation == PROJECTED:
                q_new, v_new = _projected(q_new, v_new, t_new, projection, model, counters)
                made = -1
        except Exception:  # noqa: BLE001 — LAPACK failures end the run as "failed"
            return q, v, k, FAILED_LINALG, reached
        status = _divergence(q_new, v_new, limit)
        if status != RUNNING:
            return q, v, k, status, reached
        q, v, current = q_new, v_new, made
        k += 1
