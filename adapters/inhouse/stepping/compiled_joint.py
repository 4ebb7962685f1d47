"""The compiled stepping loops of the joint-coordinate model (``coords=joint``): a whole run of
(θ, θ̇) (n_θ,) in one numba call, each right-hand side one call of the function generated for
the mechanism or of
:func:`~mbh._adapters.inhouse.formulations.joint_rhs.acceleration_kernel`, as
:mod:`~mbh._adapters.inhouse.stepping.compiled` and :mod:`.compiled_multistep` run the absolute
model.

Each right-hand side is first asked of the function generated for the mechanism (where it
declines a call, a guard of its trace failing, the kernel computes it, counted as
``kernel_calls``): the kernel's result to the bit either way.

The steps are the Python path's (:class:`~mbh._adapters.inhouse.stepping.joint_stepper.JointStepper`
over :mod:`mbh._adapters.integrators`) in the same operation order, so the two agree to the bit
for ``none`` and ``baumgarte``:

* the explicit one-step methods: the Nyström tableau (c, A, Ā, b, b̄) of
  :func:`mbh._adapters.integrators.nystrom.nystrom_step` in a Euclidean space (θ ⊕ dθ = θ + dθ),
  its stages combined by :func:`~.kernel_step.combine_stages` (:func:`run_one_step_samples`);
* the explicit Adams–Bashforth methods (Rouvinen 2003, eq. 107, table 2): f at the step's start
  pushed into the history, classical RK4 steps (eqs. 102–106, step dt) until the history holds the
  points the method reads, then ψ of :func:`.compiled_multistep._explicit_part`
  (:func:`run_adams_bashforth_samples`);
* after each step, for ``direct``, Newton on Φ_θ(θ) = 0 with the truncated pseudo-inverse of
  C_θ = Φ_cut,q B (eq. 127 in θ), then θ̇ − C_θ⁺C_θθ̇ (eq. 137 in θ), as
  :meth:`~mbh._adapters.inhouse.formulations.joint_coordinates.JointDirect.project` does; its
  products C_θ = Φ_cut,q B and C_θθ̇ are loops here where the Python path calls BLAS, so
  ``direct`` agrees to round-off, not to the bit;
* then the divergence check of :meth:`mbh._adapters.integrators.base.Integrator.step`.

Arguments shared by the loops: θ, θ̇ (n_θ,) the state after step ``first``; t0, dt (s), step k
ending at t0 + k·dt; ``targets`` (k,) int64 increasing step indices whose states go to the rows
of ``theta_out``, ``rate_out`` (k, n_θ), and the counters after them to the rows of
``counters_out`` (k, :data:`~.loop_codes.COUNTERS`) int64 (a run the harness stops at a sample
reports the cost up to there, as the Python loop, which has stepped no further); ``model`` the arguments after (θ, θ̇, t) of
:func:`~mbh._adapters.inhouse.formulations.joint_rhs.acceleration_kernel` (its ``tree``,
``dynamics``, ``closure``, ``m_c``, ``gains``, ``cut``, ``pivots``) and the generated right-hand
side (:func:`~mbh._adapters.inhouse.codegen.generated.joint_function`, or
:data:`~mbh._adapters.inhouse.codegen.generated.NEVER`: the kernel for every call), then the
kernel's entry (:class:`~mbh._adapters.inhouse.stepping.native_call.NativeEntry`);
``projection`` None (``none``, ``baumgarte``: its code is then not compiled) or (proj_tol,
proj_max_iter, the pseudo-inverse's relative cut) of ``direct``; ``limit`` the divergence limit
on the 2-norms of θ and θ̇; ``counters`` (:data:`~.loop_codes.COUNTERS`,) int64, incremented in
place as the Python path counts (each right-hand side one evaluation, one C_θ, one
factorisation), and the calls the generated function handed to the kernel.  Each returns (θ, θ̇) after step ``done`` (new arrays), ``done``, the status
(:data:`~.loop_codes.RUNNING` when every target was reached, the divergence code of step
``done + 1``, or :data:`~.loop_codes.FAILED_LINALG` when it raised: the caller words that) and
the number of targets reached.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from mbh._adapters.inhouse.bodies import kernels
from mbh._adapters.inhouse.bodies.tree_pass import tree_pass
from mbh._adapters.inhouse.numerics.linalg import truncated_solve
from mbh._adapters.inhouse.stepping.compiled import _divergence, _keep_targets
from mbh._adapters.inhouse.stepping.compiled_multistep import _explicit_part
from mbh._adapters.inhouse.stepping.kernel_step import (combine_stages, count_evaluation,
                                                        hold_state)
from mbh._adapters.inhouse.stepping.loop_codes import (FACTORIZATIONS, FAILED_LINALG,
                                                       JACOBIAN_EVALS, KERNEL_CALLS,
                                                       NEWTON_ITERATIONS, RUNNING)
from mbh._adapters.inhouse.stepping.native_call import call_native


@njit(cache=True, inline="always")
def _acceleration(theta, rate, t, model, counters):
    """θ̈ (n_θ,) at (θ, θ̇, t): the generated function ``model[7]`` where it accepts the call,
    else :func:`~.joint_rhs.acceleration_kernel` on ``model``'s first seven entries, called
    through its entry ``model[8]`` (:mod:`.native_call`) and counted in
    ``counters[KERNEL_CALLS]`` (entry by entry: a star-unpacked call after positional ones is
    bytecode numba does not take)."""
    out = np.empty(theta.shape[0])
    if model[7](theta, rate, t, out) == 1:
        return out
    counters[KERNEL_CALLS] += 1
    return call_native(model[8], (theta, rate, t, model[0], model[1], model[2], model[3],
                                  model[4], model[5], model[6]))


@njit(cache=True)
def _nystrom_into(states, current, new, stage, stages, t, h, tableau, model, counters):
    """One step of the Nyström ``tableau`` (:func:`~.kernel_step.step_tableau`) from
    (θ, θ̇) = ``states[current]`` at t by h into ``states[new]`` ((2, 2, n_θ)); ``stage``
    (1, 2, n_θ) and ``stages`` (s, n_θ) are the run's buffers.

    Not inlined, nor is :func:`_project_into`, although inlined they compiled faster (the
    Adams–Bashforth loop after the right-hand side in 11 s against 16 s): each holds a call that
    raises (a solve), and the loops call them inside ``try``; numba 0.68.1's inlined code there
    does not leave for the handler at the raise (the loop counted a right-hand side more than the
    Python loop after a failed solve, and a minimal loop of that shape crashed the process)."""
    c, velocity_table, position_table = tableau
    count = c.shape[0]
    for i in range(count):
        combine_stages(stage, 0, states, current, stages, c[i] * h, h * h, position_table, h,
                       velocity_table, i)
        count_evaluation(counters)
        a = _acceleration(stage[0, 0], stage[0, 1], t + c[i] * h, model, counters)
        for e in range(a.shape[0]):
            stages[i, e] = a[e]
    combine_stages(states, new, states, current, stages, h, h * h, position_table, h,
                   velocity_table, count)


@njit(cache=True, inline="always")
def _keep(states, current, k, targets, reached, theta_out, rate_out, counters, counters_out):
    """:func:`~.compiled._keep_targets`, and the counters at each target kept into its row of
    ``counters_out``; the new count of targets reached (inlined: assignments only, called
    outside the loops' ``try``)."""
    kept = _keep_targets(states, current, k, targets, reached, theta_out, rate_out)
    for row in range(reached, kept):
        for c in range(counters.shape[0]):
            counters_out[row, c] = counters[c]
    return kept


@njit(cache=True)
def _closure_jacobian(theta, t, tree, closure, m_c, counters):
    """C_θ = Φ_cut,q B (m_c, n_θ) at θ."""
    counters[JACOBIAN_EVALS] += 1
    q, b, _ = tree_pass(theta, np.zeros(theta.shape[0]), tree)
    jac = kernels.jacobian(q, t, closure)
    c = np.zeros((m_c, theta.shape[0]))
    for r in range(m_c):
        for k in range(b.shape[0]):
            for j in range(theta.shape[0]):
                c[r, j] += jac[r, k] * b[k, j]
    return c


@njit(cache=True)
def _project_into(states, s, t, model, projection, counters):
    """``direct``'s correction of (θ, θ̇) = ``states[s]`` in place (module docstring):
    :func:`~mbh._adapters.inhouse.formulations.stabilisation.newton_onto` on Φ_θ with C_θ⁺
    truncated at ``projection``'s cut, then the velocity projection."""
    tree, closure, m_c = model[0], model[2], model[3]
    if m_c == 0:
        return
    proj_tol, proj_max_iter, cut = projection
    n = states.shape[2]
    theta = states[s, 0].copy()
    previous = np.inf
    for _ in range(proj_max_iter):
        residual = kernels.phi(tree_pass(theta, np.zeros(n), tree)[0], t, closure)[:m_c].copy()
        size = 0.0
        for r in range(m_c):
            size = max(size, abs(residual[r]))
        if size < proj_tol or not size < previous:
            break
        previous = size
        counters[NEWTON_ITERATIONS] += 1
        counters[FACTORIZATIONS] += 1
        theta = theta - truncated_solve(_closure_jacobian(theta, t, tree, closure, m_c, counters),
                                        residual, cut)
    c = _closure_jacobian(theta, t, tree, closure, m_c, counters)
    along = np.zeros(m_c)
    for r in range(m_c):
        for j in range(n):
            along[r] += c[r, j] * states[s, 1, j]
    counters[FACTORIZATIONS] += 1
    correction = truncated_solve(c, along, cut)
    for e in range(n):
        states[s, 0, e] = theta[e]
        states[s, 1, e] = states[s, 1, e] - correction[e]


@njit(cache=True)
def run_one_step_samples(theta, rate, t0, dt, first, targets, tableau, model, projection, limit,
                         counters, theta_out, rate_out, counters_out):
    """A fixed-step run of the explicit Nyström method ``tableau``
    (:func:`~.kernel_step.step_tableau`: c (s,), A⁺, Ā⁺ (s + 1, s)); the other arguments and the
    results as the module docstring says."""
    n = theta.shape[0]
    states, stage = np.empty((2, 2, n)), np.empty((1, 2, n))
    stages = np.empty((tableau[0].shape[0], n))
    hold_state(states, 0, theta, rate)
    # The slot of the current state typed int64 from the start: a literal 0 has numba compile
    # _nystrom_into twice, for Literal[int](0) and for int64 (10 s of compilation in all).
    current, k, reached = np.int64(0), first, 0
    while True:
        reached = _keep(states, current, k, targets, reached, theta_out, rate_out, counters,
                        counters_out)
        if reached == targets.shape[0]:
            return states[current, 0].copy(), states[current, 1].copy(), k, RUNNING, reached
        t, t_new = t0 + k * dt, t0 + (k + 1) * dt
        new = 1 - current
        try:
            _nystrom_into(states, current, new, stage, stages, t, t_new - t, tableau, model,
                          counters)
            if projection is not None:
                _project_into(states, new, t_new, model, projection, counters)
        except Exception:  # noqa: BLE001 — a failed solve ends the run; the caller words it
            return (states[current, 0].copy(), states[current, 1].copy(), k, FAILED_LINALG,
                    reached)
        status = _divergence(states[new, 0], states[new, 1], limit)
        if status != RUNNING:
            return states[current, 0].copy(), states[current, 1].copy(), k, status, reached
        current, k = new, k + 1


@njit(cache=True)
def run_adams_bashforth_samples(theta, rate, t0, dt, first, targets, method, model, projection,
                                limit, counters, theta_out, rate_out, counters_out):
    """A fixed-step run of an explicit linear multistep method (β₀ = 0), ``method`` as
    :func:`.compiled_multistep.method_arguments` makes it (α, β, the RK4 start tableau and the
    history (points, 2, 2n_θ) with its count ``held`` (1,), updated in place; its Newton members
    are not read); the other arguments and the results as the module docstring says."""
    alpha, beta, start_tableau, history, held = method[0], method[1], method[3], method[4], \
        method[5]
    n, points = theta.shape[0], history.shape[0]
    states, stage = np.empty((2, 2, n)), np.empty((1, 2, n))
    stages = np.empty((start_tableau[0].shape[0], n))
    hold_state(states, 0, theta, rate)
    current, k, reached = np.int64(0), first, 0  # int64 from the start: run_one_step_samples
    while True:
        reached = _keep(states, current, k, targets, reached, theta_out, rate_out, counters,
                        counters_out)
        if reached == targets.shape[0]:
            return states[current, 0].copy(), states[current, 1].copy(), k, RUNNING, reached
        t, t_new = t0 + k * dt, t0 + (k + 1) * dt
        new = 1 - current
        try:
            count_evaluation(counters)
            a = _acceleration(states[current, 0], states[current, 1], t, model, counters)
            for j in range(points - 1, 0, -1):
                for e in range(2 * n):
                    history[j, 0, e] = history[j - 1, 0, e]
                    history[j, 1, e] = history[j - 1, 1, e]
            for e in range(n):
                history[0, 0, e], history[0, 0, n + e] = states[current, 0, e], states[current, 1, e]
                history[0, 1, e], history[0, 1, n + e] = states[current, 1, e], a[e]
            held[0] = min(held[0] + 1, points)
            if held[0] == points:
                for e in range(n):
                    states[new, 0, e] = _explicit_part(alpha, beta, history, dt, e)
                    states[new, 1, e] = _explicit_part(alpha, beta, history, dt, n + e)
            else:
                _nystrom_into(states, current, new, stage, stages, t, dt, start_tableau, model,
                              counters)
            if projection is not None:
                _project_into(states, new, t_new, model, projection, counters)
        except Exception:  # noqa: BLE001 — a failed solve ends the run; the caller words it
            return (states[current, 0].copy(), states[current, 1].copy(), k, FAILED_LINALG,
                    reached)
        status = _divergence(states[new, 0], states[new, 1], limit)
        if status != RUNNING:
            return states[current, 0].copy(), states[current, 1].copy(), k, status, reached
        current, k = new, k + 1
