"""The hard four-bars: ``parallelogram_fourbar`` (a branch choice at every flattened passage) and
``stiff_fourbar`` (the seed four-bar held by a stiff spring-damper).

Outside checks: for the parallelogram, its one-degree-of-freedom model on the parallelogram branch
(unit bars of 1 kg, crank angle φ from the ground line: T = 2 · ½ (1/3) φ̇² + ½ φ̇²,
V = g (2 · ½ + 1) sin φ, so (5/3) φ̈ = −2 g cos φ, φ(0) = π/3, φ̇(0) = 0); for the stiff four-bar,
the eigenvalues of its reduced one-degree-of-freedom equation θ̈ = f(θ, θ̇) in the crank angle,
linearised at the start by central differences of the neutral model's accelerations
(:mod:`mbh._harness.neutral.dynamics`), with and without the spring.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from mbh._adapters import get_adapter
from mbh._harness.model import scenario
from mbh._harness.neutral.assembly import assemble
from mbh._harness.run.case import run_case
from mbh._harness.measure.energy import (coordinate_work, energy_balance, energy_scale,
                                         kinetic_energy, state_arrays)
from mbh._harness.neutral.dynamics import accelerations
from mbh._harness.model.outputs import output_series
from mbh._harness.references.build import reference_grid, reference_trajectory

GRAVITY = 9.81
#: Largest step (s) on the 0.01 s / k ladder at which in-house rk4+direct stays stable on
#: stiff_fourbar (k = 13), and the next larger one, where it diverges (k = 12); measured by hand.
RK4_STABLE_STEP = 0.01 / 13
RK4_UNSTABLE_STEP = 0.01 / 12


@pytest.fixture(scope="module")
def parallelogram():
    return scenario.load("parallelogram_fourbar")


@pytest.fixture(scope="module")
def stiff():
    return scenario.load("stiff_fourbar")


def coupler_angle(mech, trajectory) -> np.ndarray:
    """The coupler's rotation about z from the drawn (horizontal) coupler, rad, shape (n,)."""
    q = trajectory.quaternion[:, mech.body_index("coupler")]
    return 2.0 * np.arctan2(q[:, 3], q[:, 0])


def flattened_times(times: np.ndarray, height: np.ndarray) -> np.ndarray:
    """Sample times just before each sign change of the tip height, s."""
    return times[np.nonzero(np.sign(height[1:]) != np.sign(height[:-1]))[0]]


def test_parallelogram_reference_passes_every_flattened_position_on_its_branch(parallelogram):
    ref = reference_trajectory(parallelogram)
    # Measured on the reference: |coupler angle| ≤ 8.9e-15 rad, |crank2 − crank1| ≤ 2.7e-15 rad
    # over 10 s; bound 1e-12 rad.  Folding into the anti-parallelogram turns the coupler by
    # ~ 2 φ, order one.
    assert np.abs(coupler_angle(parallelogram, ref)).max() <= 1e-12
    assert np.abs(output_series(parallelogram, ref, "crank2_angle")
                  - output_series(parallelogram, ref, "crank_angle")).max() <= 1e-12
    # Energy is conserved (no damper, no work): measured |T + V − E₀| ≤ 3.1e-12 J over 10 s
    # (energy scale 2g·sin 60° ≈ 17 J); bound 1e-10 J.
    assert np.abs(energy_balance(parallelogram, ref, None)).max() <= 1e-10


def test_parallelogram_passages_match_the_one_dof_model(parallelogram):
    ref = reference_trajectory(parallelogram)
    ratio = 2.0 * GRAVITY / (5.0 / 3.0)
    model = solve_ivp(lambda _t, s: [s[1], -ratio * np.cos(s[0])], (0.0, ref.times[-1]),
                      [np.pi / 3, 0.0], method="DOP853", rtol=1e-13, atol=1e-13,
                      events=lambda _t, s: np.sin(s[0]))
    passages = flattened_times(ref.times, output_series(parallelogram, ref, "tip_y"))
    # Twelve passages in 10 s (0.5378, 1.0757, 2.1514, … s); each crossing lies in the grid
    # interval (1 ms) that the model's event falls in.
    assert passages.size == model.t_events[0].size == 12
    assert np.all((model.t_events[0] - passages >= 0.0) & (model.t_events[0] - passages <= 1e-3))


def test_inhouse_best_stays_on_the_parallelogram_branch(parallelogram):
    ref = reference_trajectory(parallelogram)
    run = get_adapter("inhouse").simulate(parallelogram, "rk4+direct:proj_tol=1e-13", 1e-3,
                                          parallelogram.duration, reference_grid(parallelogram))
    assert run.status == "ok"
    # Measured at Δt = 1e-3 s over the 10 s and twelve passages: |coupler angle| ≤ 2.3e-11 rad,
    # crank angle within 4.0e-11 rad of the reference; bounds 1e-9 rad (≥ 25× margin).  A fold
    # into the anti-parallelogram is off by order one.
    assert np.abs(coupler_angle(parallelogram, run)).max() <= 1e-9
    assert np.abs(output_series(parallelogram, run, "crank_angle")
                  - output_series(parallelogram, ref, "crank_angle")).max() <= 1e-9


