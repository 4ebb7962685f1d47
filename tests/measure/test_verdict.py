"""The stick's verdict (harness/measure/verdict.py, harness/measure/branch.py): corrupted copies of the four-bar's
verified reference must lose ``ok`` at the right time with the right reason; honest runs keep it.

Measured on the four-bar reference (4 s, sampled here every 10 ms): size ℓ = 5.74 m, so the gap
bound is 5e-3 ℓ = 2.87 cm and the branch bound 0.1 ℓ = 0.574 m; energy scale 17.7 kJ (its largest
kinetic energy), energy bound 885 J.  The reference itself has joint gaps ≤ 1.3e-14 m, energy
error ≤ 6e-8 J, distance from its own branch ≤ 1.4e-14 m, and two of its visits to one driver
angle differ by ≤ 2.0e-4 m.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from mbh._adapters import get_adapter
from mbh._harness.model import scenario
from mbh._harness.run.case import run_case
from mbh._harness.model.outputs import output_series
from mbh._harness.references.build import reference_trajectory
from mbh._harness.model.trajectory import Trajectory
from mbh._harness.measure.verdict import Bounds, characteristic_length, joint_violations, judge

STRIDE = 10  # reference samples per test sample: a 10 ms grid


@pytest.fixture(scope="module")
def mech():
    return scenario.load("fourbar")


@pytest.fixture(scope="module")
def reference(mech):
    return reference_trajectory(mech)


def _late_by(reference: Trajectory, lag: int) -> Trajectory:
    """The 10 ms grid of ``reference`` with the states ``lag`` reference samples (ms) earlier,
    held at the start meanwhile (fresh arrays, to corrupt)."""
    earlier = np.maximum(np.arange(0, reference.n_samples, STRIDE) - lag, 0)
    return dataclasses.replace(
        reference, times=reference.times[::STRIDE].copy(),
        **{key: getattr(reference, key)[earlier].copy()
           for key in ("position", "quaternion", "velocity", "angular_velocity")})


@pytest.fixture()
def run(reference):
    """A fresh copy of the reference on a 10 ms grid, to corrupt."""
    return _late_by(reference, 0)


def index_at(run: Trajectory, time: float) -> int:
    return int(np.argmin(np.abs(run.times - time)))


def test_the_reference_itself_is_ok(mech, reference, run):
    judged = judge(mech, run, reference)
    assert judged.status == "ok" and judged.reason == "" and judged.notes == []


def test_non_finite_velocity_is_diverged_at_its_time(mech, reference, run):
    k = index_at(run, 2.0)
    run.velocity[k:, 1, 0] = np.nan
    judged = judge(mech, run, reference)
    assert judged.status == "diverged"
    assert judged.reason.startswith("at t = 2 s: non-finite velocity")
    assert judged.failure_time == pytest.approx(1.99)
    assert judged.n_samples == run.n_samples  # the samples are kept


def test_a_5_cm_joint_gap_is_not_ok(mech, reference, run):
    run.position[index_at(run, 1.0):, 2, 0] += 0.05  # the rocker slides off joints C and R
    judged = judge(mech, run, reference)
    # 0.05 m against the 2.87 cm bound; the branch distance (5 cm) stays under its 57 cm bound
    assert judged.status == "failed"
    assert judged.reason.startswith("at t = 1 s: joint gap 0.05 m exceeds 0.0287 m")
    assert "assembly branch" not in judged.reason
    assert judged.failure_time == pytest.approx(0.99)


def test_a_gap_within_an_overridden_bound_stays_ok(mech, reference, run):
    run.position[index_at(run, 1.0):, 2, 0] += 0.05
    assert judge(mech, run, reference, Bounds(gap=1e-2)).status == "ok"  # bound 5.7 cm


def _crossed_branch(reference: Trajectory) -> Trajectory:
    """The four-bar's other (crossed) assembly branch at the reference's crank states: joint C
    mirrored across the line from the crank tip B to the ground pivot R, the coupler and the
    rocker redrawn through it (both have their joint points on their local x axis, centres
    midway), velocities by central differences on the reference's 1 ms grid."""
    tip = 2.0 * reference.position[:, 0]  # crank from O = 0, centre midway
    pivot = np.array([2.5, 0.0, 0.0])
    c = 2.0 * reference.position[:, 1] - tip
    axis = (pivot - tip) / np.linalg.norm(pivot - tip, axis=1, keepdims=True)
    arm = c - tip
    mirrored = tip + 2.0 * np.einsum("ni,ni->n", arm, axis)[:, None] * axis - arm
    run = dataclasses.replace(reference, **{key: getattr(reference, key).copy() for key in
                                            ("position", "quaternion", "velocity",
                                             "angular_velocity")})
    for body, start in ((1, tip), (2, pivot)):
        run.position[:, body] = 0.5 * (start + mirrored)
        angle = np.unwrap(np.arctan2(*(mirrored - start)[:, 1::-1].T))
        run.quaternion[:, body] = np.column_stack([np.cos(angle / 2), 0 * angle, 0 * angle,
                                                   np.sin(angle / 2)])
        run.velocity[:, body] = np.gradient(run.position[:, body], reference.times, axis=0)
        run.angular_velocity[:, body, 2] = np.gradient(angle, reference.times)
    return run


