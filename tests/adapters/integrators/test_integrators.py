"""The in-house integrator library: measured convergence orders, failures as data, the Lie-group
``advance`` hook, the registry.

Every tolerance below comes from a measurement (numbers in the comments), with margin.
"""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from mbh._adapters.integrators import (
    IntegratorState,
    SecondOrderSystem,
    integrator_names,
    integrator_params,
    is_adaptive,
    make_integrator,
)
from mbh._adapters.integrators.nystrom import step_rule

T_END = 2.0
Q0 = np.array([1.0])
V0 = np.array([0.5])


class Oscillator(SecondOrderSystem):
    """q̈ = −q; exact solution q = cos t + 0.5 sin t from (Q0, V0)."""

    n = 1

    def acceleration(self, t, q, v):
        return -q

    @staticmethod
    def exact(t):
        return np.array([np.cos(t) + 0.5 * np.sin(t), -np.sin(t) + 0.5 * np.cos(t)])


class DampedPendulum(SecondOrderSystem):
    """q̈ = −sin q − 0.3 q̇: nonlinear and velocity-dependent; reference from a tight DOP853."""

    n = 1

    def acceleration(self, t, q, v):
        return -np.sin(q) - 0.3 * v

    @staticmethod
    def exact(t):
        solution = solve_ivp(lambda s, y: [y[1], -np.sin(y[0]) - 0.3 * y[1]], (0.0, t),
                             np.concatenate([Q0, V0]), method="DOP853", rtol=1e-13, atol=1e-14)
        return solution.y[:, -1]


class CirclePendulum:
    """The damped pendulum on the circle: q = (cos θ, sin θ), v = θ̇ (n = 1, len(q) = 2).

    ``advance`` rotates q by the angle dq; q + dq would not even have the right shape, so a method
    that bypasses ``advance`` fails.
    """

    n = 1

    def __init__(self):
        self.advance_calls = 0

    def acceleration(self, t, q, v):
        return -np.array([q[1]]) - 0.3 * v

    def advance(self, q, dq):
        self.advance_calls += 1
        c, s = np.cos(dq[0]), np.sin(dq[0])
        return np.array([c * q[0] - s * q[1], s * q[0] + c * q[1]])

    def project(self, t, q, v):
        return q, v


FIXED_STEP_ORDERS = [
    ("euler", 1, {}), ("symplectic-euler", 1, {}), ("heun", 2, {}), ("rk4", 4, {}),
    ("rkn4", 4, {}), ("rk5", 5, {}),
    *[(f"ab{k}", k, {}) for k in range(1, 6)],
    *[(f"am{k}", k, {"tol": 1e-13}) for k in range(1, 6)],
    ("abm4", 4, {}),
    *[(f"bdf{p}", p, {"tol": 1e-13}) for p in range(1, 5)],
]
EXPLICIT_ONE_STEP = ["euler", "symplectic-euler", "heun", "rk4", "rkn4", "rk5", "rk8"]
EUCLIDEAN_ONLY = ["ab2", "am2", "abm4", "bdf2", "rk45", "radau", "lsoda"]


def run_steps(integrator, count):
    for _ in range(count):
        integrator.step()
    return integrator


def final_error(name, problem, steps, params):
    integrator = run_steps(make_integrator(name, problem, 0.0, Q0, V0, T_END / steps, **params),
                           steps)
    assert integrator.status == IntegratorState.RUNNING, integrator.failure_reason
    return np.max(np.abs(np.concatenate([integrator.q, integrator.v]) - problem.exact(T_END)))


@pytest.mark.parametrize("problem", [Oscillator(), DampedPendulum()],
                         ids=["oscillator", "damped-pendulum"])
@pytest.mark.parametrize("name, order, params", FIXED_STEP_ORDERS,
                         ids=[case[0] for case in FIXED_STEP_ORDERS])
def test_convergence_order(name, order, params, problem):
    # dt = 0.1 … 0.0125 (20 … 160 steps to t = 2): the measured slopes are within 0.16 of the
    # order (furthest: abm4 3.85, ab5 4.89 on the oscillator; bdf3 2.87, rk5 4.85 on the
    # pendulum).
    steps = np.array([20, 40, 80, 160])
    errors = [final_error(name, problem, count, params) for count in steps]
    slope = np.polyfit(np.log(T_END / steps), np.log(errors), 1)[0]
    assert slope == pytest.approx(order, abs=0.3), f"{name}: slope {slope:.3f}, errors {errors}"


@pytest.mark.parametrize("problem", [Oscillator(), DampedPendulum()],
                         ids=["oscillator", "damped-pendulum"])
