"""Coordinate partitioning in joint coordinates (``partition`` with ``coords=joint``): against the
verified references and the absolute ``partition``, its order, Bricard's redundant closure row,
an open chain, a block that lost rank, and the method listing.

Every bound below comes from a measurement stated next to it (2-core machine, 2026-11-29;
``benchmarks/joint_scenes.py`` for the whole scenes, docs/measurements.md, "Joint coordinates").
"""

from __future__ import annotations

import numpy as np
import pytest

from mbh._adapters import get_adapter
from mbh._adapters.inhouse.formulations.joint_partition import JointPartition
from mbh._adapters.integrators.base import StepFailure
from mbh._harness.measure.metrics import case_metrics
from mbh._harness.model import scenario
from mbh._harness.model.timegrid import sample_times
from mbh._harness.references.build import reference_trajectory
from mbh._harness.run.spec import main_output
from tests.adapters.inhouse.test_dynamics import measured_order

INHOUSE = get_adapter("inhouse")
JOINT = "rk4+partition:coords=joint"


def run(mech, method: str, dt: float, t_end: float):
    trajectory = INHOUSE.simulate(mech, method, dt, t_end, sample_times(dt, t_end))
    assert trajectory.status == "ok", trajectory.reason
    return trajectory


def main_error_and_gap(mech, trajectory) -> tuple[float, float]:
    """The main output's largest error against the verified reference (rad or m) and the stick's
    largest joint gap (m)."""
    metrics = case_metrics(mech, trajectory, reference_trajectory(mech))
    return metrics["output_errors"][main_output(mech)], metrics["max_constraint_violation"]


#: RK4 at 1 ms over 1 s, main-output error against the reference, joint (absolute, loop=python):
#: fourbar 8.17e-10 (8.20e-10) rad, slider_crank 1.52e-11 (6.60e-9) rad, bricard 2.95e-14
#: (1.14e-13) m; joint gaps of the joint runs 1.03e-13, 1.21e-13, 6.96e-14 m (Newton to
#: newton_tol 1e-13 on Φ_θ).  Bounds: 3× the absolute error, gaps 1e-12.  The absolute
#: partition re-partitions more often (slider_crank over its 8 s: 58 against 0) and is the less
#: accurate one on the spatial scenes (docs/measurements.md).
@pytest.mark.parametrize("name", ["fourbar", "slider_crank", "bricard"])
def test_joint_partition_meets_the_reference_as_the_absolute_one_does(name):
    mech = scenario.load(name)
    joint = main_error_and_gap(mech, run(mech, JOINT, 1e-3, 1.0))
    absolute = main_error_and_gap(mech, run(mech, "rk4+partition:loop=python", 1e-3, 1.0))
    assert joint[0] <= 3 * absolute[0], (joint, absolute)
    assert joint[1] <= 1e-12, joint


def test_joint_partition_converges_at_fourth_order():
    """The four-bar's crank angle at 5, 2.5, 1.25 ms over 1 s: measured slope 4.05 (5.54e-7,
    3.30e-8, 2.01e-9 rad; the absolute rk4+partition 4.05 at the same steps, 5.55e-7, 3.31e-8,
    2.01e-9).  Bound: the order within 0.3 (as test_dynamics.py's)."""
    slope, errors = measured_order("fourbar", JOINT, [5e-3, 2.5e-3, 1.25e-3], 1.0)
    assert abs(slope - 4.0) <= 0.3, (slope, errors)


def test_bricards_redundant_closure_row_is_kept_and_met():
    """Bricard's loop: 5 closure rows of rank 4, one independent θ.  Every row, the redundant
    one included, enters Newton's least squares: the run says so, and the stick's gaps (all
    joints) stay at Newton's tolerance (measured 7.0e-14 m over 1 s)."""
    mech = scenario.load("bricard")
    trajectory = run(mech, JOINT, 1e-3, 1.0)
    notes = " ".join(trajectory.notes)
    assert "5 closure equation(s) at cut joint(s) C of rank 4, 1 redundant" in notes
    assert "1 independent" in notes and "4 dependent" in notes and "redundant rows kept" in notes
    assert main_error_and_gap(mech, trajectory)[1] <= 1e-12


def test_an_open_chain_has_nothing_to_partition():
    """No closure equations: every θ is independent, and the run is the unconstrained one
    (rk4+none in joint coordinates) to the last bit."""
    mech = scenario.load("simple_pendulum")
    partitioned, plain = run(mech, JOINT, 1e-3, 0.5), run(mech, "rk4+none:coords=joint", 1e-3, 0.5)
    assert "no closure equations, every θ (joint pivot angle) integrated" in partitioned.notes[-1]
    np.testing.assert_array_equal(partitioned.position, plain.position)
    np.testing.assert_array_equal(partitioned.velocity, plain.velocity)


def test_a_dependent_block_without_full_column_rank_fails_the_step():
    """The least-squares solve refuses a block whose columns lost rank (here two equal ones)
    instead of returning a minimum-norm guess."""
    block = np.array([[1.0, 1.0], [2.0, 2.0], [0.0, 0.0]])
    with pytest.raises(StepFailure, match="lost rank"):
        JointPartition._dependent_solve(block, np.array([1.0, 2.0, 0.0]))
    # A tall block of full column rank with consistent rows: the exact solution.
    block = np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    np.testing.assert_allclose(JointPartition._dependent_solve(block, block @ [0.3, -0.2]),
                               [0.3, -0.2], rtol=0, atol=1e-15)


def test_partition_takes_coords():
    _, params = INHOUSE.method_spec("rk4+partition")
    assert params["coords"] == "absolute"
    assert INHOUSE.method_spec(JOINT)[1]["coords"] == "joint"
