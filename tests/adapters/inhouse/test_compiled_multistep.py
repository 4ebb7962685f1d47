"""The compiled path of the linear multistep methods (adapters/inhouse/stepping/compiled_multistep.py)
against the Python path (adapters/integrators/multistep.py on the Newton solver of newton.py),
and its written-out LU factorisation.

Bounds: the paths differ in the LU factorisation (LAPACK's on the Python path) and in the
Jacobian's differences (of the kernels' q̈ there, of the generated q̈ here), so an iterate may
stop one Newton iteration apart.  Each path stops once its scaled correction is ≤ tol = 1e-10, so
each step's state is within ~tol·(1 + |y|) of the exact solution of the step's equation on both:
≤ 2e-10·(1 + |y|) apart, |y| ≤ 3 on these scenes, summed over the 200 steps at most ~2e-7 if
every step differed and nothing damped it.  The bound 1e-7 is that; measured on this machine
(2026-11-27) the largest differences were 0 on the four-bar, 5.3e-15 (positions) and 3.0e-12
(velocities) on the stiff four-bar.  The explicit methods (Adams–Bashforth, their own loop) have
no iteration to stop apart; the bound holds them too, and they measured 0 on every case here.
"""

from __future__ import annotations

import numpy as np
import pytest

from mbh._adapters import get_adapter
from mbh._adapters.inhouse.stepping.compiled_multistep import lu_factor_into, lu_solve_into
from mbh._harness.model import scenario
from mbh._harness.model.timegrid import sample_times
from mbh._harness.references.build import reference_trajectory
from mbh._harness.run.case import run_case

#: Largest difference of the two paths' positions (m, rad) and velocities (module docstring).
NEWTON_PATH_BOUND = 1e-7

CASES = [("fourbar", "am1+baumgarte"), ("fourbar", "am2+none"), ("fourbar", "bdf2+direct"),
         ("fourbar", "bdf4+baumgarte"), ("fourbar", "ab3+baumgarte"), ("fourbar", "ab5+direct"),
         ("fourbar_spatial", "ab5+baumgarte"), ("slider_crank", "ab1+none"),
         ("stiff_fourbar", "am1+baumgarte"), ("stiff_fourbar", "bdf2+direct")]


def _run(name: str, method: str, loop: str, dt: float = 1e-3, steps: int = 200):
    mech = scenario.load(name)
    t_end = steps * dt
    separator = "," if ":" in method else ":"
    return get_adapter("inhouse").simulate(mech, f"{method}{separator}loop={loop}", dt, t_end,
                                           sample_times(dt, t_end, mech.sample_step))


@pytest.mark.parametrize("loop", ["compiled", "generated"])
@pytest.mark.parametrize("name, method", CASES)
def test_compiled_and_python_multistep_paths_agree(name, method, loop):
    python, compiled = _run(name, method, "python"), _run(name, method, loop)
    assert (compiled.status, compiled.failure_time, compiled.steps, compiled.reason) == \
        (python.status, python.failure_time, python.steps, python.reason) == \
        ("ok", None, 200, "")
    assert compiled.n_samples == python.n_samples > 1
    assert np.abs(compiled.position - python.position).max() <= NEWTON_PATH_BOUND
    assert np.abs(compiled.velocity - python.velocity).max() <= NEWTON_PATH_BOUND
    # Measured: the same right-hand sides on every case; Newton and projection iterations the
    # same but for bdf2+direct on the stiff four-bar (318 against 314: projections that stop at
    # proj_tol one iteration apart).  An iteration apart here and there is what the paths
    # promise (module docstring), not the count.
    for key, share in (("rhs_evals", 0.01), ("newton_iterations", 0.03)):
        assert abs(compiled.counters[key] - python.counters[key]) <= share * python.counters[key]
    if loop == "generated":
        assert compiled.counters["kernel_calls"] == 0


