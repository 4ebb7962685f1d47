"""The neutral joint equations (mbh._harness.neutral.equations): against the in-house kernels (an
independent implementation), on hand-computed configurations, against finite differences, and
through the metrics (an injected 1 mm gap is reported as 1 mm)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mbh._adapters.inhouse.bodies.constraints import ConstraintSystem, layout_of
from mbh._adapters.inhouse.bodies.kinematics import assemble as inhouse_assemble
from mbh._adapters.inhouse.bodies.states import body_states, coordinates
from mbh._harness.model import scenario
from mbh._harness.neutral.equations import JointEquations
from mbh._harness.measure.metrics import constraint_violations, violation_series
from mbh._harness.references.build import reference_trajectory
from mbh._harness.model.trajectory import BodyStates, Trajectory

SHIPPED = scenario.scenario_names()
# Variants covering every joint type (spatial prismatic; the translational, prismatic and
# cylindrical joints as drivers; an all-revolute spatial four-bar with redundant rows).
VARIANTS = {
    "spatial_prismatic": ("slider_crank", [('type = "translational"', 'type = "prismatic"')]),
    "translational_driver": ("slider_crank", [('driver = "O"', 'driver = "P"')]),
    "prismatic_driver": ("slider_crank_planar", [('driver = "O"', 'driver = "P"')]),
    "cylindrical_driver": ("fourbar_spatial", [('driver = "O"', 'driver = "C"')]),
    "all_revolute": ("fourbar_spatial", [
        ('type = "spherical"', 'type = "revolute"'),
        ('location = [1.0, 1.7320508075688772, 0.0]\n',
         'location = [1.0, 1.7320508075688772, 0.0]\naxis = [0.0, 0.0, 1.0]\n'),
        ('type = "cylindrical"', 'type = "revolute"')]),
}
#: Driver (value, rate) for the in-house assembly: the slider-crank's slider is at its dead centre
#: in the drawing, where a translational driver can neither move away (Newton fails) nor move at a
#: rate (the in-house least-squares start then misses the joint velocity rows by 0.57 m/s); the
#: planar slider can only move towards the crank (its reach ends 0.18 m ahead).
DRIVE = {"translational_driver": (0.0, 0.0), "prismatic_driver": (-0.2, 1.3)}


@pytest.fixture(params=SHIPPED + list(VARIANTS))
def case(request, load_variant):
    if request.param in VARIANTS:
        name, edits = VARIANTS[request.param]
        return request.param, load_variant(name, edits, stem=request.param)
    return request.param, scenario.load(request.param)


def random_states(mech, rng, scale=1.0) -> BodyStates:
    """Random unassembled states; planar ones stay in the x–y plane."""
    nb = len(mech.bodies)
    position, velocity = rng.normal(size=(nb, 3)), rng.normal(size=(nb, 3))
    omega = rng.normal(size=(nb, 3))
    if mech.planar:
        angle = rng.uniform(-np.pi, np.pi, nb)
        quaternion = np.column_stack([np.cos(angle / 2), 0 * angle, 0 * angle, np.sin(angle / 2)])
        position[:, 2] = velocity[:, 2] = 0.0
        omega[:, :2] = 0.0
    else:
        quaternion = Rotation.random(nb, random_state=rng).as_quat(scalar_first=True)
    return BodyStates(scale * position, quaternion, velocity, omega)


def turned(rotation: Rotation, quaternion: np.ndarray) -> np.ndarray:
    """Scalar-first quaternion(s) of ``rotation`` applied (in world axes) after ``quaternion``."""
    return (rotation * Rotation.from_quat(quaternion, scalar_first=True)).as_quat(scalar_first=True)


def inhouse_start(name, mech):
    assembly = inhouse_assemble(mech, *DRIVE.get(name, (0.2, 1.3)))
    return body_states(layout_of(mech), assembly.q, assembly.v)


def rows_with(labels, *words):
    return [i for i, label in enumerate(labels) if any(word in label for word in words)]


# --- against the in-house kernels ----------------------------------------------------------------


def test_both_implementations_vanish_on_assembled_states(case):
    name, mech = case
    start = inhouse_start(name, mech)
    neutral = JointEquations(mech)
    inhouse = ConstraintSystem(mech)
    q, v = coordinates(inhouse.layout, start)
    # The in-house Newton stops below its tolerance 1e-13: measured max 8.0e-14 (prismatic
    # driver), seen alike by both implementations; the neutral rates ≤ 1.5e-14 (m/s, rad/s) at
    # driver rate 1.3.  Bounds: 12× and 66× margin.
    assert np.abs(neutral.residuals(start.position, start.quaternion)).max() <= 1e-12
    assert np.abs(neutral.velocity_residuals(start.position, start.quaternion, start.velocity,
                                             start.angular_velocity)).max() <= 1e-12
    assert np.abs(inhouse.phi(q)[:inhouse.n_joint_equations]).max() <= 1e-12


def test_point_and_line_rows_agree_componentwise_on_random_states(case):
    """Same definitions: the gap P₂ − P₁ (the in-house kernel writes P₁ − P₂) and the distances
    h₁·d, f₁·d from the slide line."""
    _, mech = case
    rng = np.random.default_rng(11)
    neutral, inhouse = JointEquations(mech), ConstraintSystem(mech)
    for _ in range(5):
        states = random_states(mech, rng, scale=3.0)
        q, _ = coordinates(inhouse.layout, states)
        ours = neutral.residuals(states.position, states.quaternion)
        theirs = inhouse.phi(q)
        gaps = rows_with(neutral.labels, ": gap")
        lines = rows_with(neutral.labels, "off axis")
        assert len(gaps) == len(rows_with(inhouse.labels, ": point"))
        # Measured max difference 1.8e-15 m (gaps) and 3.6e-15 m (slide lines) on residuals up to
        # 11.4 m, i.e. ≤ 3e-16 relative; bound 1e-12 relative.
        np.testing.assert_allclose(ours[gaps], -theirs[rows_with(inhouse.labels, ": point")],
                                   rtol=0, atol=1e-12 * max(1.0, np.abs(ours[gaps]).max()))
        their_lines = rows_with(inhouse.labels, "on axis", ": line")
        np.testing.assert_allclose(ours[lines], theirs[their_lines], rtol=0,
                                   atol=1e-12 * max(1.0, np.abs(ours[lines]).max(initial=0.0)))


def test_orientation_rows_agree_to_first_order_near_assembly(case):
    """The in-house orientation rows are direction cosines (a₁·h₂ ≈ angle); the neutral ones are
    angles.  Per joint, the Euclidean norms agree to first order in a small rotation ε."""
    name, mech = case
    start = inhouse_start(name, mech)
    neutral, inhouse = JointEquations(mech), ConstraintSystem(mech)
    rng = np.random.default_rng(5)
    epsilon = 1e-5
    for _ in range(3):
        turn = Rotation.from_rotvec(epsilon * rng.normal(size=(len(mech.bodies), 3)))
        quaternion = turned(turn, start.quaternion)
        if mech.planar:  # stay in the plane: turn about z only
            angle = 2 * np.arctan2(start.quaternion[:, 3], start.quaternion[:, 0])
            angle = angle + epsilon * rng.normal(size=angle.size)
            quaternion = np.column_stack([np.cos(angle / 2), 0 * angle, 0 * angle,
                                          np.sin(angle / 2)])
        moved = BodyStates(start.position, quaternion, start.velocity, start.angular_velocity)
        ours = neutral.residuals(moved.position, moved.quaternion)
        theirs = inhouse.phi(coordinates(inhouse.layout, moved)[0])
        for joint in mech.joints:
            prefix = f"joint {joint.name} ({joint.type}): "
            our_rows = [i for i in rows_with(neutral.labels, prefix) if neutral.units[i] == "rad"]
            their_rows = [i for i in rows_with(inhouse.labels, prefix) if not any(
                word in inhouse.labels[i] for word in (": point", "on axis", ": line"))]
            assert len(our_rows) == len(their_rows)
            if not our_rows:
                continue
            ours_norm = np.linalg.norm(ours[our_rows])
            theirs_norm = np.linalg.norm(theirs[their_rows])
            # Second-order terms: measured |difference| ≤ 3.0e-11 for norms ~1e-5, relative
            # ≤ 2.2e-6 = O(ε); bound 1e-4 relative (45× margin).  A wrong row gives O(1).
            assert abs(ours_norm - theirs_norm) <= 1e-4 * max(ours_norm, theirs_norm) + 1e-14


# --- hand-computed configurations ----------------------------------------------------------------


def reference_states(mech) -> BodyStates:
    nb = len(mech.bodies)
    quaternion = Rotation.from_matrix([b.rotation for b in mech.bodies]).as_quat(scalar_first=True)
    return BodyStates(np.array([b.position for b in mech.bodies]), quaternion,
                      np.zeros((nb, 3)), np.zeros((nb, 3)))


def test_planar_revolute_gap_of_a_3_4_5_triangle():
    mech = scenario.load("fourbar")
    states = reference_states(mech)
    states.position[mech.body_index("coupler")] += [0.3, 0.4, 0.0]
    equations = JointEquations(mech)
    residuals = equations.residuals(states.position, states.quaternion)
    row = {label: value for label, value in zip(equations.labels, residuals)}
    assert row["joint B (revolute): gap x"] == pytest.approx(0.3, abs=1e-15)
    assert row["joint B (revolute): gap y"] == pytest.approx(0.4, abs=1e-15)
    assert row["joint C (revolute): gap x"] == pytest.approx(-0.3, abs=1e-15)
    gaps = equations.group_magnitudes(states.position, states.quaternion)["gap_m"]
    np.testing.assert_allclose(np.sort(gaps), [0, 0, 0.5, 0.5], atol=1e-15)


def test_spatial_revolute_tilted_by_a_known_angle():
    """The rocker turned by 0.1 rad about x through its ground pivot R: R's axis tilts by 0.1."""
    mech = scenario.load("fourbar_spatial")
    states = reference_states(mech)
    index = mech.body_index("rocker")
    pivot = np.array([2.5, 0.0, 0.0])
    turn = Rotation.from_rotvec([0.1, 0.0, 0.0])
    states.position[index] = pivot + turn.apply(states.position[index] - pivot)
    states.quaternion[index] = turned(turn, states.quaternion[index])
    equations = JointEquations(mech)
    residuals = equations.residuals(states.position, states.quaternion)
    row = {label: value for label, value in zip(equations.labels, residuals)}
    # R's normal is x (the loader's choice for a z axis): the tilt is about the normal.
    assert abs(row["joint R (revolute): tilt about normal"]) == pytest.approx(0.1, abs=1e-15)
    assert row["joint R (revolute): tilt about binormal"] == pytest.approx(0.0, abs=1e-15)
    assert max(abs(row[f"joint R (revolute): gap {a}"]) for a in "xyz") <= 1e-15
    tilts = equations.group_magnitudes(states.position, states.quaternion)["orientation_rad"]
    assert tilts.max() == pytest.approx(0.1, abs=1e-15)


