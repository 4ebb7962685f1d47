"""Lie-group stepping keeps the order of RK4 and RKN4 where rotations do not commute.

The explicit methods step in the exponential chart around the current configuration
(:mod:`mbh._adapters.integrators.nystrom`, "Lie groups"): Runge–Kutta–Munthe-Kaas for Runge–Kutta
tableaus, the chart's second-order equation for RKN4.  Before (plain composition of stage
velocities, the dropped commutator term) the measured slopes were 2.00 (free top, rk4 and rkn4),
2.00/1.99 (spatial slider-crank, rk4/rkn4 + newton-euler) and 2.00 (Pinocchio rk4 with a
spherical joint); the slopes after are written next to each test.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.spatial.transform import Rotation

from mbh._adapters import get_adapter
from mbh._adapters.inhouse.bodies.constraints import layout_of
from mbh._adapters.inhouse.bodies.kinematics import assemble
from mbh._adapters.inhouse.formulations.newton_euler import NewtonEuler
from mbh._adapters.inhouse.bodies.states import body_states
from mbh._adapters.integrators import IntegratorState, make_integrator, so3
from mbh._adapters.pinocchio_adapter.adapter import solver_settings
from mbh._adapters.pinocchio_adapter.dynamics import ConstrainedProblem
from mbh._adapters.pinocchio_adapter.stepping import LieGroupProblem, constrained_problem
from mbh._harness.model import scenario
from mbh._harness.model.mechanism import Body, InitialState, Mechanism
from mbh._harness.references.build import reference_trajectory

FOURTH_ORDER = ["rk4", "rkn4"]


def rotation_error(q_a, q_b) -> float:
    """Angle (rad) of the rotation between two scalar-first quaternions."""
    relative = (Rotation.from_quat(q_a, scalar_first=True).inv()
                * Rotation.from_quat(q_b, scalar_first=True))
    return float(np.linalg.norm(relative.as_rotvec()))


def slope(steps, errors) -> float:
    return float(np.polyfit(np.log(steps), np.log(errors), 1)[0])


def integrate(name, problem, q0, v0, dt, count):
    integrator = make_integrator(name, problem, 0.0, q0, v0, dt)
    for _ in range(count):
        integrator.step()
    assert integrator.status == IntegratorState.RUNNING, integrator.failure_reason
    return integrator.q, integrator.v


# -- the exponential chart of SO(3) ----------------------------------------------------------
@pytest.mark.parametrize("scale", [1e-3, 0.3, 0.49, 0.51, 2.0])
def test_so3_chart_maps_against_scipy_rotations(scale):
    # ω̄ = J(Θ)Θ̇ is the body angular velocity of Exp(Θ(t)) (central difference of scipy's
    # rotations, h = 1e-6: measured ≤ 2.1e-10 rad/s at every scale, round-off of the difference);
    # dexp⁻¹ inverts it to 5e-16 and Θ̈ matches a difference of ω̄ to ≤ 1.4e-8 (h = 1e-4, the
    # difference's own error).  Scales either side of SERIES_BELOW = 0.5 test both branches.
    rng = np.random.default_rng(7)
    theta, rate, acc = (rng.normal(size=(3, 3)) for _ in range(3))
    theta *= scale / np.linalg.norm(theta, axis=1)[:, None]

    def chart(t):
        return theta + t * rate + 0.5 * t * t * acc

    h = 1e-6
    difference = np.array([(Rotation.from_rotvec(chart(-h)[k]).inv()
                            * Rotation.from_rotvec(chart(h)[k])).as_rotvec() / (2 * h)
                           for k in range(3)])
    omega = so3.angular_velocity(theta, rate)
    assert np.abs(omega - difference).max() <= 2e-9
    assert np.abs(so3.chart_rate(theta, omega) - rate).max() <= 1e-13
    h = 1e-4
    omega_dot = (so3.angular_velocity(chart(h), rate + h * acc)
                 - so3.angular_velocity(chart(-h), rate - h * acc)) / (2 * h)
    assert np.abs(so3.chart_acceleration(theta, rate, omega_dot) - acc).max() <= 1e-7


# -- a free asymmetric top (non-commuting rotations) -----------------------------------------
TOP_INERTIA = np.diag([1.0, 2.0, 3.0])  # kg·m², principal axes = body axes
TOP_OMEGA0 = np.array([1.0, 0.1, 2.0])  # rad/s, body axes; near the unstable middle axis
TOP_T_END = 2.0  # s
TOP_STEPS = np.array([25, 50, 100, 200])


def free_top():
    body = Body(name="top", mass=1.0, inertia=TOP_INERTIA, position=np.zeros(3),
                rotation=np.eye(3))
    mech = Mechanism(name="free_top", kind="spatial", bodies=(body,), joints=(), forces=(),
                     gravity=np.zeros(3), initial=InitialState("none", 0.0, 0.0),
                     duration=TOP_T_END, outputs=())
    q0 = np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0])
    return NewtonEuler(mech, q0, 0.01, alpha=0.0, beta=0.0), q0, np.r_[np.zeros(3), TOP_OMEGA0]


def euler_equations(t, y):
    """Quaternion and body angular velocity of the free top: θ̇ = ½ θ ⊗ (0, ω̄), J ω̄̇ = −ω̄ × Jω̄."""
    theta, omega = y[:4], y[4:]
    theta_dot = 0.5 * np.r_[-theta[1:] @ omega, theta[0] * omega + np.cross(theta[1:], omega)]
    return np.r_[theta_dot, np.linalg.solve(TOP_INERTIA, -np.cross(omega, TOP_INERTIA @ omega))]


@pytest.fixture(scope="module")
def top_reference():
    start = np.r_[1.0, 0.0, 0.0, 0.0, TOP_OMEGA0]
    return solve_ivp(euler_equations, (0.0, TOP_T_END), start, method="DOP853", rtol=1e-13,
                     atol=1e-14).y[:, -1]


def invariants(theta, omega):
    """Kinetic energy (J) and world angular momentum (kg·m²/s) of the top."""
    momentum = Rotation.from_quat(theta, scalar_first=True).apply(TOP_INERTIA @ omega)
    return 0.5 * omega @ TOP_INERTIA @ omega, momentum


@pytest.mark.parametrize("name", FOURTH_ORDER)
def test_free_asymmetric_top_keeps_fourth_order(name, top_reference):
    # Errors (rotation angle and ω̄) at 25 … 200 steps over 2 s against DOP853 at rtol 1e-13;
    # measured slopes: rk4 3.98 (pairwise 3.99, 3.96, 3.98), rkn4 4.03 (4.14, 4.00, 3.97);
    # before: 2.00 for both (errors 1.4e-3 … 2.2e-5).
    problem, q0, v0 = free_top()
    errors = []
    for count in TOP_STEPS:
        q, v = integrate(name, problem, q0, v0, TOP_T_END / count, count)
        errors.append(max(rotation_error(top_reference[:4], q[3:]),
                          np.abs(v[3:] - top_reference[4:]).max()))
    assert slope(TOP_T_END / TOP_STEPS, errors) == pytest.approx(4.0, abs=0.3), errors
    # The reference itself conserves energy and world angular momentum (measured 1.2e-14 J,
    # 8.5e-14 kg·m²/s; bound 1e-12, 12× the larger).
    energy0, momentum0 = invariants(np.array([1.0, 0.0, 0.0, 0.0]), TOP_OMEGA0)
    energy, momentum = invariants(top_reference[:4], top_reference[4:])
    assert abs(energy - energy0) <= 1e-12 and np.abs(momentum - momentum0).max() <= 1e-12
    # The method conserves them to its truncation error at 200 steps: measured energy error
    # 1.1e-9 J (rk4) / 2.4e-9 J (rkn4), momentum 5.4e-9 / 3.2e-9 kg·m²/s; bound 10× the larger.
    energy, momentum = invariants(q[3:], v[3:])
    assert abs(energy - energy0) <= 2.4e-8
    assert np.abs(momentum - momentum0).max() <= 5.4e-8


# -- the spatial slider-crank (the rod's rotation axis moves in space) -----------------------
SLIDER_T_END = 1.0  # s
SLIDER_STEPS = np.array([4e-3, 2e-3, 1e-3])  # s


@pytest.fixture(scope="module")
def slider_crank():
    mech = scenario.load("slider_crank")
    return mech, reference_trajectory(mech)


def test_spatial_slider_crank_motion_is_not_planar(slider_crank):
    # The rod's angular-velocity direction over the first second spans space: the second
    # singular value of the unit directions is 0.64 of the first (measured); a planar motion
    # (a fixed axis) gives 0.
    _, reference = slider_crank
    omega = reference.angular_velocity[(reference.times > 0.05) & (reference.times <= 1.0), 1]
    directions = omega / np.linalg.norm(omega, axis=1)[:, None]
    singular = np.linalg.svd(directions, compute_uv=False)
    assert singular[1] >= 0.2 * singular[0]


@pytest.mark.parametrize("name", FOURTH_ORDER)
def test_newton_euler_keeps_fourth_order_on_the_spatial_slider_crank(name, slider_crank):
    # Largest error of every body's CoM position (m), rotation (rad) and angular velocity
    # (rad/s, /10) at t = 1 s against the verified reference (its routes agree to 2.3e-11);
    # dt = 4e-3 … 1e-3.  Measured slopes: rk4 4.01 (errors 1.3e-7 … 5.0e-10), rkn4 4.01;
    # before: 2.00 (rk4) and 1.99 (rkn4), against 3.99 for rk4+none.
    mech, reference = slider_crank
    at = int(np.argmin(np.abs(reference.times - SLIDER_T_END)))
    assembly, layout = assemble(mech), layout_of(mech)
    errors = []
    for dt in SLIDER_STEPS:
        problem = NewtonEuler(mech, assembly.q, dt)
        q, v = integrate(name, problem, *problem.reduce(assembly.q, assembly.v), dt,
                         int(round(SLIDER_T_END / dt)))
        states = body_states(layout, *problem.expand(SLIDER_T_END, q, v))
        errors.append(max(
            max(rotation_error(reference.quaternion[at, b], states.quaternion[b])
                for b in range(len(mech.bodies))),
            np.abs(states.position - reference.position[at]).max(),
            np.abs(states.angular_velocity - reference.angular_velocity[at]).max() / 10))
    assert slope(SLIDER_STEPS, errors) == pytest.approx(4.0, abs=0.3), errors


# -- Pinocchio with a spherical joint in its tree --------------------------------------------
SPHERICAL_CHAIN = """
kind = "spatial"
duration = 1.0
gravity = [0.0, 0.0, -9.81]