@pytest.fixture(scope="module")
def crossed(mech, reference):
    """The reference until t = 2 s, then the crossed branch, on the 10 ms test grid."""
    other = _crossed_branch(reference)
    switch = int(round(2.0 / (reference.times[1] - reference.times[0])))
    arrays = {}
    for key in ("position", "quaternion", "velocity", "angular_velocity"):
        joined = np.concatenate([getattr(reference, key)[:switch], getattr(other, key)[switch:]])
        arrays[key] = joined[::STRIDE]
    run = dataclasses.replace(reference, times=reference.times[::STRIDE], **arrays)
    # measured on the crossed branch: joint gaps ≤ 2.1e-14 m (a consistent configuration) while
    # its markers are 6.6 to 8.0 m from the reference's configuration at the same crank angle
    assert joint_violations(mech, run)[0].max() < 1e-12
    return run


def test_a_branch_switch_is_not_ok(mech, reference, crossed):
    judged = judge(mech, crossed, reference)
    assert judged.status == "failed"
    assert judged.reason.startswith("at t = 2 s:")
    assert "left the assembly branch (body " in judged.reason
    assert judged.failure_time == pytest.approx(1.99)


def test_a_reference_that_changes_branch_is_not_used_for_the_branch_check(mech, run, crossed):
    judged = judge(mech, run, crossed)
    assert any(note.startswith("assembly branch not checked: the reference's configuration is "
                               "not a function of the driver O") for note in judged.notes)


def test_a_late_run_leaves_the_reference_s_motion_not_its_branch(mech, reference):
    late = _late_by(reference, 250)  # 0.25 s late
    # the crank angle lags by up to 2.2 rad, yet the configuration matches the reference's at
    # every crank angle (distance ≤ 1.4e-14 m, branch bound 0.574 m): a wrong answer, but not a
    # branch switch
    lag = np.abs(output_series(mech, late, "crank_angle")
                 - output_series(mech, reference, "crank_angle")[::STRIDE]).max()
    assert lag > 1.0
    judged = judge(mech, late, reference)
    assert judged.status == "failed"
    assert "left the reference's motion (body " in judged.reason
    assert "assembly branch" not in judged.reason
    relaxed = judge(mech, late, reference, Bounds(trajectory=10.0))
    assert relaxed.status == "ok" and relaxed.notes == []


def test_a_slightly_late_run_is_ok_and_its_error_is_a_matter_of_accuracy(mech, reference):
    # 4 ms late: measured at most 0.086 m from the reference at the same time (1.5 % of the size;
    # bound 0.574 m) and the crank at most 0.043 rad behind (bound 0.1 rad)
    assert judge(mech, _late_by(reference, 4), reference).status == "ok"


