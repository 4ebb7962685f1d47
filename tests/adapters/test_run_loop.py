"""The run loop every adapter shares (adapters/base.py): one validation rule, one failure
semantics, one divergence check, and samples that are states the method carried.

Failures here are injected deterministically (an exception or a NaN at a chosen step), so the
expected failure times are exact step times, not round-off-dependent measurements.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from mbh._adapters import adapter_names, get_adapter
from mbh._adapters.integrators.base import Integrator, StepFailure
from mbh._harness.measure.metrics import violation_series
from mbh._harness.model.scenario import load

DT = 1e-3
#: Ten steps, sampled after every step: a failure in step k keeps the samples 0 … (k − 1)·DT.
T_END = 10 * DT
EVERY_STEP = np.arange(11) * DT
#: The step whose engine call is made to fail (1-based): the last good state is after step 3.
FAILING_STEP = 4
#: A method of each adapter that runs the planar four-bar for ten steps without trouble
#: (Pinocchio's ``default`` fails at its first step on it, by design of that method).
RUNNING_METHOD = {"inhouse": "default", "mujoco": "default", "pybullet": "default",
                  "pinocchio": "rk4", "exudyn": "default"}


@pytest.fixture(scope="module")
def fourbar():
    return load("fourbar")


@pytest.fixture(scope="module")
def built(fourbar):
    """Each adapter with its model of the planar four-bar."""
    return {name: (get_adapter(name), get_adapter(name).build(fourbar)) for name in adapter_names()}


# --- one validation rule ---------------------------------------------------------------------

BAD_TIMES = [
    pytest.param({"dt": 0.0}, "dt", id="dt-zero"),
    pytest.param({"dt": -DT}, "dt", id="dt-negative"),
    pytest.param({"dt": float("nan")}, "dt", id="dt-nan"),
    pytest.param({"t_end": 0.0}, "t_end", id="t_end-zero"),
    pytest.param({"t_end": float("inf")}, "t_end", id="t_end-inf"),
    pytest.param({"t_end": 10.5 * DT}, "t_end", id="t_end-not-a-multiple"),
    pytest.param({"sample_times": [0.0, 2 * DT, DT]}, "sample_times", id="decreasing"),
    pytest.param({"sample_times": [0.0, DT, DT]}, "sample_times", id="repeated"),
    pytest.param({"sample_times": [-DT, 0.0]}, "sample_times", id="negative"),
    pytest.param({"sample_times": [0.0, 2 * T_END]}, "sample_times", id="beyond-t_end"),
    pytest.param({"sample_times": [0.0, 0.5 * DT]}, "sample_times", id="off-the-step-grid"),
    pytest.param({"sample_times": [[0.0]]}, "sample_times", id="two-dimensional"),
    pytest.param({"sample_times": [0.0, float("nan")]}, "sample_times", id="nan"),
]


@pytest.mark.parametrize("name", adapter_names())
@pytest.mark.parametrize("change, argument", BAD_TIMES)
def test_bad_times_raise_one_message_for_every_adapter(built, name, change, argument):
    adapter, model = built[name]
    arguments = {"dt": DT, "t_end": T_END, "sample_times": EVERY_STEP} | change
    with pytest.raises(ValueError, match=rf"^invalid {argument}(\[\d+\]|\.shape)? = .+: must "):
        adapter.simulate(model, "default", arguments["dt"], arguments["t_end"],
                         np.asarray(arguments["sample_times"]))


@pytest.mark.parametrize("method", ["dop853+none", "ida"])
def test_adaptive_methods_take_samples_off_the_step_grid(built, method):
    adapter, model = built["inhouse"]
    times = np.array([0.0, 0.5 * DT, 3.7 * DT, T_END])
    trajectory = adapter.simulate(model, method, DT, T_END, times)
    assert trajectory.status == "ok", trajectory.reason
    np.testing.assert_array_equal(trajectory.times, times)


# --- an exception in the engine is a failed row with the samples before it ------------------


def _raise_on_step(monkeypatch, name):
    """Make the engine's step function raise RuntimeError("injected") in step FAILING_STEP."""
    taken = {"steps": 0}

    def count(steps=1):
        taken["steps"] += steps
        if taken["steps"] >= FAILING_STEP:
            raise RuntimeError("injected")

    if name == "pinocchio":  # steps unchecked between samples: the engine call raises
        from mbh._adapters.pinocchio_adapter.dynamics import ConstrainedProblem
        engine_acceleration = ConstrainedProblem.engine_acceleration
        calls = {"n": 0}

        def failing_acceleration(self, t, q, v):
            calls["n"] += 1  # RK4: four calls a step
            if calls["n"] > 4 * (FAILING_STEP - 1):
                raise RuntimeError("injected")
            return engine_acceleration(self, t, q, v)

        monkeypatch.setattr(ConstrainedProblem, "engine_acceleration", failing_acceleration)
    elif name == "inhouse":
        step = Integrator.step

        def failing_step(self):
            count()
            return step(self)

        monkeypatch.setattr(Integrator, "step", failing_step)
    elif name == "mujoco":
        import mujoco
        mj_step = mujoco.mj_step

        def failing_mj_step(model, data, nstep=1):
            count(nstep)
            mj_step(model, data, nstep)

        monkeypatch.setattr(mujoco, "mj_step", failing_mj_step)
    elif name == "pybullet":
        from mbh._adapters.pybullet_adapter.quiet import pybullet
        step_simulation = pybullet.stepSimulation

        def failing_step_simulation(**kwargs):
            count()
            return step_simulation(**kwargs)

        monkeypatch.setattr(pybullet, "stepSimulation", failing_step_simulation)
    else:  # Exudyn steps inside one call: its pre-step hook (t = the step's end) raises instead
        from mbh._adapters.exudyn_adapter.system import ExudynSystem
        construct = ExudynSystem.__init__

        def failing_system(self, *args, **kwargs):
            construct(self, *args, **kwargs)

            def pre_step(mbs, t):
                if t > (FAILING_STEP - 0.5) * DT:
                    raise RuntimeError("injected")
                return True

            self.mbs.SetPreStepUserFunction(pre_step)

        monkeypatch.setattr(ExudynSystem, "__init__", failing_system)


