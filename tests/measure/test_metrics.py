"""case_metrics on synthetic trajectories with known errors, and the energy stick on the shipped
references and on a scene with a damper and a world torque."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mbh._adapters import get_adapter
from mbh._harness.model import scenario
from mbh._harness.measure.energy import energy_balance, energy_scale
from mbh._harness.measure.metrics import case_metrics
from mbh._harness.references.build import reference_trajectory
from mbh._harness.model.timegrid import EVALUATION_STEP, sample_times
from mbh._harness.model.trajectory import Trajectory

SHIPPED = ("fourbar", "fourbar_spatial", "slider_crank", "slider_crank_planar")
_ARRAYS = ("position", "quaternion", "velocity", "angular_velocity")


def subsample(trajectory: Trajectory, index) -> Trajectory:
    """The samples ``index`` of a trajectory (copies, safe to perturb)."""
    return Trajectory(trajectory.times[index].copy(),
                      *(getattr(trajectory, key)[index].copy() for key in _ARRAYS))


def on_evaluation_grid(mech, reference: Trajectory) -> Trajectory:
    step = round(EVALUATION_STEP / (reference.times[1] - reference.times[0]))
    trajectory = subsample(reference, slice(None, None, step))
    np.testing.assert_allclose(trajectory.times, sample_times(EVALUATION_STEP, mech.duration),
                               rtol=0, atol=1e-12)
    return trajectory


@pytest.mark.parametrize("name", SHIPPED)
def test_energy_stick_error_on_shipped_references_at_the_evaluation_grid(name):
    """The shipped scenes load only through joint torques (exact work), so the figure is the
    reference's own balance: measured 2.4e-12, 2.4e-12, 2.8e-13, 7.2e-12 of the largest kinetic
    energy (fourbar, fourbar_spatial, slider_crank, slider_crank_planar); bound 1e-10."""
    mech = scenario.load(name)
    reference = reference_trajectory(mech)
    metrics = case_metrics(mech, on_evaluation_grid(mech, reference), reference)
    assert metrics["max_energy_error_rel"] <= 1e-10


def _shift_slider(mech, trajectory):
    trajectory.position[137, mech.body_index("slider"), 0] += 1e-3


def _spin_crank(mech, trajectory):
    trajectory.angular_velocity[42, mech.body_index("crank"), 2] += 1e-2


def _turn_crank(mech, trajectory):
    crank = mech.body_index("crank")
    turned = Rotation.from_rotvec([0.0, 0.0, 2e-3]) * Rotation.from_quat(
        trajectory.quaternion[250, crank], scalar_first=True)
    trajectory.quaternion[250, crank] = turned.as_quat(scalar_first=True)


@pytest.mark.parametrize("output, size, inject", [("slider_x", 1e-3, _shift_slider),
                                                  ("crank_rate", 1e-2, _spin_crank),
                                                  ("crank_angle", 2e-3, _turn_crank)])
def test_injected_output_error_is_reported_exactly(output, size, inject):
    """One sample of the reference perturbed in one output: slider x by 1 mm, the crank rate by
    0.01 rad/s, the crank turned by 2 mrad; the other outputs stay at zero error."""
    mech = scenario.load("slider_crank_planar")
    reference = reference_trajectory(mech)
    trajectory = on_evaluation_grid(mech, reference)
    inject(mech, trajectory)
    errors = case_metrics(mech, trajectory, reference)["output_errors"]
    # |(y + δ) − y| is δ to a few ulp of y (|y| < 70): measured deviation ≤ 2.4e-15, bound 1e-13
    assert errors[output] == pytest.approx(size, abs=1e-13)
    assert all(errors[other] == 0.0 for other in errors if other != output), errors


def test_injected_kinetic_energy_is_the_reported_energy_error():
    """The slider's velocity raised by 0.05 m/s at one sample adds m(v·Δv + ½|Δv|²) to T there;
    the reported maximum is that plus the reference's own balance at that sample."""
    mech = scenario.load("slider_crank_planar")
    reference = reference_trajectory(mech)
    trajectory = on_evaluation_grid(mech, reference)
    own = energy_balance(mech, trajectory)
    slider, sample = mech.body_index("slider"), 300
    velocity = trajectory.velocity[sample, slider].copy()
    trajectory.velocity[sample, slider, 0] += 0.05
    injected = mech.bodies[slider].mass * (velocity[0] * 0.05 + 0.5 * 0.05 ** 2)
    reported = case_metrics(mech, trajectory, reference)["max_energy_error_J"]
    assert abs(injected) > 1e4 * np.abs(own).max()
    assert reported == pytest.approx(abs(injected + own[sample]), rel=1e-12)