@pytest.mark.parametrize("method, dt, failure", [
    # Its RK4 start step is far outside RK4's stability region (|hλ| ≈ 34 on the fast mode): no
    # iterate of the BDF2 step converges from the state it leaves.
    ("bdf2+baumgarte", 1e-2,
     ("failed", 0.01, 1, "StepFailure: Newton iteration did not converge in 10 iterations to "
                         "tol=1e-10 at t=0.02")),
    ("am1+baumgarte:max_iter=1", 5e-3,
     ("failed", 0.0, 0, "StepFailure: Newton iteration did not converge in 1 iterations to "
                        "tol=1e-10 at t=0.005")),
])
def test_a_newton_failure_is_reported_alike_on_both_paths(method, dt, failure):
    """Measured on the stiff four-bar: both paths fail in the same step with the same words
    (the first case once had the compiled path step on to a non-finite state: a NaN correction
    must not pass the convergence test)."""
    runs = [_run("stiff_fourbar", method, loop, dt, 20) for loop in ("python", "generated")]
    for run in runs:
        assert (run.status, run.failure_time, run.steps, run.reason) == failure
    np.testing.assert_array_equal(runs[0].times, runs[1].times)


@pytest.mark.parametrize("loop", ["compiled", "generated"])
def test_an_explicit_method_diverges_alike_on_both_paths(loop):
    """Adams–Bashforth 2 at 5e-3 s on the stiff four-bar (far outside its stability region on
    the fast mode), measured: both paths stop after step 5 with the same words, and the
    samples kept before are the same (the explicit loop writes each new state into a slot that
    does not hold the last good one)."""
    python, compiled = (_run("stiff_fourbar", "ab2+baumgarte", path, 5e-3, 40)
                        for path in ("python", loop))
    for run in (python, compiled):
        assert (run.status, run.failure_time, run.steps, run.reason) == \
            ("diverged", 0.025, 5, "state norm exceeds divergence_limit=1e+08")
    assert compiled.n_samples == python.n_samples > 1
    assert np.abs(compiled.position - python.position).max() <= NEWTON_PATH_BOUND


def test_backward_euler_runs_the_stiff_fourbar_where_explicit_methods_diverge():
    """The stiff four-bar (fast mode −1690 ± 2900i 1/s) at 5e-3 s over its whole 1 s: RK4
    diverges (stable below ~8e-4 s); am1 (backward Euler) on the compiled loop is ``ok`` and,
    measured, 1.6e-10 rad from the reference in the crank angle (the fast transient has died
    out at the first sample, 0.01 s; the equilibrium is what the samples measure).  The loop is
    asked for explicitly: its 200 steps are under ``loop=auto``'s threshold for compiling new
    generated functions, so on a fresh cache ``auto`` would run the kernels (and say so).
    tests/references/test_hard_fourbars.py checks the same method's energy balance."""
    mech = scenario.load("stiff_fourbar")
    reference = reference_trajectory(mech)
    adapter = get_adapter("inhouse")
    implicit = run_case(adapter, mech, "am1+baumgarte:loop=generated", 5e-3, mech.duration,
                        reference)
    explicit = run_case(adapter, mech, "rk4+baumgarte", 5e-3, mech.duration, reference)
    assert explicit.trajectory.status == "diverged"
    assert implicit.trajectory.status == "ok"
    assert implicit.metrics["output_errors"]["crank_angle"] <= 1e-9
    assert implicit.trajectory.counters["kernel_calls"] == 0
    assert not implicit.trajectory.notes


@pytest.mark.parametrize("size", [3, 18, 42])
def test_the_written_out_lu_solves_with_a_backward_error_at_round_off(size):
    """Random matrices with rows scaled over 1e-3 … 1e3, so that partial pivoting reorders them:
    the residual |A x − b| is within n·1e-13·max|A|·max|x| (partial pivoting is backward stable;
    measured ≤ 6.1e-16 of that scale at n = 42), and the solution is numpy's (LAPACK gesv) to the same
    order."""
    rng = np.random.default_rng(size)
    matrix = rng.standard_normal((size, size)) * np.logspace(-3, 3, size)[:, None]
    rhs = rng.standard_normal(size)
    lu, pivots, x = matrix.copy(), np.zeros(size, dtype=np.int64), rhs.copy()
    assert lu_factor_into(lu, pivots)
    assert np.any(pivots != np.arange(size))
    lu_solve_into(lu, pivots, x)
    scale = np.abs(matrix).max() * np.abs(x).max()
    assert np.abs(matrix @ x - rhs).max() <= size * 1e-13 * scale
    expected = np.linalg.solve(matrix, rhs)
    assert np.abs(matrix @ (x - expected)).max() <= size * 1e-13 * scale


def test_the_written_out_lu_refuses_a_singular_matrix():
    matrix = np.array([[1.0, 2.0], [2.0, 4.0]])
    assert not lu_factor_into(matrix.copy(), np.zeros(2, dtype=np.int64))
