"""The certified pivoted solve of redundant range-space systems
(:func:`mbh._adapters.inhouse.numerics.linalg.semidefinite_solve`): the truncated SVD's solution where it
certifies, no answer where it cannot, and the right accelerations on redundant mechanisms."""

from __future__ import annotations

import numpy as np
import pytest

from mbh._adapters.inhouse.bodies.kinematics import assemble
from mbh._adapters.inhouse.numerics.linalg import (NULL_LEVEL, certified_solve, pivot_order,
                                                   semidefinite_solve, truncated_solve)
from mbh._adapters.inhouse.formulations.stabilisation import NoStabilisation
from mbh._harness.model import scenario
from tests.helpers import parallel_revolute_fourbar

#: The factorisation chooses its own pivots.
NO_PIVOTS = np.empty(0, np.int64)


def _semidefinite(kept_values, deficiency, seed):
    """S = V diag(kept_values, 0…0) Vᵀ of size len(kept_values) + deficiency, V random
    orthogonal, shape (k, k)."""
    rng = np.random.default_rng(seed)
    k = len(kept_values) + deficiency
    basis, _ = np.linalg.qr(rng.normal(size=(k, k)))
    values = np.concatenate((kept_values, np.zeros(deficiency)))
    matrix = (basis * values) @ basis.T
    return 0.5 * (matrix + matrix.T)


@pytest.mark.parametrize("span", [0, 2, 4])
def test_the_pivoted_solve_is_the_truncated_svds_solution(span):
    """Sizes 2 … 36 with 1 … 3 null directions, kept eigenvalues over 10^span, an arbitrary
    right-hand side (so also the least-squares part): measured largest difference relative to
    |x| (2026-11-28) 8.8e-15, 2.1e-14, 1.2e-12 for spans 0, 2, 4; bound 1000 ε κ (25 times
    the first, 1,800 times the third)."""
    for k in range(2, 37):
        deficiency = 1 + k % 3 if k > 3 else 1
        matrix = _semidefinite(np.logspace(0, -span, k - deficiency), deficiency, k)
        rhs = np.random.default_rng(100 + k).normal(size=k)
        certified, x = semidefinite_solve(matrix, rhs, 1e-10, NO_PIVOTS)
        expected = truncated_solve(matrix, rhs, 1e-10)
        assert certified
        assert np.abs(x - expected).max() <= 1000 * 2.2e-16 * 10 ** span * np.abs(expected).max()


def test_the_pivots_of_one_matrix_serve_a_neighbour():
    """The order :func:`pivot_order` finds in one matrix with null directions, given to the solve
    of a neighbour with the same null space (its kept eigenvalues moved by up to 30 %, which
    reorders its diagonal), gives the truncated SVD's solution there, as the solve's own choice
    does: measured largest difference 1.2e-14 relative (2026-11-29), under the bound above for
    span 2 (2.2e-11); full rank has no pivot order."""
    for k in range(4, 20):
        deficiency = 1 + k % 3
        rng = np.random.default_rng(k)
        values = np.logspace(0, -2, k - deficiency)
        pivots = pivot_order(_semidefinite(values, deficiency, k), 1e-10)
        assert pivots.dtype == np.int64 and pivots.size == k - deficiency
        neighbour = _semidefinite(values * rng.uniform(0.7, 1.3, values.size), deficiency, k)
        rhs = rng.normal(size=k)
        certified, x = semidefinite_solve(neighbour, rhs, 1e-10, pivots)
        expected = truncated_solve(neighbour, rhs, 1e-10)
        assert certified
        assert np.abs(x - expected).max() <= 1000 * 2.2e-16 * 1e2 * np.abs(expected).max()
    assert pivot_order(_semidefinite(np.logspace(0, -2, 6), 0, 1), 1e-10).size == 0


def test_full_rank_is_left_to_the_plain_cholesky():
    matrix = _semidefinite(np.logspace(0, -3, 6), 0, 1)
    certified, x = semidefinite_solve(matrix, np.ones(6), 1e-10, NO_PIVOTS)
    assert not certified and x.size == 0
    certified, x = certified_solve(matrix, np.ones(6), 1e-10)
    assert certified and np.allclose(matrix @ x, np.ones(6), rtol=0, atol=1e-12)


@pytest.mark.parametrize("small", [1e-4, 1e-7])
def test_a_small_direction_that_is_not_null_is_left_to_the_svd(small):
    """An eigenvalue under the cut (1e-3) but far above round-off (a singular position, not a
    redundant row): the truncated SVD drops it; the pivoted solve gives no answer rather than
    decide it otherwise."""
    matrix = _semidefinite(np.array([1.0, 0.5, 0.2, small]), 1, 7)
    assert small > NULL_LEVEL
    certified, x = semidefinite_solve(matrix, np.ones(5), 1e-3, NO_PIVOTS)
    assert not certified and x.size == 0


def test_a_kept_direction_close_to_the_cut_is_left_to_the_svd():
    """Kept eigenvalues down to 1.5e-10 of the largest, just above the cut 1e-10, and one null
    direction: neither a certified kept part nor a certified null one."""
    matrix = _semidefinite(np.logspace(0, np.log10(1.5e-10), 5), 1, 3)
    certified, x = semidefinite_solve(matrix, np.ones(6), 1e-10, NO_PIVOTS)
    assert not certified and x.size == 0


@pytest.mark.parametrize("name", ["bricard", "fourbar_4r"])
def test_redundant_mechanisms_get_the_augmented_systems_accelerations(name):
    """At moving states of Bricard's mechanism (one redundant equation) and of a four-bar of
    parallel revolutes (three), q̈ equals the minimum-norm least-squares solution of the
    augmented system [M Φ_qᵀ; Φ_q 0] by numpy's SVD (q̈ is unique there; λ is not).  Measured
    largest difference relative to max(1, |q̈|) (2026-11-28): 2.9e-12 (Bricard), 1.5e-11
    (four-bar); with the truncated SVD in place of the pivoted solve 1.7e-13 and 1.5e-11 (the
    augmented system's own round-off, its masses 78–156 kg against Φ_q's entries ~1); bound
    2e-10."""
    mech = parallel_revolute_fourbar() if name == "fourbar_4r" else scenario.load(name)
    for value, rate in ((0.3, 1.0), (0.9, -2.0), (3.0, 0.5)):
        assembly = assemble(mech, value=value, rate=rate)
        q, v = assembly.q, assembly.v
        formulation = NoStabilisation(mech, q, 0.01)
        mass, force = formulation.dynamics.mass_and_forces(0.0, q, v)
        jacobian = formulation.constraints.jacobian(q, 0.0)
        gamma = formulation.constraints.gamma(q, v, 0.0)
        n, m = q.size, gamma.size
        system = np.block([[mass, jacobian.T], [jacobian, np.zeros((m, m))]])
        solution = np.linalg.lstsq(system, np.concatenate((force, gamma)), rcond=1e-12)[0]
        acceleration = formulation.acceleration(0.0, q, v)
        scale = max(1.0, np.abs(solution[:n]).max())
        assert np.abs(acceleration - solution[:n]).max() <= 2e-10 * scale
