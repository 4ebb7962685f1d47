"""The compiled loop of the joint-coordinate model (``coords=joint``,
adapters/inhouse/stepping/compiled_joint.py) against the Python loop that steps the same
equations: the same samples, counters, statuses and reasons; which loop ``loop=auto`` takes; and
the refusal of a loop the joint model has not for a method.

Every bound below comes from a measurement stated next to it (2-core machine, 2026-11-29).
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from mbh._adapters import get_adapter
from mbh._adapters.inhouse.stepping.joint_loop import COMPILED_NOTE
from mbh._adapters.inhouse.stepping.joint_stepper import PYTHON_NOTE
from mbh._harness.model import scenario
from mbh._harness.model.timegrid import sample_times
from tests.helpers import bennett_linkage, spring_damper_tree

INHOUSE = get_adapter("inhouse")

#: Scenes (a shipped name or a mechanism drawn by hand), each with its step and run length (s):
#: Bricard (redundant closure, 5 rows of rank 4), the planar and spatial four-bar, the spatial
#: slider-crank, the pendulum (an open chain: no closure), Bennett's 4R linkage (3 redundant
#: rows) and a planar tree with springs and dampers.
SCENES = {"bricard": (1e-2, 1.0), "fourbar": (1e-3, 0.2), "fourbar_spatial": (1e-3, 0.2),
          "slider_crank": (1e-2, 1.0), "simple_pendulum": (1e-2, 1.0),
          "bennett": (1e-2, 0.5), "spring_tree": (1e-2, 0.5)}
DRAWN = {"bennett": bennett_linkage, "spring_tree": spring_damper_tree}

#: Largest |compiled − Python| of the sampled body positions (m, Euler parameters, rad) and
#: velocities relative to the largest entry of the Python run's, over every scene above and
#: rk4, rkn4, ab5 with none and baumgarte: measured 0 (the same operations in the same order on
#: the same compiled right-hand side: the same bits).  Bound 1e-12, room for another CPU or LLVM
#: that vectorises or contracts the loop and the right-hand side differently.
SAME_STEPS_BOUND = 1e-12
#: The same for ``direct``, whose C_θ = Φ_cut,q B and C_θθ̇ are loops in the compiled loop and
#: BLAS on the Python one, so its projections differ in the last bits: measured 3.9e-15
#: (slider_crank rk4+direct), 4.9e-16 – 1.3e-15 on the others.  Bound 1e-12, 250× that: another
#: BLAS's order of summation, amplified over the run as the measured gap was.
DIRECT_BOUND = 1e-12


def mechanism(name: str):
    return DRAWN[name]() if name in DRAWN else scenario.load(name)


def simulate(mech, method: str, dt: float, t_end: float):
    return INHOUSE.simulate(mech, method, dt, t_end, sample_times(dt, t_end))


def relative_gap(compiled, python) -> float:
    """Largest difference of the two runs' sampled positions and velocities, relative to the
    largest entry of the Python run's."""
    scale = max(np.abs(python.position).max(), np.abs(python.velocity).max(), 1e-300)
    return float(max(np.abs(compiled.position - python.position).max(),
                     np.abs(compiled.velocity - python.velocity).max()) / scale)


def loop_counters(run) -> dict:
    """The run's counters but ``kernel_calls``, which only the compiled loop counts (every call
    with ``loop=compiled``)."""
    return {k: v for k, v in run.counters.items() if k != "kernel_calls"}


def both_loops(name: str, method: str):
    mech = mechanism(name)
    dt, t_end = SCENES[name]
    python = simulate(mech, f"{method}:coords=joint,loop=python", dt, t_end)
    compiled = simulate(mech, f"{method}:coords=joint,loop=compiled", dt, t_end)
    assert python.status == compiled.status == "ok", (python.reason, compiled.reason)
    assert PYTHON_NOTE in python.notes and COMPILED_NOTE in compiled.notes
    assert compiled.position.shape == python.position.shape
    return python, compiled


@pytest.mark.parametrize("method", ["rk4+none", "rk4+baumgarte", "rkn4+none", "rkn4+baumgarte",
                                    "ab5+none", "ab5+baumgarte"])
@pytest.mark.parametrize("name", sorted(SCENES))
def test_the_compiled_loop_takes_the_python_loops_steps(name, method):
    python, compiled = both_loops(name, method)
    gap = relative_gap(compiled, python)
    print(f"{name} {method}: relative gap {gap:.3g}")
    assert gap <= SAME_STEPS_BOUND
    assert compiled.steps == python.steps
    assert loop_counters(compiled) == loop_counters(python)


@pytest.mark.parametrize("method", ["rk4+direct", "ab5+direct"])
@pytest.mark.parametrize("name", ["bricard", "fourbar", "slider_crank", "bennett"])
def test_the_compiled_projection_is_the_python_ones_to_round_off(name, method):
    python, compiled = both_loops(name, method)
    gap = relative_gap(compiled, python)
    print(f"{name} {method}: relative gap {gap:.3g}")
    assert gap <= DIRECT_BOUND
    assert compiled.counters["rhs_evals"] == python.counters["rhs_evals"]


@pytest.mark.parametrize("method", ["euler+baumgarte", "heun+none", "rk5+baumgarte",
                                    "rk8+none", "symplectic-euler+baumgarte", "ab1+none",
                                    "ab3+baumgarte"])