SLIDE_ON_ARM = """
kind = "planar"
plane = "xy"
duration = 1.0
gravity = [0.0, -9.81, 0.0]
[[bodies]]
name = "arm"
mass = 1.0
inertia = [0.01, 0.1, 0.1]
position = [0.4975020826390129, 0.04991670832341408, 0.0]
angle_deg = 5.729577951308232
[[bodies]]
name = "block"
mass = 1.0
inertia = [0.01, 0.01, 0.01]
position = [0.9950041652780258, 0.09983341664682815, 0.0]
angle_deg = -5.729577951308232
[[joints]]
name = "O"
type = "revolute"
body1 = "ground"
body2 = "arm"
location = [0.0, 0.0, 0.0]
[[joints]]
name = "P"
type = "prismatic"
body1 = "arm"
body2 = "block"
location = [0.9950041652780258, 0.09983341664682815, 0.0]
axis = [0.9950041652780258, 0.09983341664682815, 0.0]
[initial]
driver = "O"
"""


@pytest.mark.parametrize("turn", [np.pi, -np.pi, 2 * np.pi, np.pi - 0.05, 7.0])
def test_planar_prismatic_between_rotating_bodies_shows_no_false_2pi(write_scenario, turn):
    """Arm at +0.1 rad, block at −0.1 rad in the drawing; the whole mechanism turned rigidly about
    the ground pivot: the bodies' angles fall on both sides of ±π, the joint stays exact."""
    mech = scenario.load(write_scenario("slide_on_arm", SLIDE_ON_ARM))
    states = reference_states(mech)
    rotation = Rotation.from_rotvec([0.0, 0.0, turn])
    position = rotation.apply(states.position)
    quaternion = turned(rotation, states.quaternion)
    equations = JointEquations(mech, with_driver=True, drive=(turn, 0.0))
    residuals = equations.residuals(position, quaternion)
    # Measured ≤ 8.9e-16 for every turn; an unwrapped angle row would show 2π.
    assert np.abs(residuals).max() <= 1e-14
    assert np.abs(equations.residuals(position, -quaternion)).max() <= 1e-14  # q and −q alike


