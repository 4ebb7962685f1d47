"""The compiled stepping path (adapters/inhouse/compiled*.py), with the generic kernels and with
the generated right-hand side, against the Python path, and the certified Cholesky solves that
replaced the SVD where no direction is cut.

Bounds: both paths run the same compiled kernels in the same operation order; measured on this
machine (2026-11-24) their trajectories are bit-identical on every scene and method below (largest
difference 0.0; 6.7e-16 for rk4+partition on double_fourbar, whose dependent-coordinate Newton
solves and sensitivities are small products numpy and numba sum differently).  Over longer runs
partitioning amplifies such round-off where the split is a close call (measured over 1 s:
1.3e-10 m on fourbar, 5e-10 on fourbar_spatial with one re-partition more, 2.4e-8 on
double_fourbar after its first singular passage), which is why the runs here are short.  The bound allows round-off of a differently vectorised build (AVX-512 summation
of the small matrix products: ~1e-16 relative per operation, a few hundred steps, amplification
≤ ~10 over these short runs) with a wide margin, and is far below any method's error (≥ 1e-12 m at
these steps).
"""

from __future__ import annotations

import numpy as np
import pytest

from mbh._adapters import get_adapter
from mbh._adapters.base import RunGrid
from mbh._adapters.inhouse.numerics.linalg import (certified_spd_solve, min_norm_solve,
                                                   truncated_solve)
from mbh._harness.model import scenario
from mbh._harness.model.timegrid import sample_times
from tests.helpers import LARGE_TRACES, PATH_BOUND

METHODS = ("rk4+direct:proj_tol=1e-15", "rkn4+baumgarte", "heun+none", "rk4+partition",
           "rk8+direct")


def _run(name: str, method: str, loop: str):
    mech = scenario.load(name)
    dt = mech.sample_step / 10 if mech.sample_step < 1e-2 else 1e-3
    t_end = 200 * dt
    separator = "," if ":" in method else ":"
    return get_adapter("inhouse").simulate(mech, f"{method}{separator}loop={loop}", dt, t_end,
                                           sample_times(dt, t_end, mech.sample_step))


SCENE_LOOPS = [pytest.param(name, loop, marks=pytest.mark.slow)
               if loop == "generated" and name in LARGE_TRACES else (name, loop)
               for name in scenario.scenario_names() for loop in ("compiled", "generated")]


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("name, loop", SCENE_LOOPS)
def test_compiled_and_python_paths_agree(name, loop, method):
    python, compiled = _run(name, method, "python"), _run(name, method, loop)
    assert (compiled.status, compiled.failure_time, compiled.steps, compiled.reason) == \
        (python.status, python.failure_time, python.steps, python.reason)
    assert compiled.n_samples == python.n_samples > 1
    assert np.abs(compiled.position - python.position).max() <= PATH_BOUND
    assert np.abs(compiled.velocity - python.velocity).max() <= PATH_BOUND
    for key in ("rhs_evals", "newton_iterations", "repartitions"):
        assert compiled.counters[key] == python.counters[key]
    if loop == "compiled":
        return
    # The generated functions serve the calls: measured, their guards handed none of these runs'
    # right-hand sides to the kernel; Bricard's trace is too large, which its note says, and the
    # kernel serves every stage.
    skipped = [note for note in compiled.notes if note.startswith("not generated")]
    if name == "bricard":
        assert skipped and compiled.counters["kernel_calls"] == compiled.counters["rhs_evals"]
    else:
        assert not skipped
        assert compiled.counters["kernel_calls"] <= compiled.counters["rhs_evals"] // 100


def test_a_divergence_is_reported_alike_on_both_paths():
    """Baumgarte gains far beyond the explicit stability limit: measured, both paths diverge in
    the 15th step of dt = 0.01 s (state norm above the limit) and keep the 0.14 s samples."""
    mech = scenario.load("fourbar")
    runs = [get_adapter("inhouse").simulate(
        mech, f"euler+baumgarte:alpha=500,beta=500,loop={loop}", 0.01, 2.0,
        sample_times(0.01, 2.0)) for loop in ("python", "compiled")]
    assert {(r.status, r.failure_time, r.reason, r.steps) for r in runs} == \
        {("diverged", 0.15, "state norm exceeds divergence_limit=1e+08", 15)}
    np.testing.assert_array_equal(runs[0].times, runs[1].times)


def test_a_divergence_between_samples_keeps_its_step_time_on_both_paths():
    """Ten steps per sample: measured, both paths diverge in step 39 (t = 0.039 s), keep the
    samples up to 0.03 s and name 0.038 s, the last good step, as the failure time; the compiled
    path found it inside its one call through every sample."""
    mech = scenario.load("fourbar")
    runs = [get_adapter("inhouse").simulate(
        mech, f"euler+baumgarte:alpha=3000,beta=3000,loop={loop}", 1e-3, 2.0,
        sample_times(1e-3, 2.0)) for loop in ("python", "compiled")]
    assert {(r.status, r.failure_time, r.steps, r.n_samples) for r in runs} == \
        {("diverged", 0.038, 38, 4)}
    assert np.abs(runs[0].position - runs[1].position).max() <= PATH_BOUND