def test_every_explicit_method_runs_there(method):
    """The other tableaus and Adams–Bashforth orders, on Bricard (bound and measurement as
    :data:`SAME_STEPS_BOUND`)."""
    python, compiled = both_loops("bricard", method)
    assert relative_gap(compiled, python) <= SAME_STEPS_BOUND
    assert loop_counters(compiled) == loop_counters(python)


@pytest.mark.parametrize("method", ["rk4+baumgarte", "ab5+none"])
def test_a_divergence_is_the_python_loops(method):
    """A divergence limit the pendulum's state passes (|θ̇| reaches ~3 rad/s): the same status,
    reason, failure time and samples."""
    mech, dt, t_end = scenario.load("simple_pendulum"), 1e-2, 1.0
    runs = [simulate(mech, f"{method}:coords=joint,loop={loop},divergence_limit=2", dt, t_end)
            for loop in ("python", "compiled")]
    python, compiled = runs
    assert python.status == compiled.status == "diverged"
    assert compiled.reason == python.reason == "state norm exceeds divergence_limit=2"
    assert compiled.failure_time == python.failure_time and compiled.steps == python.steps
    np.testing.assert_array_equal(compiled.position, python.position)


@pytest.mark.parametrize("method", ["rk4+baumgarte", "ab5+baumgarte"])
def test_a_divergence_the_run_loop_finds_is_the_python_loops(method):
    """Baumgarte's α = β = 1e4 at 1e-2 s on Bricard: the steps blow up, and the run loop's check
    of the body states stops the run at a sample (measured: "velocity 8.11e+96 m/s exceeds
    1e+08" after 3 steps for rk4).  The same status, reason, failure time, steps, samples and
    counters on both loops: the compiled loop integrated on past that sample before the check
    read it (16 right-hand sides against 12 for rk4), and reports its counters kept there."""
    mech = scenario.load("bricard")
    runs = [simulate(mech, f"{method}:coords=joint,loop={loop},auto=0,alpha=1e4,beta=1e4",
                     1e-2, 1.0) for loop in ("python", "compiled")]
    python, compiled = runs
    assert python.status == "diverged" and "exceeds" in python.reason, python.reason
    assert (compiled.status, compiled.reason, compiled.failure_time, compiled.steps,
            loop_counters(compiled)) == (python.status, python.reason, python.failure_time,
                                         python.steps, loop_counters(python))
    np.testing.assert_array_equal(compiled.velocity, python.velocity)


@pytest.mark.parametrize("method", ["rk4+baumgarte", "ab5+baumgarte"])
def test_a_failed_solve_gets_the_python_loops_reason(method):
    """Baumgarte's β = 1e200 on Bricard: β² overflows, γ_θ is not finite at a stage of the first
    step and the solve refuses it (measured: LinAlgError, "Array must not contain infs or
    NaNs.", on both loops).  The compiled loop stops there, and the Python loop, taking the step
    again, words why: the same status, reason, failure time and counters."""
    mech = scenario.load("bricard")
    runs = [simulate(mech, f"{method}:coords=joint,loop={loop},auto=0,alpha=0,beta=1e200",
                     1e-2, 0.1) for loop in ("python", "compiled")]
    python, compiled = runs
    assert python.status == "failed" and python.reason.startswith("LinAlgError"), python.reason
    assert (compiled.status, compiled.reason, compiled.failure_time, loop_counters(compiled)) \
        == (python.status, python.reason, python.failure_time, loop_counters(python))
    assert any(note.startswith("the failing step was taken again on the Python loop")
               for note in compiled.notes), compiled.notes


@pytest.mark.parametrize("method,loop_note", [
    ("rk4+baumgarte:coords=joint", COMPILED_NOTE),
    ("ab2+direct:coords=joint", COMPILED_NOTE),
    ("am2+baumgarte:coords=joint", PYTHON_NOTE),
    ("rk4+partition:coords=joint", PYTHON_NOTE),
    ("abm4+baumgarte:coords=joint", PYTHON_NOTE),
    ("rk4+baumgarte:coords=joint,loop=python", PYTHON_NOTE)])
def test_auto_takes_the_compiled_loop_where_it_runs_the_method(method, loop_note):
    trajectory = simulate(scenario.load("fourbar"), method, 1e-3, 0.005)
    assert trajectory.status == "ok", trajectory.reason
    other = PYTHON_NOTE if loop_note == COMPILED_NOTE else COMPILED_NOTE
    assert loop_note in trajectory.notes and other not in trajectory.notes


@pytest.mark.parametrize("method,why", [
    ("am2+baumgarte", "the compiled joint-coordinate loop runs the explicit one-step methods and "
                      "ab1–ab5, not am2"),
    ("bdf2+none", "the compiled joint-coordinate loop runs the explicit one-step methods and "
                  "ab1–ab5, not bdf2"),
    ("rk4+partition", "the compiled joint-coordinate loop runs none, baumgarte, direct, not "
                      "partition")])
@pytest.mark.parametrize("loop", ["compiled", "generated"])
def test_a_compiled_loop_with_a_method_it_does_not_run_is_refused_by_name(method, why, loop):
    with pytest.raises(ValueError, match=re.escape(
            f"parameter 'loop' of {method!r}: coords=joint has no loop={loop} ({why}); it "
            "takes loop=auto or loop=generated or loop=compiled or loop=python")):
        simulate(scenario.load("fourbar"), f"{method}:coords=joint,loop={loop}", 1e-3, 0.005)
