"""The compiled right-hand sides of the neutral reference routes (``harness/neutral/dynamics_kernels.py``,
issue 14) compute what the numpy measuring stick computes, and the routes built on them reproduce
the shipped references.

Two levels: one state at a time against :mod:`mbh._harness.neutral.equations` and
:mod:`mbh._harness.neutral.dynamics` (every scene, every joint and load type), and whole routes against
the stored route A of ``scenarios/references`` (short spans here, the full runs marked slow).
Bounds are relative to the quantity's size with a floor of 1 (m, rad, m/s², …): the two paths
differ only in the order of floating-point operations, and no bound is below 1e-12 relative.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from mbh._harness.model import scenario
from scipy.spatial.transform import Rotation

from mbh._harness.neutral.assembly import (MAX_ITERATIONS, POLISH_STEPS, POSITION_TOLERANCE,
                                           assemble, newton_positions)
from mbh._harness.references.routes import (FULL_ROUTE_BAUMGARTE, BranchEquations, full_route,
                                  reduced_route)
from mbh._harness.neutral.equations import twist_vector
from mbh._harness.model.mechanism import (GROUND, Body, BodyForce, BodyTorque, InitialState, Joint,
                           JointActuation, Mechanism)
from mbh._harness.neutral.dynamics import (DIFFERENCE_STEP, DIFFERENCE_TURN, KKT_RCOND,
                                      UNIQUENESS_RATIO, IndeterminateAccelerations, accelerations,
                                      gamma, twist_mass_and_forces)
from mbh._harness.neutral.dynamics_kernels import (body_table, branch_pose, full_rates,
                                                   mass_and_forces, mass_spread)
from mbh._harness.neutral.dynamics_kernels import gamma as compiled_gamma
from mbh._harness.references.build import (AGREEMENT_LIMIT, reference_grid, reference_trajectory,
                               route_difference)
from mbh._harness.model.trajectory import BodyStates

#: The scenes whose references are built by the neutral routes.
NEUTRAL_SCENES = ("andrews", "bricard", "double_fourbar", "parallelogram_fourbar", "n_fourbar@4")
#: Every shipped scene: between them every joint type and load type of the scenario files.
ALL_SCENES = (*scenario.scenario_names(), "n_fourbar@4")
#: Reference samples the single-state checks are made at (fractions of the run).
SAMPLE_FRACTIONS = (0.0, 0.17, 0.5, 0.83, 1.0)


def _size(reference: np.ndarray) -> float:
    """The scale a difference is measured against: the largest entry, at least 1."""
    return max(1.0, float(np.abs(reference).max(initial=0.0)))


def _relative(value: np.ndarray, reference: np.ndarray) -> float:
    return float(np.abs(value - reference).max(initial=0.0)) / _size(reference)


def _neutral(mech):
    """``mech`` with the neutral routes on (a no-op for the neutral scenes)."""
    return dataclasses.replace(mech, neutral_routes=True)


def _sampled_states(mech):
    """States along the shipped reference of ``mech`` (consistent and moving), as writable
    copies: the states the reference build passes to the compiled kernels are writable, the
    stored reference's read-only, and numba compiles a kernel again for read-only arguments
    (eleven neutral kernels, ~30 s of a suite's first run, for nothing the product runs)."""
    trajectory = reference_trajectory(mech)
    for fraction in SAMPLE_FRACTIONS:
        k = int(round(fraction * (trajectory.n_samples - 1)))
        yield BodyStates(*(array[k].copy() for array in (
            trajectory.position, trajectory.quaternion, trajectory.velocity,
            trajectory.angular_velocity)))


@pytest.fixture(scope="module", params=ALL_SCENES)
def scene(request):
    mech = scenario.load(request.param)
    return mech, assemble(mech).states


def test_compiled_rows_are_the_joint_equations(scene):
    """Rows, Jacobian and velocity residuals, with the branch rows and with the driver row.
    Measured worst over the ten scenes and five samples each: rows 8.9e-16 (m or rad), Jacobian
    3.3e-16, velocity residuals 4.4e-15 (of 1 m/s); bound 1e-12, the floor for two paths."""
    mech, start = scene
    for with_driver in (False, True):
        numpy_rows = BranchEquations(_neutral(mech), start, with_driver=with_driver)
        compiled = numpy_rows.compiled()
        numpy_rows.drive = compiled.drive = 0.3  # a driver value away from the start's
        for s in _sampled_states(mech):
            assert _relative(compiled.residuals(s.position, s.quaternion),
                             numpy_rows.residuals(s.position, s.quaternion)) <= 1e-12
            assert _relative(compiled.jacobian(s.position, s.quaternion),
                             numpy_rows.jacobian(s.position, s.quaternion)) <= 1e-12
            arguments = (s.position, s.quaternion, s.velocity, s.angular_velocity)
            assert _relative(compiled.velocity_residuals(*arguments),
                             numpy_rows.velocity_residuals(*arguments)) <= 1e-12


def test_compiled_dynamics_are_the_neutral_dynamics(scene):
    """γ, the mass matrix and forces, and the full route's twist rates (index-1 KKT with
    Baumgarte's terms).  Measured worst (relative, floor 1): γ 2.0e-13 (its central difference
    cancels ~3 digits), mass 1.4e-16, forces 1.6e-16, twist rates 7.0e-13 (the KKT solve's
    conditioning); bounds 1e-11 for γ and the rates (14x the worst), 1e-12 for M and Q.  The
    mass matrix's eigenvalue spread is the constant :func:`mass_spread` in every sampled pose."""
    mech, start = scene
    numpy_rows = BranchEquations(_neutral(mech), start)
    table = numpy_rows.compiled().table
    bodies = body_table(mech).arrays()
    for s in _sampled_states(mech):
        arguments = (s.position, s.quaternion, s.velocity, s.angular_velocity)
        assert _relative(compiled_gamma(table.kind, table.bodies, table.vectors, table.rate,
                                        table.combine, *arguments, DIFFERENCE_STEP,
                                        DIFFERENCE_TURN),
                         gamma(numpy_rows, s)) <= 1e-11
        mass, forces = mass_and_forces(*bodies, mech.planar, *arguments)
        numpy_mass, numpy_forces = twist_mass_and_forces(mech, s)
        assert _relative(mass, numpy_mass) <= 1e-12
        assert _relative(forces, numpy_forces) <= 1e-12
        eigenvalues = np.linalg.eigvalsh(numpy_mass)  # measured ≤ 2.2e-16 from the constant
        assert abs(mass_spread(mech) - eigenvalues[0] / eigenvalues[-1]) <= 1e-12
        y = np.concatenate([s.position.ravel(), s.quaternion.ravel(),
                            twist_vector(s.velocity, s.angular_velocity, mech.planar)])
        rates, unique = full_rates(y, *table.arrays(), *bodies, mech.planar,
                                   *FULL_ROUTE_BAUMGARTE, DIFFERENCE_STEP, DIFFERENCE_TURN,
                                   KKT_RCOND, UNIQUENESS_RATIO, 0.0)  # 0: check every state
        expected = accelerations(mech, s, numpy_rows, baumgarte=FULL_ROUTE_BAUMGARTE)
        assert unique
        assert _relative(rates[7 * len(mech.bodies):],
                         twist_vector(expected.linear, expected.angular, mech.planar)) <= 1e-11


def test_every_load_type_is_compiled():
    """The scenes have joint torques and spring-dampers only; a point force, a body torque and a
    prismatic joint's actuation force are added to the spatial slider-crank.  Measured: forces
    1.6e-16 relative (the added loads change them by ≥ 5.7e-3); bound 1e-12."""
    mech = scenario.load("slider_crank")
    loaded = dataclasses.replace(mech, forces=(
        *mech.forces, BodyForce("rod", np.array([1.0, -2.0, 0.5]), np.array([0.1, 0.02, -0.03])),
        BodyTorque("crank", np.array([0.3, 0.0, -0.7])), JointActuation("P", 4.0)))
    for s in _sampled_states(mech):
        _, forces = mass_and_forces(*body_table(loaded).arrays(), loaded.planar, s.position,
                                    s.quaternion, s.velocity, s.angular_velocity)
        _, numpy_forces = twist_mass_and_forces(loaded, s)
        assert _relative(forces, numpy_forces) <= 1e-12
        assert _relative(forces, twist_mass_and_forces(mech, s)[1]) > 1e-3  # the loads count


@pytest.mark.parametrize("name", NEUTRAL_SCENES)
def test_compiled_newton_is_the_assembly_newton(name):
    """The reduced route's pose at θ 0.01 rad (or m) past three reference samples, from the
    sample: :func:`branch_pose` against :func:`mbh._harness.neutral.assembly.newton_positions` on the numpy
    rows.  Measured worst 6.7e-16 (m, and quaternion components); bound 1e-12."""
    mech = scenario.load(name)
    start = assemble(mech).states
    numpy_rows = BranchEquations(mech, start, with_driver=True)
    compiled = numpy_rows.compiled()
    tolerance = POSITION_TOLERANCE * max(1.0, float(np.abs(start.position).max()))
    for s in list(_sampled_states(mech))[1:4]:
        numpy_rows.drive = 0.0
        theta = numpy_rows.residuals(s.position, s.quaternion)[-1] + 0.01
        numpy_rows.drive = compiled.drive = theta
        position, rotation, _, _, converged = newton_positions(
            mech, numpy_rows, tolerance,
            start=(s.position.copy(), Rotation.from_quat(s.quaternion, scalar_first=True)))
        new_position, new_quaternion, _, new_converged = branch_pose(
            *compiled.arrays(), mech.planar, s.position, s.quaternion, tolerance,
            MAX_ITERATIONS, POLISH_STEPS)
        quaternion = rotation.as_quat(scalar_first=True)
        same_sign = np.sign(np.sum(quaternion * new_quaternion, axis=1))[:, None]
        assert converged and new_converged
        assert np.abs(new_position - position).max() <= 1e-12
        assert np.abs(same_sign * new_quaternion - quaternion).max() <= 1e-12


def test_a_bar_free_to_spin_is_refused_by_the_full_route():
    """A slender bar (no moment about its own axis) on a revolute about that axis, beside a ball
    on its own revolute: any spin rate of the bar solves the equations, so the compiled
    uniqueness check refuses the mechanism and the route raises the numpy path's error, which
    names the bar."""
    x, z = np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])
    bar = Body("bar", 1.0, np.diag([0.0, 1.0, 1.0]) / 12.0, np.zeros(3), np.eye(3))
    ball = Body("ball", 1.0, np.eye(3) / 6.0, np.array([0.0, 0.0, 1.0]), np.eye(3))
    joints = (Joint("pivot", "revolute", GROUND, "bar", np.zeros(3), np.zeros(3), x, x, z, z),
              Joint("hub", "revolute", GROUND, "ball", z, np.zeros(3), z, z, x, x))
    mech = Mechanism("spinning-bar", "spatial", (bar, ball), joints, (),
                     np.array([0.0, 0.0, -9.81]), InitialState("pivot", 0.0, 1.0), 0.01, (),
                     content_hash="spinning-bar", neutral_routes=True)
    with pytest.raises(IndeterminateAccelerations, match="'bar'"):
        full_route(mech, np.arange(11) * 1e-3)