def test_a_whole_run_in_one_call_hands_out_each_sample_and_refuses_to_go_back():
    # The first _step_to integrates through every sample (compiled.run_samples); the states it
    # hands out are those of stepping sample by sample (same calls, so equal to the bit).
    mech, adapter = scenario.load("fourbar"), get_adapter("inhouse")
    spec, params = adapter.method_spec("rk4+direct:loop=compiled")
    grid = RunGrid(1e-3, 0.05, sample_times(1e-3, 0.05), True)
    whole, stepwise = adapter._start(mech, spec, params, grid), \
        adapter._start(mech, spec, params, grid)
    for t in grid.sample_times:
        whole._step_to(t)
        stepwise.q, stepwise.v, stepwise.steps, _ = stepwise._run(grid.steps(t))
        assert whole.steps == stepwise.steps
        q, v = whole._full(t)  # the stored sample's row, cut out when read
        np.testing.assert_array_equal(q, stepwise.q)
        np.testing.assert_array_equal(v, stepwise.v)
    with pytest.raises(ValueError, match="step 25 was passed without its state being kept"):
        whole._step_to(0.025)


def test_an_unknown_loop_is_refused_by_name():
    mech = scenario.load("fourbar")
    with pytest.raises(ValueError, match="parameter 'loop' of 'rk4\\+direct' must be one of "
                                         "auto, generated, compiled, python, got 'gpu'"):
        get_adapter("inhouse").simulate(mech, "rk4+direct:loop=gpu", 1e-3, 0.01,
                                        sample_times(1e-3, 0.01))


def _spd(values, seed):
    rng = np.random.default_rng(seed)
    basis, _ = np.linalg.qr(rng.normal(size=(len(values), len(values))))
    return (basis * values) @ basis.T


def test_certified_solve_is_the_exact_solve_when_well_conditioned():
    matrix = _spd(np.logspace(0, -3, 6), 1)
    rhs = np.arange(1.0, 7.0)
    certified, x = certified_spd_solve(matrix, rhs, 1e-10)
    assert certified
    # κ = 1e3: forward error ≤ ~κ ε; 1e-11 relative leaves 40× margin over κ·ε.
    assert np.abs(x - np.linalg.solve(matrix, rhs)).max() <= 1e-11 * np.abs(x).max()


@pytest.mark.parametrize("values", [np.logspace(0, -12, 5), np.array([1.0, 1.0, 0.0]),
                                    np.array([1.0, -1e-3, 1.0])])
def test_no_certificate_near_the_cut_or_without_positive_definiteness(values):
    """κ = 1e12 > 1/cut, a singular and an indefinite matrix: the caller must fall back."""
    certified, x = certified_spd_solve(_spd(values, 2), np.ones(values.size), 1e-10)
    assert not certified and x.size == 0


@pytest.mark.parametrize("span", [3, 8, 12])
def test_the_written_out_cholesky_factor_matches_lapacks(span):
    """Sizes 1 … 25 with condition numbers 10^span.  Measured largest difference relative to
    max |L| (2026-11-25): 1.8e-15, 2.2e-12, 1.9e-10 (a different summation order's round-off,
    growing like ε·√κ on the trailing pivots); bound 100 ε √κ."""
    from mbh._adapters.inhouse.numerics.linalg import _cholesky

    for k in range(1, 26):
        matrix = _spd(np.logspace(0, -span, k), k)
        positive, lower = _cholesky(matrix)
        reference = np.linalg.cholesky(matrix)
        assert positive
        assert np.abs(lower - reference).max() <= 100 * 2.2e-16 * 10 ** (span / 2) \
            * np.abs(reference).max()


@pytest.mark.parametrize("last", [-1e-3, -1.0])
def test_the_written_out_cholesky_refuses_what_lapack_refuses(last):
    """A clearly negative eigenvalue: no positive factor, as LAPACK's potrf decides."""
    from mbh._adapters.inhouse.numerics.linalg import _cholesky

    matrix = _spd(np.array([1.0, 0.5, last]), 4)
    with pytest.raises(np.linalg.LinAlgError):
        np.linalg.cholesky(matrix)
    assert not _cholesky(matrix)[0]


def test_a_nan_entry_gets_no_certificate():
    """The written-out factorisation stops at a NaN pivot (OpenBLAS's potrf lets it through and
    the NaN bound then failed the certificate): either way no certificate."""
    matrix = np.eye(3)
    matrix[2, 2] = np.nan
    certified, x = certified_spd_solve(matrix, np.ones(3), 1e-10)
    assert not certified and x.size == 0