[[bodies]]
name = "arm"
mass = 1.0
inertia = [0.01, 0.05, 0.05]
position = [0.25, 0.0, 0.0]

[[bodies]]
name = "bob"
mass = 2.0
inertia = [0.02, 0.03, 0.04]
position = [0.5, 0.0, -0.3]

[[joints]]
name = "O"
type = "revolute"
body1 = "ground"
body2 = "arm"
location = [0.0, 0.0, 0.0]
axis = [0.0, 0.0, 1.0]

[[joints]]
name = "S"
type = "spherical"
body1 = "arm"
body2 = "bob"
location = [0.5, 0.0, 0.0]

[initial]
driver = "O"
value = 0.0
rate = 0.0
"""
# Joint coordinates (O angle; S as a rotation vector from the reference) and rates (rad/s):
# the bob starts tilted and spinning about a skew axis, so its motion is genuinely spatial.
CHAIN_Q0_TANGENT = np.array([0.0, 0.4, -0.3, 0.2])
CHAIN_V0 = np.array([1.5, 2.0, -1.0, 3.0])
CHAIN_T_END = 1.0  # s


@pytest.fixture
def spherical_chain(write_scenario):
    import pinocchio as pin

    adapter = get_adapter("pinocchio")
    model = adapter.build(scenario.load(write_scenario("spherical_chain", SPHERICAL_CHAIN)))
    problem = constrained_problem(model, solver_settings(adapter.method_spec("rk4")[1]))
    q0 = pin.integrate(model.model, pin.neutral(model.model), CHAIN_Q0_TANGENT)
    return pin, model, problem, q0


def test_pinocchio_rk4_keeps_fourth_order_with_a_spherical_joint(spherical_chain):
    # 100 … 800 steps over 1 s against 12800 steps of the same method (whose own error is then
    # ≥ 4000× below the finest case's).  Measured slope 3.94 (pairwise 3.89, 3.95, 3.97; errors
    # 2.9e-5 … 8.0e-9); before (the plain ConstrainedProblem, no dexp⁻¹): 2.00 (3.6e-3 … 5.6e-5).
    # Energy drift at 800 steps (Pinocchio's own mechanical energy; no loss in this scene):
    # measured 2.6e-10 J (before: 8.1e-7 J); bound 10×.
    pin, model, problem, q0 = spherical_chain
    assert isinstance(problem, LieGroupProblem)
    q_ref, v_ref = integrate("rk4", problem, q0, CHAIN_V0, CHAIN_T_END / 12800, 12800)
    steps = np.array([100, 200, 400, 800])
    errors = []
    for count in steps:
        q, v = integrate("rk4", problem, q0, CHAIN_V0, CHAIN_T_END / count, count)
        errors.append(max(np.abs(pin.difference(model.model, q_ref, q)).max(),
                          np.abs(v - v_ref).max()))
    assert slope(CHAIN_T_END / steps, errors) == pytest.approx(4.0, abs=0.3), errors
    data = model.model.createData()
    drift = (pin.computeMechanicalEnergy(model.model, data, q, v)
             - pin.computeMechanicalEnergy(model.model, data, q0, CHAIN_V0))
    assert abs(drift) <= 2.6e-9


def test_pinocchio_refuses_rkn4_on_a_non_commutative_tree(spherical_chain):
    _, _, problem, q0 = spherical_chain
    with pytest.raises(ValueError, match="chart_velocity and chart_acceleration"):
        make_integrator("rkn4", problem, 0.0, q0, CHAIN_V0, 1e-3)


@pytest.mark.parametrize("name", ["fourbar", "fourbar_spatial", "slider_crank",
                                  "slider_crank_planar"])
def test_pinocchio_models_of_the_shipped_scenes_step_plainly(name):
    # Their trees hold only revolute, prismatic and universal joints (R^k or the circle): no
    # dexp⁻¹ needed, and rkn4 stays available.
    adapter = get_adapter("pinocchio")
    model = adapter.build(scenario.load(name))
    problem = constrained_problem(model, solver_settings(adapter.method_spec("rk4")[1]))
    assert type(problem) is ConstrainedProblem
