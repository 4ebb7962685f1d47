"""The energy stick against closed-form motions (mbh._harness.measure.energy).

Each test builds a small Mechanism and a Trajectory from an exact solution, so the balance
e(t) = T + V − W − E₀ the stick reports is its own error.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.special import ellipj, ellipk

from mbh._harness.measure.energy import (QUADRATURE_DEGREE, cumulative_quadrature, energy_balance,
                            energy_scale, interval_work, kinetic_energy, state_arrays)
from mbh._harness.model.mechanism import (GROUND, Body, BodyForce, BodyTorque, InitialState, Joint,
                                          Mechanism, SpringDamper)
from mbh._harness.model.trajectory import Trajectory

G = np.array([0.0, -9.81, 0.0])
STEP = 0.01  # the evaluation grid step (mbh._harness.model.timegrid.EVALUATION_STEP)


def mechanism(bodies, forces=(), gravity=G, kind="spatial", joints=()) -> Mechanism:
    return Mechanism(name="closed_form", kind=kind, bodies=tuple(bodies), joints=tuple(joints),
                     forces=tuple(forces), gravity=np.asarray(gravity, dtype=float),
                     initial=InitialState(driver="", value=0.0, rate=0.0), duration=1.0,
                     outputs=())


def body(name="b", mass=2.0, inertia=(0.3, 0.5, 0.7), position=(0.0, 0.0, 0.0)) -> Body:
    return Body(name, mass, np.diag(inertia), np.asarray(position, dtype=float), np.eye(3))


def trajectory(times, position, rotation, velocity, angular_velocity) -> Trajectory:
    """One-body trajectory from arrays (n, 3), rotations (n, 3, 3)."""
    quaternion = Rotation.from_matrix(rotation).as_quat(scalar_first=True)
    return Trajectory(np.asarray(times), position[:, None], quaternion[:, None],
                      velocity[:, None], angular_velocity[:, None])


def about_z(angle) -> np.ndarray:
    return Rotation.from_rotvec(np.outer(angle, [0.0, 0.0, 1.0])).as_matrix()


def relative_error(mech, traj) -> float:
    """max |e| over the samples / the largest kinetic energy."""
    return float(np.abs(energy_balance(mech, traj)).max() / energy_scale(mech, traj))


def test_free_fall_with_a_point_force_balances_to_round_off():
    """p = p₀ + v₀t + ½(g + F/m)t², spinning freely about a principal axis: the force's work
    F·Δp is exact.  Measured 4.7e-16 of the largest kinetic energy (bound 1e-13, round-off)."""
    force = BodyForce("b", np.array([3.0, 1.0, -2.0]), np.zeros(3))
    mech = mechanism([body()], [force])
    t = np.arange(0.0, 2.0 + STEP / 2, STEP)[:, None]
    v0 = np.array([1.0, 4.0, 0.5])
    accel = G + force.force / 2.0
    traj = trajectory(t[:, 0], v0 * t + 0.5 * accel * t ** 2, about_z(3.0 * t[:, 0]),
                      v0 + accel * t, np.tile([0.0, 0.0, 3.0], (t.size, 1)))
    assert relative_error(mech, traj) <= 1e-13


def _spring_mass(times, damping=0.4):
    """A 2 kg mass on a spring-damper (k = 200 N/m, free length 1 m) to the origin, moving along
    x: x = 1 + e^(−γt)(0.2 cos ω_d t), γ = c/2m, ω_d = √(k/m − γ²) (about 10 rad/s)."""
    mass, k, length = 2.0, 200.0, 1.0
    spring = SpringDamper("s", GROUND, "b", np.zeros(3), np.zeros(3), k, damping, length)
    mech = mechanism([body(mass=mass, position=(1.2, 0.0, 0.0))], [spring], gravity=np.zeros(3))
    gamma = damping / (2 * mass)
    omega = np.sqrt(k / mass - gamma ** 2)
    decay = np.exp(-gamma * times)
    x = length + 0.2 * decay * np.cos(omega * times)
    rate = -0.2 * decay * (gamma * np.cos(omega * times) + omega * np.sin(omega * times))
    zero = np.zeros_like(times)
    traj = trajectory(times, np.stack([x, zero, zero], 1),
                      np.broadcast_to(np.eye(3), (times.size, 3, 3)),
                      np.stack([rate, zero, zero], 1), np.zeros((times.size, 3)))
    return mech, traj


def test_damped_spring_mass_dissipation_at_the_evaluation_grid():
    """Damper work −c∫ẋ² by the degree-9 spline quadrature over 4 s.  Measured relative to the
    largest kinetic energy: 2.3e-6 at h = 40 ms, 4.4e-10 at 20 ms, 4.2e-13 at 10 ms (power at
    20 rad/s, hω = 0.2), 2.3e-15 at 5 ms (round-off): slopes 12.3 and 10.1, the quadrature's
    order 10.  Bounds: 5e-12 at 10 ms (12× the measurement), slopes ≥ 8."""
    errors = [relative_error(*_spring_mass(np.arange(0.0, 4.0 + h / 2, h)))
              for h in (0.04, 0.02, STEP)]
    assert errors[-1] <= 5e-12
    slopes = np.diff(np.log(errors)) / np.log(0.5)
    assert np.all(slopes >= 8.0), errors


def test_damped_spring_mass_at_times_off_any_grid():
    """Irregular sample times (spacing 5–15 ms, seeded): measured 6.5e-14 relative to the
    largest kinetic energy (bound 1e-12)."""
    steps = np.random.default_rng(3).uniform(0.005, 0.015, 400)
    times = np.concatenate([[0.0], np.cumsum(steps)])
    assert relative_error(*_spring_mass(times)) <= 1e-12


def test_trapezoid_rule_is_what_a_two_state_interval_gets():
    """interval_work keeps the trapezoidal rule for dampers (only two states at hand): over one
    10 ms interval of the spring–mass it equals ½(P₀ + P₁)h exactly."""
    mech, traj = _spring_mass(np.array([0.3, 0.3 + STEP]))
    state = state_arrays(traj)
    start, end = ({key: value[i] for key, value in state.items()} for i in (0, 1))
    power = -0.4 * traj.velocity[:, 0, 0] ** 2
    assert float(interval_work(mech, start, end, STEP)) == pytest.approx(
        0.5 * power.sum() * STEP, rel=1e-14)


def test_large_amplitude_pendulum_conserves_energy():
    """A bar on a pivot released at rest from 150°: sin(θ/2) = k sn(K − ω₀t, k) (Jacobi), exact
    for any amplitude.  Measured 6.5e-16 of the largest kinetic energy (bound 1e-13)."""
    mass, arm, izz = 3.0, 0.8, 0.05
    mech = mechanism([body(mass=mass, inertia=(0.01, izz, izz), position=(0.0, -arm, 0.0))],
                     kind="planar")
    omega0 = np.sqrt(mass * 9.81 * arm / (mass * arm ** 2 + izz))
    k = np.sin(np.radians(150.0) / 2)
    t = np.arange(0.0, 3.0 + STEP / 2, STEP)
    sn, cn, dn, _ = ellipj(ellipk(k ** 2) - omega0 * t, k ** 2)
    theta = 2 * np.arcsin(k * sn)
    rate = -2 * k * omega0 * cn * dn / np.cos(theta / 2)
    zero = np.zeros_like(t)
    traj = trajectory(t, arm * np.stack([np.sin(theta), -np.cos(theta), zero], 1), about_z(theta),
                      arm * rate[:, None] * np.stack([np.cos(theta), np.sin(theta), zero], 1),
                      np.stack([zero, zero, rate], 1))
    assert relative_error(mech, traj) <= 1e-13


def test_world_torque_on_a_planar_body_is_exact_over_many_turns():
    """φ = ω₀t + ½(τ_z/I)t² through 22 turns (0.3 to 1.1 rad per sample, unwrapped); the
    torque's x component does no work in the plane.  Measured 6.4e-16 of the largest kinetic
    energy (bound 1e-13)."""
    izz = 0.7
    torque = BodyTorque("b", np.array([5.0, 0.0, 28.0]))
    mech = mechanism([body()], [torque], gravity=np.zeros(3), kind="planar")
    t = np.arange(0.0, 2.0 + STEP / 2, STEP)
    phi = 30.0 * t + 0.5 * torque.torque[2] / izz * t ** 2
    zero = np.zeros((t.size, 3))
    rate = np.stack([t * 0, t * 0, 30.0 + torque.torque[2] / izz * t], 1)
    traj = trajectory(t, zero, about_z(phi), zero, rate)
    assert phi[-1] / (2 * np.pi) > 22
    assert relative_error(mech, traj) <= 1e-13


def test_world_torque_on_a_spatial_body_uses_its_full_power():
    """Isotropic inertia I: ω = ω₀ + τt/I (Euler's equations lose the gyroscopic term), with ω₀
    not along τ, so the body's axis of rotation turns; T = ½I|ω|², power τ·ω.  Measured 7.7e-16
    of the largest kinetic energy (bound 1e-13); counting only τ_z (the planar rule) is 0.59 off
    (bound: above 1e-3)."""
    inertia = 0.4
    torque = BodyTorque("b", np.array([0.3, -0.2, 0.5]))
    mech = mechanism([body(inertia=(inertia,) * 3)], [torque], gravity=np.zeros(3))
    t = np.arange(0.0, 2.0 + STEP / 2, STEP)
    omega = np.array([2.0, 1.0, -1.0]) + np.outer(t, torque.torque) / inertia
    rotation = Rotation.from_rotvec(np.cumsum(omega, 0) * STEP).as_matrix()  # T is isotropic
    zero = np.zeros((t.size, 3))
    traj = trajectory(t, zero, rotation, zero, omega)
    assert relative_error(mech, traj) <= 1e-13
    planar = mechanism([body(inertia=(inertia,) * 3)], [torque], gravity=np.zeros(3), kind="planar")
    assert relative_error(planar, traj) > 1e-3


def test_scene_at_rest_has_a_static_energy_scale():
    """Zero kinetic energy everywhere: the scale is M·|g|·ℓ (ℓ: extent, here pivot to centre
    1 m), the balance is zero; without gravity there is no scale (None), never a division."""
    pivot = Joint("O", "revolute", GROUND, "b", np.zeros(3), np.array([0.0, 1.0, 0.0]),
                  *(np.array([0.0, 0.0, 1.0]),) * 2, *(np.array([1.0, 0.0, 0.0]),) * 2)
    still = body(position=(0.0, -1.0, 0.0))
    mech = mechanism([still], joints=[pivot])
    t = np.arange(0.0, 1.0 + STEP / 2, STEP)
    zero = np.zeros((t.size, 3))
    traj = trajectory(t, zero + still.position, np.broadcast_to(np.eye(3), (t.size, 3, 3)), zero,
                      zero)
    assert energy_scale(mech, traj) == pytest.approx(2.0 * 9.81 * 1.0, rel=1e-15)
    assert np.all(energy_balance(mech, traj) == 0.0)
    assert energy_scale(mechanism([still], joints=[pivot], gravity=np.zeros(3)), traj) is None


def test_quadrature_degree_adapts_to_few_samples():
    """Fewer samples than the spline degree: the degree drops to n − 1 (two samples: the
    trapezoid); a polynomial of that degree integrates exactly (measured to 1e-16)."""
    for n in range(2, QUADRATURE_DEGREE + 2):
        times = np.linspace(0.0, 1.0, n) ** 1.3
        values = np.polyval(np.arange(1.0, n + 1), times)          # degree n − 1
        exact = np.polyval(np.polyint(np.arange(1.0, n + 1)), times)
        np.testing.assert_allclose(cumulative_quadrature(times, values), exact - exact[0],
                                   rtol=0, atol=1e-12 * np.abs(exact).max())
    assert cumulative_quadrature(np.zeros(1), np.ones(1)).tolist() == [0.0]


def test_kinetic_energy_uses_the_inertia_in_world_axes():
    """A body turned 90° about z spinning about world x has the body's y inertia."""
    rotation = about_z(np.array([np.pi / 2]))[:, None]
    energy = kinetic_energy(mechanism([body()]), np.zeros((1, 1, 3)), np.array([[[2.0, 0, 0]]]),
                            rotation)
    assert energy[0] == pytest.approx(0.5 * 0.5 * 4.0, rel=1e-15)