def test_the_comparison_bound_bounds_the_inverse_norm():
    """‖L⁻¹‖₂² ≤ the O(k²) comparison-matrix bound for Cholesky factors of sizes 1 … 30 with
    condition numbers up to 1e12: a theorem, so the only slack allowed is round-off (1e-12
    relative)."""
    from mbh._adapters.inhouse.numerics.linalg import _comparison_bound

    for k in range(1, 31):
        lower = np.linalg.cholesky(_spd(np.logspace(0, -(k % 13), k), k))
        exact = np.linalg.norm(np.linalg.inv(lower), 2) ** 2
        assert _comparison_bound(lower) >= exact * (1.0 - 1e-12)


def test_what_the_comparison_bound_overestimates_the_frobenius_bound_certifies():
    """L with ones on and below the diagonal (k = 40): L⁻¹ is bidiagonal, ‖L⁻¹‖_F² = 2k − 1 = 79,
    but M(L)⁻¹ has entries 2^(i−j−1), so the O(k²) bound is ~1e23 and only the ‖L⁻¹‖_F bound can
    certify S = LLᵀ (‖S‖_F·79 ≈ 5e4, far inside 1/(10·cut) = 1e9).  κ₂(S) ≈ 2.6e3: a relative
    error of 1e-11 leaves ~20 times κ·ε."""
    from mbh._adapters.inhouse.numerics.linalg import _comparison_bound

    lower = np.tril(np.ones((40, 40)))
    assert _comparison_bound(lower) > 1e20
    matrix, rhs = lower @ lower.T, np.linspace(-1.0, 1.0, 40)
    certified, x = certified_spd_solve(matrix, rhs, 1e-10)
    assert certified
    assert np.abs(x - np.linalg.solve(matrix, rhs)).max() <= 1e-11 * np.abs(x).max()


def test_the_loop_products_match_numpys():
    """The BLAS-free products of the range-space solves on a sparse 8 × 9 Jacobian-like matrix;
    measured differences ≤ 4.5e-16 on entries of ~1-10 (summation order), bound 1e-14; the
    weighted Gram matrix is exactly symmetric."""
    from mbh._adapters.inhouse.numerics.linalg import matvec, rmatvec, weighted_gram

    rng = np.random.default_rng(5)
    matrix = rng.normal(size=(8, 9))
    matrix[matrix < 0.3] = 0.0
    weights = rng.uniform(0.5, 2.0, 9)
    x, y = rng.normal(size=9), rng.normal(size=8)
    gram = weighted_gram(matrix, weights)
    np.testing.assert_array_equal(gram, gram.T)
    assert np.abs(gram - (matrix * weights) @ matrix.T).max() <= 1e-14
    assert np.abs(matvec(matrix, x) - matrix @ x).max() <= 1e-14
    assert np.abs(rmatvec(matrix, y) - matrix.T @ y).max() <= 1e-14


def test_min_norm_solve_matches_the_truncated_svd_with_and_without_a_certificate():
    rng = np.random.default_rng(3)
    wide = rng.normal(size=(4, 7))
    rhs = rng.normal(size=4)
    # Well conditioned (certified): the normal-equation solution equals the SVD's to round-off.
    assert np.abs(min_norm_solve(wide, rhs, 1e-3) - truncated_solve(wide, rhs, 1e-3)).max() \
        <= 1e-12 * np.abs(truncated_solve(wide, rhs, 1e-3)).max()
    # A redundant row (rank 3): no Cholesky certificate; the pivoted factorisation of AAᵀ
    # certifies its null direction and answers as the truncated SVD does (measured difference
    # 2.2e-15 relative, 2026-11-28).
    redundant = np.vstack([wide[:3], wide[0] + wide[1]])
    expected = truncated_solve(redundant, rhs, 1e-3)
    assert np.abs(min_norm_solve(redundant, rhs, 1e-3) - expected).max() \
        <= 1e-12 * np.abs(expected).max()
    # A row nearly but not exactly redundant (σ_min/σ_max 1.8e-4, under the cut 1e-3): the
    # truncated SVD itself answers, as before.
    nearly = np.vstack([wide[:3], wide[0] + wide[1] + 1e-3 * wide[3]])
    np.testing.assert_array_equal(min_norm_solve(nearly, rhs, 1e-3),
                                  truncated_solve(nearly, rhs, 1e-3))


# --- the banded solves of large planar mechanisms (adapters/inhouse/numerics/banded.py) ----------------