def test_a_scene_at_rest_has_a_relative_energy_error(load_variant):
    """The four-bar without torque, gravity out of its plane: at rest, largest kinetic energy 0.
    The relative figure uses M·|g|·ℓ instead (no division by zero); without gravity it is None."""
    still = [("value = -1200.0", "value = 0.0")]
    gravity = "gravity = [0.0, -9.81, 0.0]"
    mech = load_variant("fourbar", [*still, (gravity, "gravity = [0.0, 0.0, -9.81]")])
    reference = reference_trajectory(scenario.load("fourbar"))
    trajectory = subsample(reference, np.zeros(11, dtype=int))
    trajectory.times = np.arange(11) * EVALUATION_STEP
    trajectory.velocity[:] = 0.0
    trajectory.angular_velocity[:] = 0.0
    metrics = case_metrics(mech, trajectory, trajectory)
    assert metrics["max_energy_error_J"] == 0.0 and metrics["max_energy_error_rel"] == 0.0
    assert energy_scale(mech, trajectory) > 0.0
    weightless = load_variant("fourbar", [*still, (gravity, "gravity = [0.0, 0.0, 0.0]")],
                              stem="weightless")
    assert case_metrics(weightless, trajectory, trajectory)["max_energy_error_rel"] is None


DAMPED = """
[[forces]]
type = "spring_damper"
name = "damper"
body1 = "rocker"
body2 = "ground"
location1 = [3.5735214136195177, 1.687469044012468, 0.0]
location2 = [5.0, 3.0, 0.0]
stiffness = 2000.0
damping = 200.0
free_length = 1.5

[[forces]]
type = "body_torque"
body = "coupler"
torque = [30.0, -20.0, 400.0]

[initial]"""


@pytest.mark.parametrize("name", ["fourbar", "fourbar_spatial"])
def test_damper_and_world_torque_work_with_the_reference_as_control_variate(name, load_variant):
    """A damper on the rocker and a world torque on the coupler (spatial: integrated power) over
    0.5 s, through a fast passage near 0.46 s.  Reference: RK4 + direct at 1e-4 on the 1 ms grid;
    case: RK4 + direct at 1e-3 (its own balance error ~1e-8).  The case's balance on the 10 ms
    grid against its balance on its own 1 ms samples (quadrature error ~1e-16 there): measured
    5.7e-13 (planar) and 5.8e-11 (spatial) of the largest kinetic energy with the reference as
    control variate, 8.7e-7 and 4.9e-5 without (10 ms samples do not resolve the passage, which
    is close to the end of the run).  Bound 2e-10 (3.4× the larger measurement)."""
    mech = load_variant(name, [("duration = 4.0", "duration = 0.5"), ("[initial]", DAMPED)])
    inhouse = get_adapter("inhouse")
    dense = np.arange(501) * 1e-3
    reference = inhouse.simulate(mech, "rk4+direct:proj_tol=1e-14", 1e-4, 0.5, dense)
    case = inhouse.simulate(mech, "rk4+direct", 1e-3, 0.5, dense)
    assert reference.status == case.status == "ok"
    scale = energy_scale(mech, reference)
    own = energy_balance(mech, case)[::10]
    sampled = subsample(case, slice(None, None, 10))
    with_reference = np.abs(energy_balance(mech, sampled, reference) - own).max() / scale
    assert with_reference <= 2e-10