def test_a_turned_body_leaves_the_reference_s_motion_within_the_distance_bound(mech, reference):
    # 10 ms late: every marker stays within 0.214 m of the reference's at the same time (3.7 % of
    # the size, bound 0.574 m), but the 2 m crank, turning at up to 11 rad/s, is 0.107 rad
    # behind: the bound's angular counterpart (a turn of 0.1 rad moves a point at the
    # mechanism's size from the axis by 0.1 of the size) catches what the size-scaled distance
    # lets through on a small body
    late = _late_by(reference, 10)
    judged = judge(mech, late, reference)
    assert judged.status == "failed"
    assert "left the reference's motion (body crank is turned " in judged.reason
    assert " m from the reference's configuration" not in judged.reason
    assert judge(mech, late, reference, Bounds(trajectory=0.2)).status == "ok"


def test_the_motion_is_judged_only_where_the_reference_reaches(mech, reference):
    short = dataclasses.replace(reference, **{
        key: getattr(reference, key)[:index_at(reference, 2.0) + 1]
        for key in ("times", "position", "quaternion", "velocity", "angular_velocity")})
    judged = judge(mech, _late_by(reference, 250), short)
    assert judged.status == "failed" and judged.failure_time < 2.0
    assert "motion not compared with the reference after t = 2 s, where the reference ends" \
        in judged.notes


def test_an_energy_blow_up_is_not_ok(mech, reference, run):
    k = index_at(run, 3.0)
    run.velocity[k:] *= 3.0
    run.angular_velocity[k:] *= 3.0
    judged = judge(mech, run, reference)
    assert judged.status == "failed"
    assert judged.reason.startswith("at t = 3 s: energy-balance error")


def test_a_run_growing_a_thousandfold_past_a_bound_is_diverged(mech, reference, run):
    run.position[index_at(run, 1.0):, 2, 0] += 1e3 * 0.0287 * 1.01
    assert judge(mech, run, reference).status == "diverged"


def test_a_run_the_adapter_failed_keeps_its_status_and_gets_a_note(mech, reference, run):
    run.position[index_at(run, 1.0):, 2, 0] += 0.05
    failed = dataclasses.replace(run, status="failed", reason="solver gave up", failure_time=3.0)
    judged = judge(mech, failed, reference)
    assert (judged.status, judged.reason, judged.failure_time) == ("failed", "solver gave up", 3.0)
    assert judged.notes[-1].startswith("the measuring stick: at t = 1 s: joint gap")


def test_without_a_reference_the_branch_is_not_checked(mech, run):
    judged = judge(mech, run, None)
    assert judged.status == "ok"
    assert judged.notes == ["assembly branch and motion not checked: no reference"]


def test_characteristic_length_is_the_largest_distance_between_joint_points(mech):
    # joints O (0, 0) and C (4.647, 3.375) of the four-bar are farthest apart
    assert characteristic_length(mech) == pytest.approx(np.hypot(4.647042827239035,
                                                                 3.374938088024936), rel=1e-12)


def test_bounds_parse_names_and_values():
    assert Bounds.parse("gap=0.01, energy=0.1") == Bounds(gap=0.01, energy=0.1)
    assert Bounds.parse("trajectory=0.2") == Bounds(trajectory=0.2)
    with pytest.raises(ValueError, match="one of gap, orientation, energy, branch, trajectory"):
        Bounds.parse("gaps=0.01")
    with pytest.raises(ValueError, match="energy must be a positive finite number"):
        Bounds.parse("energy=-1")


def test_an_honest_engine_run_is_ok(mech, reference):
    # MuJoCo best at dt 1e-3 for 1 s, measured: gap 8e-8 ℓ, energy 1.2e-6 of the scale, branch
    # distance 3e-7 ℓ: every figure at least 1e4 times below its bound
    case = run_case(get_adapter("mujoco"), mech, "best", 1e-3, 1.0, reference)
    assert case.trajectory.status == "ok" and case.metrics["status"] == "ok"
    assert not any("assembly branch not checked" in note for note in case.metrics["notes"])