def test_plane_residuals_of_a_tilted_lifted_spinning_body():
    mech = scenario.load("fourbar")
    states = reference_states(mech)
    index = mech.body_index("crank")
    tilt = Rotation.from_rotvec([0.0, 0.2, 0.0])
    states.quaternion[index] = turned(tilt, states.quaternion[index])
    states.position[index, 2] = -0.01
    states.velocity[index, 2] = 0.25
    states.angular_velocity[index] = [3.0, -4.0, 7.0]
    plane = JointEquations.plane_residuals(states.position, states.quaternion, states.velocity,
                                           states.angular_velocity)
    assert plane["out_of_plane_m"][index] == pytest.approx(0.01, abs=1e-17)
    assert plane["tilt_rad"][index] == pytest.approx(0.2, abs=1e-15)
    assert plane["out_of_plane_velocity_m_s"][index] == pytest.approx(0.25, abs=1e-17)
    assert plane["out_of_plane_angular_velocity_rad_s"][index] == pytest.approx(5.0, abs=1e-15)
    others = [i for i in range(len(mech.bodies)) if i != index]
    assert all(np.abs(plane[key][others]).max() == 0.0 for key in plane)


# --- derivatives ---------------------------------------------------------------------------------


def twist_columns(mech):
    return [0, 1, 5] if mech.planar else list(range(6))