def _short(mech, seconds: float):
    """``mech`` over its first ``seconds`` and that span's reference grid."""
    short = dataclasses.replace(mech, duration=min(seconds, mech.duration))
    return short, reference_grid(short)


@pytest.mark.parametrize("name", NEUTRAL_SCENES)
def test_routes_reproduce_the_shipped_reference_over_a_short_span(name):
    """Both routes over the first 0.1 s (andrews: its whole 0.03 s) against the stored route A
    (the same DOP853 steps: the span's start is the full run's).  Measured, largest
    body-position difference: full route 1.3e-13 m (andrews; the others ≤ 1.1e-14 m), reduced
    route 2.7e-13 m; bounds 1e-12 m and 3e-12 m."""
    mech = scenario.load(name)
    short, grid = _short(mech, 0.1)
    stored = reference_trajectory(mech)
    n = grid.size
    assert np.abs(full_route(short, grid).position - stored.position[:n]).max() <= 1e-12
    assert np.abs(reduced_route(short, grid).position - stored.position[:n]).max() <= 3e-12


@pytest.mark.slow
@pytest.mark.parametrize("name", NEUTRAL_SCENES)
def test_full_runs_reproduce_the_shipped_reference(name):
    """The whole run (1 to 14 s per route here).  Measured, new route A against stored route A,
    with the KKT system solved by gelsd or by the symmetric eigendecomposition and with γ's
    difference step changed by 1e-12 relative (which moves only the round-off): 7.5e-15 m
    (bricard) to 7.9e-12 m (double_fourbar, n_fourbar@4); bound 5e-11 m, a tenth of the routes'
    stored agreement.  Route B reproduces itself only to ~2e-10 m (the same 1e-12 change of
    the step moves it by 5.5e-11 m on parallelogram_fourbar, 1.8e-10 m on double_fourbar): its
    θ̈ carries γ's finite-difference round-off times θ̇².  The new routes' agreement, 2.2e-12 to
    3.0e-10 m, stays within the limit."""
    mech = scenario.load(name)
    grid = reference_grid(mech)
    stored = reference_trajectory(mech)
    route_a, route_b = full_route(mech, grid), reduced_route(mech, grid)
    assert np.abs(route_a.position - stored.position).max() <= 5e-11
    assert route_difference(mech, route_a, route_b)["max"] <= AGREEMENT_LIMIT