@pytest.mark.parametrize("n_cells", [16, 64])
def test_banded_solves_match_the_dense_ones_on_the_n_fourbar(n_cells):
    """Banded Cholesky (RCM order) against the dense range-space solve and the truncated SVD at
    the start of n_fourbar@N.  Measured differences (2026-11-24): accelerations 1.1e-14 (N = 16)
    and 5.3e-15 (N = 64) on values of ~1; projections 5.8e-15 and 1.1e-14 on ~2.6.  Bound 1e-11:
    a different factorisation's round-off times the condition number (κ(Φ_qΦ_qᵀ) = 9e3 at N = 64)
    with margin."""
    from mbh._adapters.inhouse.numerics.banded import BANDED_MIN_ROWS, min_norm_correction
    from mbh._adapters.inhouse.formulations.dynamics import (ACCELERATION_CUT, index1_acceleration,
                                                            range_space_acceleration)
    from mbh._adapters.inhouse.formulations.mass_and_forces import mass_and_forces_kernel
    from mbh._adapters.inhouse.bodies.kinematics import common_start
    from mbh._adapters.inhouse.formulations.stabilisation import NoStabilisation

    mech = scenario.load(f"n_fourbar@{n_cells}")
    start = common_start(mech)
    formulation = NoStabilisation(mech, start.q, 1e-3)
    constraints = formulation.constraints
    assert constraints.m >= BANDED_MIN_ROWS and constraints.sparsity.bandwidth == 5
    q, v = start.q, start.v
    banded = index1_acceleration(q, v, 0.0, 0.0, 0.0, formulation.rows, constraints.kernel_args,
                                 formulation.dynamics.kernel_args, constraints.sparsity.arrays)
    mass, force = mass_and_forces_kernel(q, v, *formulation.dynamics.kernel_args)
    dense = range_space_acceleration(mass, constraints.jacobian(q), force, constraints.gamma(q, v),
                                     ACCELERATION_CUT)
    assert np.abs(banded - dense).max() <= 1e-11
    jacobian = constraints.jacobian(q)
    residual = np.sin(np.arange(constraints.m))
    assert np.abs(min_norm_correction(jacobian, residual, 1e-3, constraints.sparsity.arrays)
                  - truncated_solve(jacobian, residual, 1e-3)).max() <= 1e-11


@pytest.mark.parametrize("name", ["fourbar_spatial", "slider_crank"])
def test_the_euler_parameter_block_solve_matches_the_dense_one(name):
    """The block-diagonal solve of Euler-parameter bodies (only the rows touching each body,
    S = Φ_q M'⁻¹ Φ_qᵀ from the rows' patterns) against the dense M̃ form, at the start with a
    random velocity in Φ_q's null space.  Measured differences: 4.3e-14 on accelerations up to
    7.2 (fourbar_spatial), 4.4e-14 on 12.4 (slider_crank) (2026-11-25); 1.8e-14 and 2.3e-14 with
    each body's rotational block inverse made once (2026-11-27); bound 1e-11 as for the banded
    solves above."""
    from mbh._adapters.inhouse.formulations.dynamics import (
        ACCELERATION_CUT, range_space_acceleration)
    from mbh._adapters.inhouse.formulations.mass_and_forces import (
        mass_and_forces_kernel, spatial_block_acceleration)
    from mbh._adapters.inhouse.bodies.kinematics import common_start
    from mbh._adapters.inhouse.formulations.stabilisation import NoStabilisation

    mech = scenario.load(name)
    q = common_start(mech).q
    formulation = NoStabilisation(mech, q, 1e-3)
    constraints, dynamics = formulation.constraints, formulation.dynamics
    jacobian = constraints.jacobian(q, 0.3)
    r = np.random.default_rng(0).normal(size=q.size)
    v = r - np.linalg.pinv(jacobian) @ (jacobian @ r)
    gamma = constraints.gamma(q, v, 0.3)
    mass, force = mass_and_forces_kernel(q, v, *dynamics.kernel_args)
    nc, masses, inertias = dynamics.kernel_args[:3]
    kind, bi, row = (constraints.kernel_args[k] for k in (1, 2, 4))
    accepted, block = spatial_block_acceleration(q, jacobian, force, gamma, nc, masses, inertias,
                                                 kind, bi, row, constraints.sparsity.arrays,
                                                 ACCELERATION_CUT)
    dense = range_space_acceleration(mass, jacobian, force, gamma, ACCELERATION_CUT)
    assert accepted
    assert np.abs(block - dense).max() <= 1e-11


def test_the_bandwidth_of_the_n_fourbar_does_not_grow_with_n():
    from mbh._adapters.inhouse.bodies.constraints import ConstraintSystem

    widths = {n: ConstraintSystem(scenario.load(f"n_fourbar@{n}")).sparsity.bandwidth
              for n in (4, 16, 64)}
    assert widths == {4: 5, 16: 5, 64: 5}