def test_jacobian_matches_finite_differences_along_exp_map_perturbations(case):
    _, mech = case
    rng = np.random.default_rng(3)
    equations = JointEquations(mech, with_driver=True, drive=(0.3, 1.7))
    k, h = equations.twist_size, 1e-6
    for _ in range(3):
        states = random_states(mech, rng)
        analytic = equations.jacobian(states.position, states.quaternion)
        numeric = np.zeros_like(analytic)
        for body in range(len(mech.bodies)):
            for c, component in enumerate(twist_columns(mech)):
                twist = np.zeros(6)
                twist[component] = 1.0

                def moved(step, states=states, body=body, twist=twist):
                    position, quaternion = states.position.copy(), states.quaternion.copy()
                    position[body] += step * twist[:3]
                    quaternion[body] = turned(Rotation.from_rotvec(step * twist[3:]),
                                              quaternion[body])
                    return equations.residuals(position, quaternion)
                numeric[:, k * body + c] = (moved(h) - moved(-h)) / (2 * h)
        # Central differences, h = 1e-6: measured max error 3.6e-10 relative to max |J| over every
        # scene and variant (truncation O(h²) + round-off 1e-16/h).  A wrong term gives O(1).
        np.testing.assert_allclose(analytic, numeric, rtol=0, atol=1e-8 * np.abs(analytic).max())


def test_velocity_residuals_are_the_jacobian_times_the_twist(case):
    _, mech = case
    rng = np.random.default_rng(4)
    equations = JointEquations(mech, with_driver=True, drive=(0.3, 1.7))
    for _ in range(3):
        s = random_states(mech, rng)
        twist = np.concatenate([s.velocity, s.angular_velocity], axis=1)[:, twist_columns(mech)]
        expected = equations.jacobian(s.position, s.quaternion) @ twist.ravel() - equations.rates
        actual = equations.velocity_residuals(s.position, s.quaternion, s.velocity,
                                              s.angular_velocity)
        # One gradient code, two contractions: measured ≤ 2.1e-16 relative to max |J ν|.
        np.testing.assert_allclose(actual, expected, rtol=0,
                                   atol=1e-12 * max(1.0, np.abs(expected).max()))