def test_bdf4_stops_at_the_first_passage_and_says_why(parallelogram):
    """Multistep methods get no placed passages: bdf4+direct (Newton to its default 1e-10)
    fails at the first flattened position (0.538 s) instead of crossing it inaccurately.
    Measured at dt 1e-3 s: failed at 0.537 s, crank angle within 4.3e-10 rad of the reference
    before it; at the seed's tol=1e-5 it ran through as ``ok``, 1.3e-6 rad off over this 1 s
    (6.3e-6 rad over the hard campaign's 2 s, 1.9e-5 rad there at dt 1e-4 s).  Bound on the
    error before the failure: 1e-8 rad (23×)."""
    reference = reference_trajectory(parallelogram)
    case = run_case(get_adapter("inhouse"), parallelogram, "bdf4+direct", 1e-3, 1.0, reference)
    run = case.trajectory
    assert run.status == "failed"
    assert "singular configuration" in run.reason
    assert 0.52 <= run.failure_time <= 0.538
    assert case.metrics["output_errors"]["crank_angle"] <= 1e-8


def crank_acceleration(mech, theta: float, rate: float) -> float:
    """θ̈ (rad/s²) of the driver's body at driver angle ``theta`` (rad) and rate (rad/s)."""
    states = assemble(mech, theta, rate).states
    body = mech.body_index(mech.joint(mech.initial.driver).body2)
    return float(accelerations(mech, states).angular[body, 2])


def start_linearisation(mech, h: float = 1e-7) -> np.ndarray:
    """Eigenvalues (1/s, shape (2,)) of θ̈ = f(θ, θ̇) linearised at the start (central
    differences with step ``h`` in rad and rad/s)."""
    stiffness = (crank_acceleration(mech, h, 0.0) - crank_acceleration(mech, -h, 0.0)) / (2 * h)
    damping = (crank_acceleration(mech, 0.0, h) - crank_acceleration(mech, 0.0, -h)) / (2 * h)
    return np.linalg.eigvals(np.array([[0.0, 1.0], [stiffness, damping]]))


def test_stiffness_ratio_to_the_slow_mode_is_at_least_a_million(stiff):
    without_spring = dataclasses.replace(
        stiff, forces=tuple(f for f in stiff.forces if not hasattr(f, "stiffness")))
    slow = np.abs(start_linearisation(without_spring)).max()
    fast = start_linearisation(stiff)
    omega = np.abs(fast).max()
    damping_ratio = -fast.real.max() / omega
    # Measured: slow mode ±2.271 s⁻¹ (gravity and torque), fast −1690 ± 2900i s⁻¹
    # (ω_s = 3356 rad/s, ζ = 0.503): stiffness ratio (ω_s / 2.271)² = 2.18e6.
    assert (omega / slow) ** 2 >= 1e6
    assert 0.1 <= damping_ratio <= 1.0


def coarse_reference(mech):
    """Times (s) every 10 ms, the evaluation grid of steps 0.01 s / k, and the reference's crank
    angle there (rad)."""
    ref = reference_trajectory(mech)
    return ref.times[::10], output_series(mech, ref, "crank_angle")[::10]


def test_rk4_step_collapses_on_the_stiff_fourbar(stiff):
    grid, reference_angle = coarse_reference(stiff)
    inhouse = get_adapter("inhouse")
    unstable = inhouse.simulate(stiff, "rk4+direct", RK4_UNSTABLE_STEP, stiff.duration, grid)
    assert unstable.status == "diverged"
    stable = inhouse.simulate(stiff, "rk4+direct", RK4_STABLE_STEP, stiff.duration, grid)
    assert stable.status == "ok"
    error = np.abs(output_series(stiff, stable, "crank_angle") - reference_angle).max()
    # Measured at Δt = 0.01/13 s: 1.2e-7 rad (RK4 at the edge of its stability region barely
    # damps the fast transient; the static deflection is 3.6e-7 rad); bound 3e-7 rad.  The
    # unstable step ends at 6e-2 rad, state norm beyond 1e8.
    assert error <= 3e-7


def test_implicit_euler_is_stable_thirteen_times_above_rk4s_limit(stiff):
    grid, reference_angle = coarse_reference(stiff)
    run = get_adapter("inhouse").simulate(stiff, "bdf1+direct", 0.01, stiff.duration, grid)
    assert run.status == "ok"
    error = np.abs(output_series(stiff, run, "crank_angle") - reference_angle).max()
    # Measured at Δt = 0.01 s (13× RK4's largest stable step): 1.08e-8 rad (implicit Euler damps
    # the fast transient away and lands on the static deflection, −3.6e-7 rad); bound 3e-8 rad.
    assert error <= 3e-8


def test_stiff_fourbar_energy_scale_is_the_work_the_torque_stores(stiff):
    """The spring holds the mechanism: its kinetic energy peaks at 1.94e-6 J while the driving
    torque's work, stored in the spring, reaches 5.01e-4 J (measured).  The stick's energy scale
    is the latter, so relative energy errors compare with the energy that moves."""
    reference = reference_trajectory(stiff)
    state = state_arrays(reference)
    kinetic = kinetic_energy(stiff, state["velocity"], state["angular_velocity"],
                             state["rotation"]).max()
    work = np.abs(coordinate_work(stiff, state, reference.n_samples)).max()
    assert energy_scale(stiff, reference) == work
    assert work >= 100 * kinetic


def test_implicit_euler_at_half_its_step_passes_the_stick(stiff):
    """bdf1+direct at 5e-3 s: energy-balance error 8.7e-7 J (measured), far below 5 % of the
    energy scale (2.5e-5 J) — a scale of kinetic energy alone (9.7e-8 J) failed it.  At 1e-2 s the
    method's own damping of the fast transient costs 5.9e-5 J (12 % of the scale): failed."""
    inhouse = get_adapter("inhouse")
    reference = reference_trajectory(stiff)
    passed = run_case(inhouse, stiff, "bdf1+direct", 5e-3, stiff.duration, reference).trajectory
    assert passed.status == "ok"
    damped = run_case(inhouse, stiff, "bdf1+direct", 1e-2, stiff.duration, reference).trajectory
    assert damped.status == "failed" and "energy-balance error" in damped.reason