def test_rk8_converges_at_order_eight(problem):
    # At FIXED_STEP_ORDERS' steps rk8 is at round-off (≤ 6e-15 from 20 steps on), so it is fitted
    # over 4 … 12 steps to t = 2 (dt 0.5 … 0.17): measured slopes 8.00 (oscillator, errors
    # 5.5e-10 … 8.4e-14) and 8.47 (damped pendulum, 1.9e-9 … 1.8e-13).
    steps = np.array([4, 6, 8, 12])
    errors = [final_error("rk8", problem, count, {}) for count in steps]
    slope = np.polyfit(np.log(T_END / steps), np.log(errors), 1)[0]
    assert slope == pytest.approx(8.0, abs=0.6), f"slope {slope:.3f}, errors {errors}"


@pytest.mark.parametrize("name", EXPLICIT_ONE_STEP)
def test_explicit_methods_integrate_on_the_circle_through_advance(name):
    # The angle θ of the circle run equals the Euclidean run to rounding (measured ≤ 3e-15).
    circle = CirclePendulum()
    theta0 = Q0[0]
    on_circle = run_steps(make_integrator(name, circle, 0.0, [np.cos(theta0), np.sin(theta0)],
                                          V0, 0.05, divergence_limit=1e8), 40)
    euclidean = run_steps(make_integrator(name, DampedPendulum(), 0.0, Q0, V0, 0.05), 40)
    assert circle.advance_calls >= 2 * 40
    assert np.arctan2(on_circle.q[1], on_circle.q[0]) == pytest.approx(euclidean.q[0], abs=1e-12)
    assert on_circle.v == pytest.approx(euclidean.v, abs=1e-12)


@pytest.mark.parametrize("name", EUCLIDEAN_ONLY)
def test_linear_methods_refuse_a_lie_group_configuration(name):
    with pytest.raises(ValueError, match="Euclidean"):
        make_integrator(name, CirclePendulum(), 0.0, [1.0, 0.0], [0.0], 0.01)


class StiffOscillator(SecondOrderSystem):
    n = 1

    def acceleration(self, t, q, v):
        return -1e4 * q


def test_euler_diverges_on_a_stiff_problem_with_its_time():
    # |1 + i h ω| = 10.05 per step with h = 0.1, ω = 100: the norm passes 1e8 in the 7th step.
    integrator = run_steps(make_integrator("euler", StiffOscillator(), 0.0, [1.0], [0.0], 0.1), 20)
    assert integrator.status == IntegratorState.DIVERGED
    assert integrator.failure_time == pytest.approx(0.7)
    assert integrator.t == pytest.approx(0.6)
    assert integrator.n_steps == 6
    assert np.linalg.norm(integrator.v) <= 1e8
    nfev = integrator.nfev
    assert integrator.step() == IntegratorState.DIVERGED
    assert integrator.nfev == nfev


class NaNAfter(SecondOrderSystem):
    n = 1

    def acceleration(self, t, q, v):
        return np.array([np.nan]) if t > 0.25 else -q


def test_a_non_finite_state_is_diverged():
    integrator = run_steps(make_integrator("rk4", NaNAfter(), 0.0, Q0, V0, 0.1), 10)
    assert integrator.status == IntegratorState.DIVERGED
    assert integrator.failure_reason == "non-finite state"
    assert integrator.failure_time == pytest.approx(0.3)


class RaisesAfter(SecondOrderSystem):
    n = 1

    def acceleration(self, t, q, v):
        if t > 0.35:
            raise FloatingPointError("singular mass matrix")
        return -q


@pytest.mark.parametrize("name", ["euler", "rkn4", "ab3", "abm4", "am3", "bdf2", "rk45", "radau"])
def test_an_exception_from_the_problem_is_a_failure_with_its_reason(name):
    integrator = run_steps(make_integrator(name, RaisesAfter(), 0.0, Q0, V0, 0.1), 100)
    assert integrator.status == IntegratorState.FAILED
    assert "singular mass matrix" in integrator.failure_reason
    # The failing step evaluates at t ≥ its start, and no step exceeds 0.22 s here (rk45's
    # largest measured; the others take 0.1): the run stops within one step of t = 0.35.
    assert integrator.t < integrator.failure_time
    assert 0.35 < integrator.failure_time < integrator.t + 0.25
    assert integrator.t < 0.35 + 0.1
    assert integrator.step() == IntegratorState.FAILED


class SquareRootEnd(SecondOrderSystem):
    """q̈ = −1 / (4 q³) from q = 1, q̇ = −1/2: q = √(1 − t), whose rates are infinite at t = 1
    while q stays bounded (no divergence to stop the run first)."""

    n = 1

    def acceleration(self, t, q, v):
        return -0.25 / q ** 3


