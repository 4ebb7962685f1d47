"""The in-house solves at singular positions (issue "Hard scenes" item 1) and the failure labels.

The rank-revealing pieces: :func:`mbh._adapters.inhouse.numerics.linalg.truncated_solve`, the range-space
acceleration :func:`mbh._adapters.inhouse.formulations.dynamics.range_space_acceleration`, the truncated projection
of :class:`mbh._adapters.inhouse.formulations.stabilisation.DirectCorrection`; and
:func:`mbh._harness.measure.failure_label.label_failure`.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

from mbh._adapters import get_adapter
from mbh._adapters.inhouse.bodies.constraints import ConstraintSystem
from mbh._adapters.inhouse.bodies.kinematics import common_start
from mbh._adapters.inhouse.formulations.dynamics import range_space_acceleration, solve_augmented
from mbh._adapters.inhouse.formulations.mass_and_forces import Dynamics
from mbh._adapters.inhouse.numerics.linalg import truncated_solve
from mbh._harness.model import scenario
from mbh._harness.run.case import run_case
from mbh._harness.neutral.conditioning import conditioning
from mbh._harness.model.outputs import output_series
from mbh._harness.references.build import reference_trajectory


def test_truncated_solve_is_the_minimum_norm_solution_without_the_lost_directions():
    rng = np.random.default_rng(3)
    rows = rng.normal(size=(3, 6))
    matrix = np.vstack([rows, rows[0] + rows[1]])  # one exactly redundant row
    rhs = matrix @ rng.normal(size=6)
    expected = scipy.linalg.lstsq(matrix, rhs, cond=1e-12)[0]
    # Two SVD-based paths (gesdd here, gelsd in SciPy): measured 1.1e-15; bound 1e-12.
    assert np.abs(truncated_solve(matrix, rhs, 1e-10) - expected).max() <= 1e-12
    tilted = np.diag([1.0, 1e-9])
    assert truncated_solve(tilted, np.array([1.0, 1.0]), 1e-6)[1] == 0.0


@pytest.mark.parametrize("name", ["fourbar", "slider_crank", "andrews"])
def test_range_space_acceleration_equals_the_augmented_solve_off_singular_positions(name):
    """Same q̈ as the LU of Rouvinen 2003, eq. 77 at the start (planar and Euler-parameter scenes, Andrews'
    moments of 1e-7 kg·m²).  Measured largest relative difference: fourbar 3.8e-15, slider_crank
    4.3e-16, andrews 9.2e-14; bound 1e-10 (100x the worst; two factorisations of a matrix of
    condition up to ~1e9 on Andrews)."""
    mech = scenario.load(name)
    start = common_start(mech)
    q, v = start.q, start.v
    constraints, dynamics = ConstraintSystem(mech), Dynamics(mech)
    mass, force = dynamics.mass_and_forces(0.0, q, v)
    jacobian, gamma = constraints.jacobian(q, 0.0), constraints.gamma(q, v, 0.0)
    plain = solve_augmented(mass, jacobian, force, gamma)[0]
    ranged = range_space_acceleration(mass, jacobian, force, gamma, 1e-10)
    assert np.abs(ranged - plain).max() <= 1e-10 * max(1.0, np.abs(plain).max())


@pytest.fixture(scope="module")
def double_fourbar():
    mech = scenario.load("double_fourbar")
    return mech, reference_trajectory(mech)


def _tip_error(mech, run, reference) -> float:
    index = np.round(run.times / 1e-3).astype(int)
    return max(float(np.abs(output_series(mech, run, name)
                            - output_series(mech, reference, name)[index]).max())
               for name in ("tip_x", "tip_y"))


@pytest.mark.parametrize("dt, bound", [
    # Measured over the first 1.5 s (two flattened passages), best = rk4+direct with
    # proj_tol 1e-15 and singular_cut 5e-2: 1.2e-11 m at dt 1e-3, 1.1e-11 m at 1e-4 (the
    # reference's own error there is ~2e-12 m).  Bound 1e-9: 80x.
    (1e-3, 1e-9),
    (1e-4, 1e-9),
])
def test_best_passes_the_first_singular_positions(double_fourbar, dt, bound):
    """Before the rank-revealing solves, rk4+direct at dt 1e-4 was 4.7e-7 m off after two
    passages, and at 1e-5 1.66 m (the second passage lost the branch, status ok)."""
    mech, reference = double_fourbar
    times = np.arange(151) * 1e-2
    run = get_adapter("inhouse").simulate(mech, "best", dt, 1.5, times)
    assert run.status == "ok"
    assert _tip_error(mech, run, reference) <= bound


def test_a_failure_at_a_singular_passage_says_so(double_fourbar):
    mech, reference = double_fourbar
    case = run_case(get_adapter("inhouse"), mech, "ida", 1e-2, 2.0, reference)
    trajectory = case.trajectory
    assert trajectory.status == "failed"
    # IDA stops at 0.7096 s; the reference's first flattened position is at 0.714 s.
    assert trajectory.reason.startswith("singular configuration")
    assert "t = 0.714 s" in trajectory.reason


def test_a_scene_without_singular_positions_has_none():
    mech = scenario.load("bricard")
    analysis = conditioning(mech, reference_trajectory(mech))
    assert analysis.rank == analysis.n_rows - 1
    assert analysis.minima.size == 0


def test_an_engine_that_cannot_close_the_overconstrained_loop_says_why():
    mech = scenario.load("bricard")
    case = run_case(get_adapter("pybullet"), mech, "best", 1e-3, 0.01, None)
    assert case.trajectory.status == "unsupported"
    assert "overconstrained loop: 1 of the 30 joint equations are redundant" in \
        case.trajectory.reason