@pytest.mark.parametrize("name", adapter_names())
def test_engine_exception_keeps_the_samples_before_it(built, monkeypatch, name):
    adapter, model = built[name]
    _raise_on_step(monkeypatch, name)
    # The in-house compiled path runs a whole run in one call, which nothing can interrupt from
    # Python (its own failures come back as status codes, test_compiled_path.py): the exception
    # is injected on its Python path (the default, rk4+baumgarte, with loop=python).
    method = "rk4+baumgarte:loop=python" if name == "inhouse" else RUNNING_METHOD[name]
    trajectory = adapter.simulate(model, method, DT, T_END, EVERY_STEP)
    assert trajectory.status == "failed"
    # Pinocchio's problem words an exception of pin.constraintDynamics as a StepFailure.
    raised = "pin.constraintDynamics raised" if name == "pinocchio" else "RuntimeError"
    assert raised in trajectory.reason and "injected" in trajectory.reason
    np.testing.assert_allclose(trajectory.times, EVERY_STEP[:FAILING_STEP], rtol=0, atol=1e-15)
    assert trajectory.failure_time == pytest.approx((FAILING_STEP - 1) * DT, rel=1e-12)
    assert np.all(np.isfinite(trajectory.position))


def test_partitioning_failure_outside_the_step_is_a_failed_row(built, monkeypatch):
    """``StepFailure`` raised by the re-partition check (between steps, outside ``step()``):
    the check runs before steps 2, 3, …; its fourth call, before step 5, raises."""
    from mbh._adapters.inhouse.formulations.partition import CoordinatePartitioning

    adapter, model = built["inhouse"]
    calls = {"n": 0}

    def failing_check(self, q_full):
        calls["n"] += 1
        if calls["n"] == 4:
            raise StepFailure("injected: constraint Jacobian lost rank")
        return False

    monkeypatch.setattr(CoordinatePartitioning, "needs_repartition", failing_check)
    # The Python path: the compiled one runs its own check inside the compiled loop.
    trajectory = adapter.simulate(model, "rk4+partition:loop=python", DT, T_END, EVERY_STEP)
    assert trajectory.status == "failed"
    assert trajectory.reason.startswith("StepFailure: injected")
    np.testing.assert_allclose(trajectory.times, EVERY_STEP[:5], rtol=0, atol=1e-15)
    assert trajectory.failure_time == pytest.approx(4 * DT, rel=1e-12)


def test_ida_exception_keeps_the_samples_before_it(built, monkeypatch):
    """IDA chooses its own steps: the fourth advance (towards the sample at 3·DT) raises, so the
    samples 0, DT, 2·DT are kept and the last good state is IDA's last step, in [2·DT, 3·DT)."""
    from mbh._adapters.inhouse.formulations.dae import IdaIntegration

    adapter, model = built["inhouse"]
    advance = IdaIntegration.advance_to
    calls = {"n": 0}

    def failing_advance(self, t):
        calls["n"] += 1
        if calls["n"] == 4:
            raise RuntimeError("injected")
        advance(self, t)

    monkeypatch.setattr(IdaIntegration, "advance_to", failing_advance)
    trajectory = adapter.simulate(model, "ida", DT, T_END, EVERY_STEP)
    assert trajectory.status == "failed" and trajectory.reason == "RuntimeError: injected"
    np.testing.assert_allclose(trajectory.times, EVERY_STEP[:3], rtol=0, atol=1e-15)
    assert 2 * DT <= trajectory.failure_time < 3 * DT