def test_vectorised_evaluation_equals_sample_by_sample(case):
    _, mech = case
    rng = np.random.default_rng(6)
    samples = [random_states(mech, rng) for _ in range(4)]
    stack = {key: np.stack([getattr(s, key) for s in samples])
             for key in ("position", "quaternion", "velocity", "angular_velocity")}
    equations = JointEquations(mech, with_driver=True)
    batch = equations.velocity_residuals(**stack)
    for index, s in enumerate(samples):
        single = equations.velocity_residuals(s.position, s.quaternion, s.velocity,
                                              s.angular_velocity)
        np.testing.assert_allclose(batch[index], single, rtol=0,
                                   atol=1e-13 * max(1.0, np.abs(single).max()))  # measured 0.0


# --- through the metrics -------------------------------------------------------------------------


def shifted(trajectory: Trajectory, body: int, offset) -> Trajectory:
    position = trajectory.position.copy()
    position[:, body] += offset
    return dataclasses.replace(trajectory, position=position)


@pytest.mark.parametrize(("name", "body", "direction"), [
    ("fourbar", "coupler", [0.6, 0.8, 0.0]),
    ("slider_crank", "rod", [0.0, 0.0, 1.0]),
    ("fourbar_spatial", "crank", [0.0, 0.6, -0.8]),
])
def test_an_injected_1_mm_gap_is_reported_as_1_mm(name, body, direction):
    mech = scenario.load(name)
    reference = reference_trajectory(mech)
    injected = shifted(reference, mech.body_index(body), 1e-3 * np.array(direction))
    metrics = constraint_violations(mech, injected)
    # Measured |reported − 1 mm| ≤ 1.3e-14 m (the reference's own gaps, ≤ 3.2e-14 m, add to it);
    # bound 1e-12 m, i.e. 1.000 mm to 1e-9 relative.
    assert metrics["max_joint_gap_m"] == pytest.approx(1e-3, abs=1e-12)
    series = violation_series(mech, injected)["joint_gap_m"]
    assert series.shape == (reference.n_samples,)
    assert np.abs(series - 1e-3).max() <= 1e-12
    assert constraint_violations(mech, reference)["max_joint_gap_m"] <= 1e-12


def test_an_injected_1_mrad_tilt_is_reported_as_1_mrad():
    """The slider turned 1 mrad about world z about its centre (where the U and P points are):
    the translational joint's axis tilts by 1 mrad, no point moves."""
    mech = scenario.load("slider_crank")
    reference = reference_trajectory(mech)
    index = mech.body_index("slider")
    quaternion = reference.quaternion.copy()
    quaternion[:, index] = turned(Rotation.from_rotvec([0.0, 0.0, 1e-3]), quaternion[:, index])
    metrics = constraint_violations(mech, dataclasses.replace(reference, quaternion=quaternion))
    # Measured |reported − 1 mrad| = 2e-19 rad (the reference's own tilt is ≤ 1e-14 rad).
    assert metrics["max_orientation_violation_rad"] == pytest.approx(1e-3, abs=1e-12)
    assert metrics["max_joint_gap_m"] <= 1e-12


def test_a_trajectory_without_samples_has_no_violation_figures():
    mech = scenario.load("fourbar")
    empty = Trajectory.empty(len(mech.bodies), status="failed", reason="crashed at t = 0")
    assert all(np.isnan(value) for value in constraint_violations(mech, empty).values())
    assert all(series.shape == (0,) for series in violation_series(mech, empty).values())


def test_planar_metrics_see_the_plane_and_a_diverged_sample_is_nan():
    mech = scenario.load("fourbar")
    reference = reference_trajectory(mech)
    position = reference.position.copy()
    angular_velocity = reference.angular_velocity.copy()
    position[10, 0, 2] = 2e-3
    angular_velocity[20, 1, :2] = [0.3, 0.4]
    metrics = constraint_violations(mech, dataclasses.replace(
        reference, position=position, angular_velocity=angular_velocity))
    assert metrics["max_out_of_plane_m"] == pytest.approx(2e-3, abs=1e-18)
    assert metrics["max_out_of_plane_angular_velocity_rad_s"] == pytest.approx(0.5, abs=1e-15)
    broken = reference.quaternion.copy()
    broken[-1, 0] = np.nan
    series = violation_series(mech, dataclasses.replace(reference, quaternion=broken))
    assert np.isnan(series["joint_gap_m"][-1]) and np.isfinite(series["joint_gap_m"][:-1]).all()