@pytest.mark.parametrize("name", ["rk45", "dop853", "radau"])
def test_a_collapsing_adaptive_step_stops_the_run_at_once(name):
    integrator = make_integrator(name, SquareRootEnd(), 0.0, [1.0], [-0.5], 1e-3, rtol=1e-10,
                                 atol=1e-12)
    run_steps(integrator, 5000)
    assert integrator.status == IntegratorState.FAILED
    assert "step-size collapse" in integrator.failure_reason
    # The steps shrink with the distance to t = 1 and fall below 1e-5 · dt = 1e-8 s just before
    # it; the run stops there instead of crawling on.
    assert 0.99 < integrator.failure_time < 1.0
    assert integrator.n_steps < 5000


@pytest.mark.parametrize("problem", [DampedPendulum(), NaNAfter(), RaisesAfter()],
                         ids=["running", "non-finite", "raising"])
@pytest.mark.parametrize("name", EXPLICIT_ONE_STEP)
def test_unchecked_steps_are_the_checked_ones_and_replay_a_failure(name, problem):
    # Same rule, same arithmetic: equal to the bit; a failing step is replayed by step().
    checked = run_steps(make_integrator(name, problem, 0.0, Q0, V0, 0.1), 10)
    unchecked = make_integrator(name, problem, 0.0, Q0, V0, 0.1)
    rule = step_rule(type(unchecked), problem, problem.acceleration)
    assert unchecked.steps_unchecked(10, rule) == checked.status
    for key in ("t", "n_steps", "nfev", "failure_reason", "failure_time"):
        assert getattr(unchecked, key) == getattr(checked, key), key
    np.testing.assert_array_equal(unchecked.q, checked.q)
    np.testing.assert_array_equal(unchecked.v, checked.v)


def test_newton_that_cannot_converge_is_a_failure():
    # One iteration cannot reach tol = 1e-12 on the pendulum (first correction ~1e-3).
    integrator = run_steps(make_integrator("bdf2", DampedPendulum(), 0.0, Q0, V0, 0.1,
                                           max_iter=1, tol=1e-12), 5)
    assert integrator.status == IntegratorState.FAILED
    assert "Newton" in integrator.failure_reason
    assert integrator.failure_time == pytest.approx(0.2)  # step 1 is the RK4 start


def test_cost_counters_of_explicit_and_multistep_methods():
    rk4 = run_steps(make_integrator("rk4", Oscillator(), 0.0, Q0, V0, 0.1), 10)
    assert (rk4.nfev, rk4.njev, rk4.nlu, rk4.n_newton, rk4.n_steps) == (40, 0, 0, 0, 10)
    # ab4: 3 RK4 start steps (4 + 1 evaluations), then one evaluation per step.
    ab4 = run_steps(make_integrator("ab4", Oscillator(), 0.0, Q0, V0, 0.1), 10)
    assert ab4.nfev == 3 * 5 + 7
    # abm4 (PECE): two evaluations per step after the start.
    abm4 = run_steps(make_integrator("abm4", Oscillator(), 0.0, Q0, V0, 0.1), 10)
    assert abm4.nfev == 3 * 5 + 7 * 2


def test_bdf_reuses_its_jacobian_on_a_linear_problem():
    # Linear problem: the first Jacobian (2 evaluations + 1 LU) serves every step; measured
    # 2 Newton iterations per step.
    bdf = run_steps(make_integrator("bdf2", Oscillator(), 0.0, Q0, V0, 0.01), 400)
    assert (bdf.njev, bdf.nlu) == (1, 1)
    assert bdf.n_newton == 2 * 399


class VanDerPol(SecondOrderSystem):
    n = 1

    def acceleration(self, t, q, v):
        return 10.0 * (1.0 - q ** 2) * v - q


@pytest.mark.parametrize("name", ["bdf1", "am2"])
def test_jacobian_is_refreshed_when_newton_slows_down(name):
    # Van der Pol, μ = 10, h = 0.01, 2000 steps: measured njev 4 (bdf1), 7 (am2).
    integrator = run_steps(make_integrator(name, VanDerPol(), 0.0, [2.0], [0.0], 0.01), 2000)
    assert integrator.status == IntegratorState.RUNNING
    assert 1 < integrator.njev <= 20
    assert integrator.nlu == integrator.njev


class TwoFrequencies(SecondOrderSystem):
    """q̈ = −diag(1, 4) q; exact (cos t, sin 2t)."""

    n = 2

    def acceleration(self, t, q, v):
        return -np.array([1.0, 4.0]) * q

    @staticmethod
    def exact(t):
        return np.array([np.cos(t), np.sin(2 * t), -np.sin(t), 2 * np.cos(2 * t)])