def test_failure_before_the_start_has_no_samples(built, monkeypatch):
    adapter, model = built["mujoco"]

    def refused(*args):
        raise RuntimeError("engine refused the model")

    monkeypatch.setattr(adapter, "_start", refused)
    trajectory = adapter.simulate(model, "default", DT, T_END, EVERY_STEP)
    assert (trajectory.status, trajectory.failure_time) == ("failed", 0.0)
    assert trajectory.reason == "RuntimeError: engine refused the model"
    assert trajectory.n_samples == 0


# --- one divergence check: positions, velocities and angular velocities ---------------------

POISON = [
    pytest.param("position", np.nan, "non-finite position", id="nan-position"),
    pytest.param("velocity", np.nan, "non-finite velocity", id="nan-velocity"),
    pytest.param("angular_velocity", np.inf, "non-finite angular velocity", id="inf-omega"),
    # The PyBullet case of "Trust 2": ~1e30 rad/s ended ``ok``.
    pytest.param("angular_velocity", 1e30, "angular velocity 1e+30 rad/s exceeds", id="1e30-omega"),
]


def poison_reads(monkeypatch, adapter, after: float, corrupt) -> None:
    """Make every state the adapter's stepper reads at t > ``after`` pass through ``corrupt``."""
    start = adapter._start

    def poisoned_start(*args):
        stepper = start(*args)
        read = stepper._states
        stepper._states = lambda t: corrupt(read(t)) if t > after else read(t)
        return stepper

    monkeypatch.setattr(adapter, "_start", poisoned_start)


@pytest.mark.parametrize("name", adapter_names())
@pytest.mark.parametrize("field, value, reason", POISON)
def test_a_bad_state_is_diverged_at_the_last_good_time(built, monkeypatch, name, field, value,
                                                       reason):
    """The state read after step FAILING_STEP gets ``value`` in one component of ``field``."""
    adapter, model = built[name]

    def corrupt(states):
        bad = np.array(getattr(states, field), dtype=float)
        bad[0, 2] = value
        return dataclasses.replace(states, **{field: bad})

    poison_reads(monkeypatch, adapter, (FAILING_STEP - 0.5) * DT, corrupt)
    trajectory = adapter.simulate(model, RUNNING_METHOD[name], DT, T_END, EVERY_STEP)
    assert trajectory.status == "diverged"
    assert trajectory.reason.startswith(reason)
    np.testing.assert_allclose(trajectory.times, EVERY_STEP[:FAILING_STEP], rtol=0, atol=1e-15)
    assert trajectory.failure_time == pytest.approx((FAILING_STEP - 1) * DT, rel=1e-12)


def test_divergence_after_the_last_sample_is_caught(built, monkeypatch):
    """The state at t_end is checked even when t_end is not a sample time."""
    adapter, model = built["inhouse"]
    poison_reads(monkeypatch, adapter, T_END - 0.5 * DT, lambda states: dataclasses.replace(
        states, velocity=np.full_like(states.velocity, np.nan)))
    trajectory = adapter.simulate(model, "default", DT, T_END, EVERY_STEP[:6])
    assert trajectory.status == "diverged" and trajectory.n_samples == 6
    assert trajectory.failure_time == pytest.approx(5 * DT, rel=1e-12)


# --- samples are states the method carried ---------------------------------------------------


def test_projected_adaptive_samples_lie_on_the_constraints(fourbar, built, monkeypatch):
    """dop853+direct:rtol=1e-6 over 4 s sampled every 10 ms (86 accepted steps, so most samples
    fall between steps).  Measured largest joint gap of the samples: 1.9e-13 m projected,
    1.43e-6 m from the unprojected dense output; velocity residual 5.0e-15 vs 1.05e-5 m/s."""
    from mbh._adapters.inhouse.stepping.driver import PROJECTED_SAMPLES_NOTE, InhouseStepper

    adapter, model = built["inhouse"]
    times = np.arange(401) * 0.01
    projected = adapter.simulate(model, "dop853+direct:rtol=1e-6", DT, 4.0, times)
    monkeypatch.setattr(InhouseStepper, "_carried", lambda self, t, q, v: (q, v))
    dense = adapter.simulate(model, "dop853+direct:rtol=1e-6", DT, 4.0, times)
    assert projected.status == dense.status == "ok"
    assert PROJECTED_SAMPLES_NOTE in projected.notes
    assert projected.steps == dense.steps  # the reading does not change the integration
    on_manifold = violation_series(fourbar, projected)
    off_manifold = violation_series(fourbar, dense)
    assert np.max(on_manifold["joint_gap_m"]) < 1e-10  # measured 1.9e-13 m
    assert np.max(on_manifold["velocity_m_s"]) < 1e-10  # measured 5.0e-15 m/s
    assert np.max(off_manifold["joint_gap_m"]) > 1e-8  # measured 1.43e-6 m
