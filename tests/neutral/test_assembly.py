"""The neutral assembly and rank analysis (mbh._harness.neutral.assembly, mbh._harness.neutral.mobility) and `mbh check`."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from tests.helpers import variant_text

from mbh._adapters.inhouse.bodies.constraints import layout_of
from mbh._adapters.inhouse.bodies.kinematics import assemble as inhouse_assemble
from mbh._adapters.inhouse.bodies.states import body_states
from mbh._harness import cli
from mbh._harness.model import scenario
from mbh._harness.neutral.assembly import AssemblyError, SingularStartError, assemble
from mbh._harness.neutral.start import initial_state
from mbh._harness.neutral.equations import JointEquations
from mbh._harness.model.mechanism import PrescribedJointRate, PrescribedPointVelocity
from mbh._harness.model.outputs import body_rotations, joint_angle
from mbh._harness.neutral.mobility import CONDITION_LIMIT

SHIPPED = scenario.scenario_names()

@pytest.fixture
def nfourbar(load_variant):
    """The shipped IFToMM N-four-bar (N = 2) with its driver O1 at ``value`` (rad, text)."""
    def load(value: str):
        return load_variant("double_fourbar", [("value = 0.0", f"value = {value}")], "nfourbar")
    return load


def quaternion_distance(a, b):
    """Largest component difference of two quaternion arrays, q and −q alike."""
    return min(np.abs(a - b).max(), np.abs(a + b).max())


@pytest.mark.parametrize("drive", [None, (0.4, 1.5), (-0.3, -2.0)])
@pytest.mark.parametrize("name", SHIPPED)
def test_the_start_is_the_inhouse_start(name, drive):
    mech = scenario.load(name)
    ours = assemble(mech, *(drive or ())).states
    theirs = inhouse_assemble(mech, *(drive or ()))
    theirs = body_states(layout_of(mech), theirs.q, theirs.v)
    # Measured over every shipped scene and drive: positions ≤ 2.3e-14 m, quaternions ≤ 9.7e-15,
    # velocities ≤ 1.6e-14 m/s, angular velocities ≤ 1.2e-14 rad/s (two Newton paths, each to
    # round-off).  Bound 1e-12: ≥ 40× margin.
    assert np.abs(ours.position - theirs.position).max() <= 1e-12
    assert quaternion_distance(ours.quaternion, theirs.quaternion) <= 1e-12
    assert np.abs(ours.velocity - theirs.velocity).max() <= 1e-12
    assert np.abs(ours.angular_velocity - theirs.angular_velocity).max() <= 1e-12


@pytest.mark.parametrize("name", SHIPPED)
def test_the_start_satisfies_the_joints_and_the_driver(name):
    mech = scenario.load(name)
    value, rate = 0.4, 1.5
    assembly = assemble(mech, value, rate)
    s = assembly.states
    equations = JointEquations(mech)
    # Measured: rows ≤ 4.4e-16 (m, rad), rates ≤ 1.8e-15 (m/s, rad/s); bounds 1e-12.
    assert assembly.residual <= 1e-12 and assembly.velocity_residual <= 1e-12
    assert np.abs(equations.residuals(s.position, s.quaternion)).max() <= 1e-12
    assert np.abs(equations.velocity_residuals(s.position, s.quaternion, s.velocity,
                                               s.angular_velocity)).max() <= 1e-12
    driver = mech.joint(mech.initial.driver)
    angle = joint_angle(mech, driver, s.position, body_rotations(s.quaternion))
    assert angle == pytest.approx(value, abs=1e-12)  # mbh._harness.model.outputs' own angle; measured 3.9e-16
    assert assembly.condition < CONDITION_LIMIT and assembly.report.mobility == 1


def test_initial_state_is_the_neutral_start_and_a_copy():
    mech = scenario.load("fourbar_spatial")
    first = initial_state(mech)
    first.position[:] = np.nan
    second = initial_state(mech)
    expected = assemble(mech).states
    assert np.array_equal(second.position, expected.position)
    assert np.array_equal(second.quaternion, expected.quaternion)


def with_prescribed(mech, *conditions, rate=None):
    initial = dataclasses.replace(mech.initial, prescribed=tuple(conditions),
                                  rate=mech.initial.rate if rate is None else rate)
    return dataclasses.replace(mech, initial=initial)


def joint_rate(mech, states, joint):
    rates = JointEquations(mech, coordinates=(joint,)).velocity_residuals(
        states.position, states.quaternion, states.velocity, states.angular_velocity)
    return float(rates[-1])


def test_a_consistent_prescribed_joint_rate_is_accepted_and_an_inconsistent_one_refused():
    mech = scenario.load("fourbar")
    free = assemble(mech, 0.0, 1.5).states
    rocker_rate = joint_rate(mech, free, "R")
    assert abs(rocker_rate) > 0.1
    accepted = assemble(with_prescribed(mech, PrescribedJointRate("R", rocker_rate)), 0.0, 1.5)
    # The same solution with one more consistent row: measured 2.2e-16 rad/s apart.
    assert np.abs(accepted.states.angular_velocity - free.angular_velocity).max() <= 1e-12
    with pytest.raises(AssemblyError) as error:
        assemble(with_prescribed(mech, PrescribedJointRate("R", rocker_rate + 0.5)), 0.0, 1.5)
    message = str(error.value)
    assert "fourbar.toml" in message and "inconsistent initial velocities" in message
    assert "initial.velocities[0]: rate of joint R" in message


def test_a_rate_prescribed_for_a_spherical_joint_is_refused_naming_the_field():
    mech = scenario.load("fourbar_spatial")
    with pytest.raises(AssemblyError) as error:
        assemble(with_prescribed(mech, PrescribedJointRate("B", 1.0)))
    assert "fourbar_spatial.toml: initial.velocities[0]: spherical joint 'B'" in str(error.value)


def test_a_prescribed_point_velocity_is_checked(nfourbar):
    """The first crank's tip starts at 1 m/s along +x (the benchmark's start): driver rate −1."""
    mech = nfourbar("0.0")
    tip = np.array([0.5, 0.0, 0.0])  # crank1's local x runs up the bar
    good = assemble(with_prescribed(mech, PrescribedPointVelocity("crank1", tip, np.array(
        [1.0, 0.0, 0.0]), (0, 1))))
    index = mech.body_index("crank1")
    s = good.states
    arm = body_rotations(s.quaternion)[index] @ tip
    velocity = s.velocity[index] + np.cross(s.angular_velocity[index], arm)
    np.testing.assert_allclose(velocity, [1.0, 0.0, 0.0], rtol=0, atol=1e-12)  # measured 4.4e-16
    with pytest.raises(AssemblyError) as error:
        assemble(with_prescribed(mech, PrescribedPointVelocity("crank1", tip, np.array(
            [1.0, 0.3, 0.0]), (0, 1))))
    message = str(error.value)
    assert "nfourbar.toml" in message
    assert "initial.velocities[0]: velocity y of body crank1" in message
    assert "missed by -0.3" in message


def test_the_flattened_nfourbar_start_is_refused_as_singular(nfourbar):
    with pytest.raises(SingularStartError) as error:
        assemble(nfourbar("-1.5707963267948966"))
    message = str(error.value)
    assert "nfourbar.toml" in message and "singular configuration at driver O1 = -1.5708" in message
    assert "condition" in message and "initial.guess" in message
    # Newton stops within round-off of the flat position, so which symptom fires depends on the
    # CPU's round-off: a QR pivot under RANK_TOLERANCE (rank 13 of 14, mobility 2: measured on an
    # AMD EPYC, where the remaining rows then have condition 9.1e3) or a full rank with
    # [independent rows; driver row] at condition 2.8e16 (measured on the CI machine).
    report = error.value.report
    assert report.singular
    assert report.mobility == 2 or report.condition > CONDITION_LIMIT


def test_the_upright_nfourbar_assembles_with_mobility_one(nfourbar):
    assembly = assemble(nfourbar("0.0"))
    report = assembly.report
    assert (report.mobility, report.grubler_mobility, report.rank) == (1, 1, 14)
    assert report.redundant_labels == () and report.n_coordinates == 15
    assert report.condition < 100  # measured 9.17


def test_a_start_near_the_flattened_position_is_accepted_until_the_limit(nfourbar):
    """Condition ≈ 9/δ at δ rad from the flattened position (measured 9.0e3 at 1e-3, 9.0e5 at
    1e-5): δ = 1e-3 is accepted, δ = 1e-6 refused."""
    assert assemble(nfourbar(repr(-np.pi / 2 + 1e-3))).condition == pytest.approx(9.0e3, rel=0.01)
    with pytest.raises(SingularStartError):
        assemble(nfourbar(repr(-np.pi / 2 + 1e-6)))


def test_a_link_too_short_to_close_the_loop_is_reported(load_variant):
    mech = load_variant("fourbar", [
        ('location = [2.5, 0.0, 0.0]',
         'location = [4.110282120429277, 2.531203566018702, 0.0]\nlocation2 = [2.5, 0.0, 0.0]')],
        stem="fourbar_short_rocker")
    with pytest.raises(AssemblyError) as error:
        assemble(mech)
    message = str(error.value)
    assert "fourbar_short_rocker.toml" in message and "cannot be assembled with driver O" in message
    assert "max |residual|" in message and "in row 'joint" in message


ALL_REVOLUTE = [
    ('type = "spherical"', 'type = "revolute"'),
    ('location = [1.0, 1.7320508075688772, 0.0]\n',
     'location = [1.0, 1.7320508075688772, 0.0]\naxis = [0.0, 0.0, 1.0]\n'),
    ('type = "cylindrical"', 'type = "revolute"'),
]


def test_the_all_revolute_spatial_fourbar_has_three_redundant_rows(load_variant):
    report = assemble(load_variant("fourbar_spatial", ALL_REVOLUTE, stem="all_revolute")).report
    assert (report.grubler_mobility, report.mobility) == (-2, 1)
    assert (report.n_equations, report.rank, report.n_coordinates) == (20, 17, 18)
    assert len(report.redundant_labels) == 3
    assert all(label.startswith("joint ") for label in report.redundant_labels)


# --- `mbh check` ---------------------------------------------------------------------------------


def check_json(capsys, *argv):
    status = cli.main(["check", *argv, "--json"])
    return status, json.loads(capsys.readouterr().out)


def test_check_all_reports_mobility_one_and_no_redundancy(capsys):
    status, rows = check_json(capsys, "--all")
    assert status == 0
    assert [row["scenario"] for row in rows] == SHIPPED
    # Grübler 0, one redundant row: tests/references/test_bricard.py
    overconstrained = {"bricard": (1, 0, 1)}
    for row in rows:
        assert (row["mobility"], row["grubler_mobility"], row["redundant_equations"]) \
            == overconstrained.get(row["scenario"], (1, 1, 0))
        assert row["assembly_residual"] <= 1e-12 and "warning" not in row
        assert row["n_coordinates"] == row["n_bodies"] * (3 if row["kind"] == "planar" else 6)


def test_check_refuses_the_singular_start_with_a_warning(capsys, write_scenario):
    text = variant_text("double_fourbar", [("value = 0.0", "value = -1.5707963267948966")])
    path = write_scenario("nfourbar_flat", text)
    status, rows = check_json(capsys, str(path))
    assert status == 1
    assert "singular configuration" in rows[0]["error"]
    assert "singular configuration" in rows[0]["warning"]
    status = cli.main(["check", str(path)])
    captured = capsys.readouterr()
    assert status == 1 and "mbh: warning: nfourbar_flat: singular configuration" in captured.err