# Global error at t = 5 over rtol (atol = 1e-3 rtol), measured at rtol = 1e-8:
# rk45 3.2, dop853 1.4, radau 0.03, bdf 102, lsoda 6.4; the bound is about 3× that.
ADAPTIVE_ERROR_FACTOR = [("rk45", 10), ("dop853", 5), ("radau", 1), ("bdf", 300), ("lsoda", 20)]


def adaptive_error(name, rtol):
    integrator = make_integrator(name, TwoFrequencies(), 0.0, [1.0, 0.0], [0.0, 2.0], 1e-3,
                                 rtol=rtol, atol=1e-3 * rtol)
    while integrator.t < 5.0 and integrator.step() == IntegratorState.RUNNING:
        pass
    assert integrator.status == IntegratorState.RUNNING, integrator.failure_reason
    return np.max(np.abs(np.concatenate(integrator.dense(5.0)) - TwoFrequencies.exact(5.0)))


@pytest.mark.parametrize("name, factor", ADAPTIVE_ERROR_FACTOR)
def test_adaptive_solvers_reach_the_requested_tolerance(name, factor):
    # Tightening rtol 100× cut the error by 42× (bdf) to 720× (radau).
    fine = adaptive_error(name, 1e-8)
    assert fine <= factor * 1e-8
    assert fine <= adaptive_error(name, 1e-6) / 10


class UnitCircleOrbit(SecondOrderSystem):
    """q̈ = −q in the plane from (1, 0), (0, 1): the unit circle at unit speed; the projection
    puts q back on the circle and v on its tangent (changes the state every step)."""

    n = 2

    def __init__(self):
        self.projections = 0

    def acceleration(self, t, q, v):
        return -q

    def project(self, t, q, v):
        self.projections += 1
        q = q / np.linalg.norm(q)
        return q, v - (q @ v) * q


@pytest.mark.parametrize("name", ["rk4", "bdf3", "rk45", "bdf"])
def test_projection_runs_after_every_step(name):
    problem = UnitCircleOrbit()
    integrator = make_integrator(name, problem, 0.0, [1.0, 0.0], [0.0, 1.0], 0.01)
    while integrator.t < 1.0 and integrator.step() == IntegratorState.RUNNING:
        pass
    assert problem.projections == integrator.n_steps
    assert np.linalg.norm(integrator.q) == pytest.approx(1.0, abs=1e-14)
    # Phase error at t = 1, measured: rk4 8e-11, bdf3 1.2e-7, rk45 2e-8, bdf 2.8e-4 (scipy BDF
    # restarts at order 1 after every changing projection: 617 steps instead of 27).
    angle = np.arctan2(integrator.q[1], integrator.q[0])
    assert angle == pytest.approx(integrator.t, abs=1e-3)


def test_dense_output_outside_the_last_step_is_refused():
    integrator = make_integrator("dop853", Oscillator(), 0.0, Q0, V0, 0.1)
    integrator.step()
    with pytest.raises(ValueError, match="outside the last step"):
        integrator.dense(integrator.t + 1.0)


def test_unknown_method_lists_the_valid_names():
    with pytest.raises(ValueError,
                       match="valid: euler, symplectic-euler, heun, rk4, rkn4, rk5, rk8, ab1"):
        make_integrator("rk7", Oscillator(), 0.0, Q0, V0, 0.1)


def test_unknown_parameter_is_named():
    with pytest.raises(ValueError, match="no parameter rtol .*valid: divergence_limit"):
        make_integrator("rk4", Oscillator(), 0.0, Q0, V0, 0.1, rtol=1e-3)


@pytest.mark.parametrize("argument, value, match", [
    ("dt", 0.0, "dt must be > 0"), ("v0", [0.0, 1.0], r"v0 must have shape \(1,\)"),
])
def test_bad_arguments_are_named(argument, value, match):
    arguments = {"t0": 0.0, "q0": Q0, "v0": V0, "dt": 0.1, argument: value}
    with pytest.raises(ValueError, match=match):
        make_integrator("heun", Oscillator(), **arguments)


def test_parameter_listing_and_step_kind():
    assert len(integrator_names()) == 27
    assert integrator_params("bdf4") == {"divergence_limit": 1e8, "tol": 1e-10, "max_iter": 10}
    assert integrator_params("am3")["tol"] == 1e-10
    assert integrator_params("rk45") == {"divergence_limit": 1e8, "rtol": 1e-6, "atol": 1e-9,
                                         "max_step": np.inf, "min_step_ratio": 1e-5}
    assert [is_adaptive(name) for name in ("rk4", "bdf4", "lsoda")] == [False, False, True]
