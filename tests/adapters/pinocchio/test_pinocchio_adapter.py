"""The Pinocchio adapter: build, start, faithfulness switches, accuracy and failure reporting.

Tolerances come from measurements on this machine (numbers in the comments, run with
``.venv/bin/python -m pytest tests/adapters/pinocchio/test_pinocchio_adapter.py``), with a
margin of 3–10×.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin
import pytest

from mbh._adapters import get_adapter
from mbh._adapters.base import UnsupportedCase
from mbh._adapters.integrators import make_integrator
from mbh._adapters.pinocchio_adapter.adapter import solver_settings
from mbh._adapters.pinocchio_adapter.dynamics import ConstrainedProblem, pseudo_inverse
from mbh._adapters.pinocchio_adapter.stepping import bare_rule, bare_steps, constrained_problem
from mbh._adapters.pinocchio_adapter.state import joint_state
from mbh._harness.neutral.start import initial_state
from mbh._harness.neutral.dynamics import accelerations, start_accelerations
from mbh._harness.model.mechanism import GROUND, Body, InitialState, Joint, Mechanism
from mbh._harness.model.outputs import output_series
from mbh._harness.model.scenario import load, scenario_names
from tests.helpers import DATA, bennett_linkage, parallel_revolute_fourbar

ADAPTER = get_adapter("pinocchio")

#: Cut joints, the closure model's redundant equations (closure costs: spherical 3, planar
#: revolute 3, spatial revolute 6, slides and universal joints not closable) and number of joint
#: velocities of every shipped scenario.
EXPECTED_TREES = {
    "simple_pendulum": ((), 0, 1),
    "fourbar": (("B",), 1, 3),
    "fourbar_spatial": (("B",), 0, 4),
    "slider_crank": (("A",), 0, 4),
    "slider_crank_planar": (("A",), 1, 3),
    "double_fourbar": (("A1", "A2"), 2, 5),
    "bricard": (("C",), 1, 5),
    "andrews": (("E3", "E4", "E6"), 3, 7),
    "parallelogram_fourbar": (("A",), 1, 3),
    "stiff_fourbar": (("B",), 1, 3),
}


def _run(mech, method, dt, t_end):
    """Simulate ``mech`` sampling every step."""
    model = ADAPTER.build(mech)
    times = np.arange(int(round(t_end / dt)) + 1) * dt
    return ADAPTER.simulate(model, method, dt, t_end, times)


def _closure_gap(mech, trajectory, joint_name):
    """Largest distance (m) between the two points of ``joint_name`` over the samples."""
    joint = mech.joint(joint_name)
    points = []
    for body, point in ((joint.body1, joint.point1), (joint.body2, joint.point2)):
        if body == GROUND:
            points.append(point)
            continue
        index = mech.body_index(body)
        quat = trajectory.quaternion[:, index]
        rotations = np.array([pin.Quaternion(w, x, y, z).toRotationMatrix() for w, x, y, z in quat])
        points.append(trajectory.position[:, index] + rotations @ point)
    return np.max(np.linalg.norm(points[0] - points[1], axis=1))


# --- build -------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", scenario_names())
def test_build_every_shipped_scenario(name):
    model = ADAPTER.build(load(name))
    cut, redundant, nv = EXPECTED_TREES[name]
    assert model.tree.cut_joints == cut
    assert model.tree.redundant_closure_equations == redundant
    assert model.model.nv == nv


@pytest.mark.parametrize("mech, rows, mechanism, closure_model", [
    (bennett_linkage(), 6, 3, 1),             # Grübler −2, mobility 1; two points close a revolute
    (parallel_revolute_fourbar(), 6, 3, 1),   # the tilts of two joints
    (load("bricard"), 6, 1, 1),               # Bricard's 6R: Grübler 0, mobility 1
    (load("fourbar"), 3, 0, 1),               # planar: a 3-D point closes a class-2 revolute
    (load("fourbar_spatial"), 3, 0, 0),       # closed by its spherical joint
], ids=["bennett", "fourbar_4r", "bricard", "fourbar", "fourbar_spatial"])
def test_note_counts_the_mechanisms_redundant_equations(mech, rows, mechanism, closure_model):
    """The run's note counts the redundant rows by the rank of the closure Jacobian at the start
    (the counts of the in-house rank analysis: Bennett 3, the four-bar of parallel revolutes 3,
    Bricard 1), split into the mechanism's and the closure model's."""
    notes = [note for note in _run(mech, "best", 1e-3, 1e-3).notes
             if not note.startswith("engine limit:")]  # the proximal solves' (run-dependent)
    redundant = mechanism + closure_model
    expected = [f"{redundant} redundant closure equation(s) of {rows} (rank {rows - redundant} "
                f"at the start): {mechanism} of the mechanism, {closure_model} of the closure "
                f"model"] if redundant else []
    assert notes == expected


def test_build_rejects_a_loop_of_slides():
    mech = load("slider_crank_planar")
    slides = dataclasses.replace(mech, joints=tuple(
        dataclasses.replace(joint, type="prismatic") for joint in mech.joints))
    with pytest.raises(UnsupportedCase, match="cannot close: .*prismatic"):
        ADAPTER.build(slides)


def test_methods_include_default_and_best():
    names = [spec.name for spec in ADAPTER.methods()]
    assert names[:2] == ["default", "best"]
    assert ADAPTER.method_spec("best")[1]["integrator"] == "rk4"


@pytest.mark.parametrize("method", ["nonsense", "best:integrator=leapfrog", "best:kq=1"])
def test_bad_method_raises_value_error(method):
    model = ADAPTER.build(load("fourbar"))
    with pytest.raises(ValueError):
        ADAPTER.simulate(model, method, 1e-3, 1e-3, np.array([0.0]))


# --- start -------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", scenario_names())
def test_first_sample_is_the_harness_initial_state(name):
    mech = load(name)
    trajectory = _run(mech, "rk4", 1e-3, 1e-3)
    start = initial_state(mech)
    first = trajectory.at(0)
    for field in ("position", "quaternion", "velocity", "angular_velocity"):
        np.testing.assert_allclose(getattr(first, field), getattr(start, field), rtol=0,
                                   atol=1e-12, err_msg=field)


@pytest.mark.parametrize("name", ["fourbar", "slider_crank"])
def test_moving_start_converts_exactly(load_variant, name):
    """A start away from the reference pose (driver 0.4 rad, 2 rad/s): the joint coordinates
    solved from the body poses reproduce them (measured 2.9e-15 fourbar, 1.6e-15 slider_crank)."""
    mech = load_variant(name, [("value = 0.0\nrate = 0.0", "value = 0.4\nrate = 2.0")],
                        stem=f"{name}_moving")
    start = initial_state(mech)
    first = _run(mech, "rk4", 1e-3, 1e-3).at(0)
    for field in ("position", "quaternion", "velocity", "angular_velocity"):
        np.testing.assert_allclose(getattr(first, field), getattr(start, field), rtol=0,
                                   atol=1e-12, err_msg=field)


def test_axis_a_hair_off_a_coordinate_axis_keeps_its_tilt(load_variant):
    """Crank axis (0, 1e-9, 1): its unit z component rounds to exactly 1.0, yet the axis is not
    z.  Built as RZ the crank turned about z and the start came back 2.0e-9 rad/s (angular
    velocity) off: a ConversionError at t = 0.  Kept unaligned it converts to 1.5e-15 (measured)."""
    mech = load_variant("fourbar_spatial", [
        ("location = [0.0, 0.0, 0.0]\naxis = [0.0, 0.0, 1.0]",
         "location = [0.0, 0.0, 0.0]\naxis = [0.0, 1e-9, 1.0]"),
        ("rate = 0.0", "rate = 2.0")], stem="fourbar_spatial_tilted")
    assert mech.joint("O").axis1[2] == 1.0 and mech.joint("O").axis1[1] != 0.0
    trajectory = _run(mech, "rk4", 1e-3, 1e-3)
    assert trajectory.status == "ok", trajectory.reason
    start, first = initial_state(mech), trajectory.at(0)
    for field in ("position", "quaternion", "velocity", "angular_velocity"):
        np.testing.assert_allclose(getattr(first, field), getattr(start, field), rtol=0,
                                   atol=1e-12, err_msg=field)


# --- faithfulness ------------------------------------------------------------------------------

_ZERO_SWITCHES = ["armature", "damping", "friction", "rotorInertia", "lowerDryFrictionLimit",
                  "upperDryFrictionLimit"]
_UNBOUNDED_SWITCHES = ["effortLimit", "lowerEffortLimit", "upperEffortLimit", "velocityLimit",
                       "lowerVelocityLimit", "upperVelocityLimit"]


@pytest.mark.parametrize("name", scenario_names())
@pytest.mark.parametrize("switch", _ZERO_SWITCHES)
def test_engine_default_is_zero(name, switch):
    assert np.all(getattr(ADAPTER.build(load(name)).model, switch) == 0.0)


@pytest.mark.parametrize("name", scenario_names())
@pytest.mark.parametrize("switch", _UNBOUNDED_SWITCHES)
def test_limit_is_unbounded(name, switch):
    # Pinocchio stores "no limit" as ±DBL_MAX (lowerVelocityLimit defaults to +DBL_MAX).
    limits = getattr(ADAPTER.build(load(name)).model, switch)
    assert np.all(np.abs(limits) == np.finfo(float).max)


@pytest.mark.parametrize("name", scenario_names())
def test_constraints_are_rigid(name):
    for constraint in ADAPTER.build(load(name)).constraints:
        assert np.all(constraint.retrieveCompliance() == 0.0)


@pytest.mark.parametrize("name", scenario_names())
def test_default_method_has_no_baumgarte_correction(name):
    settings = solver_settings(ADAPTER.method_spec("default")[1])
    problem = ConstrainedProblem(ADAPTER.build(load(name)), settings)
    for constraint in problem.constraints:
        gains = constraint.m_baumgarte_parameters
        assert (gains.Kp, gains.Kd) == (0.0, 0.0)


@pytest.mark.parametrize("name", scenario_names())
def test_inertias_and_gravity_are_the_scenarios(name):
    mech = load(name)
    built = ADAPTER.build(mech)
    model, data = built.model, built.model.createData()
    pin.framesForwardKinematics(model, data, pin.neutral(model))
    assert np.array_equal(model.gravity.linear, mech.gravity)
    for body, frame in zip(mech.bodies, built.body_frames):
        inertia = model.inertias[model.frames[frame].parentJoint]
        placement = model.frames[frame].placement
        assert inertia.mass == body.mass
        np.testing.assert_allclose(inertia.lever, placement.translation, rtol=0, atol=0)
        np.testing.assert_allclose(inertia.inertia, body.inertia, rtol=0, atol=1e-15)
        # forward kinematics against the stored position (two paths): measured ≤ 4.4e-16 m with
        # OpenBLAS's Haswell, SkylakeX and Sandybridge kernels; bound 1e-12 m, the cross-CPU floor
        np.testing.assert_allclose(data.oMf[frame].translation, body.position, atol=1e-12)


# --- accuracy ----------------------------------------------------------------------------------

@pytest.mark.parametrize("name, tolerance", [
    # measured max |Δ crank angle| (rad) over 0.5 s, best at dt = 1e-3 vs best at dt = 2.5e-4:
    ("fourbar", 5e-9),             # measured 1.08e-9
    ("slider_crank", 3e-10),       # measured 3.6e-11
])
def test_best_agrees_with_a_fine_step(name, tolerance):
    mech = load(name)
    coarse = _run(mech, "best", 1e-3, 0.5)
    fine = _run(mech, "best", 2.5e-4, 0.5)
    assert coarse.status == fine.status == "ok"
    angle = output_series(mech, coarse, "crank_angle")
    reference = output_series(mech, fine, "crank_angle")[::4]
    assert np.max(np.abs(angle - reference)) < tolerance


@pytest.mark.parametrize("name", ["fourbar", "slider_crank", "slider_crank_planar"])
def test_best_keeps_the_loop_closed(name):
    mech = load(name)
    trajectory = _run(mech, "best", 1e-2, 1.0)
    for joint in ADAPTER.build(mech).tree.cut_joints:
        # measured 8.4e-13 fourbar, 5.2e-16 slider_crank, 1.04e-12 slider_crank_planar
        assert _closure_gap(mech, trajectory, joint) < 1e-11


def test_counters_count_the_engine_calls_and_the_projection():
    # slider_crank best (RK4 + projection), 500 steps of 1e-3 s: one constraintDynamics call per
    # stage, one projection (one pseudo-inverse, its Jacobian, then one per Newton iteration)
    # per step; measured 7953 proximal iterations, 40 Newton iterations, residual 9.5e-13.
    mech = load("slider_crank")
    trajectory = _run(mech, "best", 1e-3, 0.5)
    counters = trajectory.counters
    assert trajectory.status == "ok" and trajectory.steps == 500
    assert counters["constraint_dynamics_calls"] == counters["rhs_evals"] == 4 * 500
    assert counters["proximal_iterations"] >= counters["constraint_dynamics_calls"]
    assert counters["projection_factorizations"] == 500
    assert counters["jacobian_evals"] == 500 + counters["newton_iterations"]
    assert 0 < counters["max_relative_residual"] < 1e-10  # converged solves


def test_planar_and_spatial_fourbar_agree():
    """Same mechanism, planar (4 revolutes, 1 redundant row) and spatial joint sets: measured
    max |Δ crank angle| over 1 s at dt = 1e-3 (|angle| ≤ 1.06 rad) of 7.8e-16 to 1.0e-15 rad with
    OpenBLAS's Haswell, SkylakeX and Sandybridge kernels.  Two computation paths, whose spread
    reached 2.0e-13 rad on the body-wrench test below: bound 1e-11 rad, as there."""
    planar = _run(load("fourbar"), "best", 1e-3, 1.0)
    spatial = _run(load("fourbar_spatial"), "best", 1e-3, 1.0)
    difference = output_series(load("fourbar"), planar, "crank_angle") - output_series(
        load("fourbar_spatial"), spatial, "crank_angle")
    assert np.max(np.abs(difference)) < 1e-11


def test_loads_through_body_wrenches_match_joint_actuation_and_gravity(load_variant):
    """The crank torque as a body torque and gravity as body forces at the centres of mass
    reproduce the shipped model.  Two computation paths: measured max |Δ crank angle| over 0.5 s
    (|angle| ≤ 0.71 rad) 7.2e-16 rad with OpenBLAS's Haswell, Sandybridge and Prescott kernels and
    2.0e-13 rad with its SkylakeX (AVX-512) kernels (OPENBLAS_CORETYPE, 2026-11-23); bound 1e-11
    rad, 50× the largest spread."""
    mech = load("fourbar")
    forces = [('[[forces]]\ntype = "joint_torque"\njoint = "O"\nvalue = -1200.0',
               '[[forces]]\ntype = "body_torque"\nbody = "crank"\ntorque = [0.0, 0.0, -1200.0]'
               + "".join(f'\n\n[[forces]]\ntype = "body_force"\nbody = "{body.name}"\n'
                         f'force = [0.0, {-9.81 * body.mass!r}, 0.0]' for body in mech.bodies)),
              ("gravity = [0.0, -9.81, 0.0]", "gravity = [0.0, 0.0, 0.0]")]
    variant = load_variant("fourbar", forces, stem="fourbar_wrenches")
    shipped = _run(mech, "best", 1e-3, 0.5)
    loaded = _run(variant, "best", 1e-3, 0.5)
    difference = output_series(mech, shipped, "crank_angle") - output_series(
        variant, loaded, "crank_angle")
    assert np.max(np.abs(difference)) < 1e-11


# --- failures are results ----------------------------------------------------------------------

@pytest.mark.parametrize("name", ["fourbar", "slider_crank_planar"])
def test_default_fails_on_a_redundant_planar_closure(name):
    """ProximalSettings() (mu = 0, one iteration) meets the singular KKT matrix of a planar loop
    closed by a 3D point: Pinocchio returns NaN at the first evaluation."""
    trajectory = _run(load(name), "default", 1e-3, 0.01)
    assert trajectory.status == "failed"
    assert "non-finite" in trajectory.reason and "mu = 0" in trajectory.reason
    assert trajectory.failure_time == 0.0  # the last good state: the start, sample kept
    assert trajectory.n_samples == 1


def test_stiff_baumgarte_diverges_with_its_time():
    """Kp = 1e6 at dt = 1e-2 puts the corrector's eigenvalues far outside RK4's stability
    region: measured diverged in the step to t = 0.05 s (state norm above the integrator's 1e8
    limit), so the last good state is at 0.04 s."""
    trajectory = _run(load("fourbar"), "baumgarte:kp=1e6,kd=0", 1e-2, 1.0)
    assert trajectory.status == "diverged"
    assert trajectory.failure_time == pytest.approx(0.04)
    assert trajectory.times[-1] <= trajectory.failure_time


def test_unreachable_start_fails_with_reason(monkeypatch):
    """Body velocities no joint state produces (the crank sliding off its pivot) are caught by
    the round-trip check and end the run as ``failed`` at t = 0."""
    mech = load("fourbar")

    def drifting_start(mechanism):
        state = initial_state(mechanism)
        state.velocity[0] += (0.0, 0.0, 1.0)
        return state

    monkeypatch.setattr("mbh._adapters.pinocchio_adapter.adapter.initial_state", drifting_start)
    trajectory = _run(mech, "best", 1e-3, 0.01)
    assert trajectory.status == "failed"
    assert trajectory.failure_time == 0.0
    assert "not representable" in trajectory.reason


# --- declaration order (issue 9: the N-four-bar declared breadth-first) -------------------------


def _nfourbar():
    return load(DATA / "nfourbar_breadth_first.toml")


def test_every_subtree_has_contiguous_velocity_indices():
    """Joints are added depth-first: each joint's subtree owns one contiguous run of velocities
    from its idx_v, the layout crba's nvSubtree ranges assume.  Breadth-first (the old order)
    gave crank 2's subtree {crank 2, coupler 1} the velocities {1, 3}, which crba reads as
    {1, 2}."""
    model = ADAPTER.build(_nfourbar()).model
    for joint in range(1, model.njoints):
        owned = sorted(index for member in model.subtrees[joint]
                       for index in range(model.joints[member].idx_v,
                                          model.joints[member].idx_v + model.joints[member].nv))
        start = model.joints[joint].idx_v
        assert owned == list(range(start, start + len(owned))), model.names[joint]


def test_mass_matrix_agrees_with_rnea_breadth_first():
    """crba's mass matrix equals the one RNEA gives column by column (M e_i = τ(q, 0, e_i) − τ(q,
    0, 0)).  The old breadth-first model: effective inertia 4.33 where RNEA gives 3 (issue 9);
    now measured 4.4e-16 kg·m² apart."""
    mech = _nfourbar()
    pm = ADAPTER.build(mech)
    model, data = pm.model, pm.model.createData()
    q, _ = joint_state(pm, data, initial_state(mech))
    mass = pin.crba(model, data, q)
    mass = np.triu(mass) + np.triu(mass, 1).T
    zero = np.zeros(model.nv)
    bias = pin.rnea(model, data, q, zero, zero)
    columns = np.column_stack([pin.rnea(model, data, q, zero, unit) - bias
                               for unit in np.eye(model.nv)])
    np.testing.assert_allclose(mass, columns, rtol=0, atol=1e-12 * np.max(np.abs(mass)))


def test_start_accelerations_match_the_neutral_model_breadth_first():
    """The accelerations of Pinocchio's run at t = 0 equal the neutral model's.  The old
    breadth-first model violated the loop closure at acceleration level by 0.41 m/s² (issue 9);
    now measured 1.5e-5 m/s² apart (the difference formula's O(T²) at T = 1 ms), 1e-4 allowed."""
    mech = _nfourbar()
    span = 1e-3
    trajectory = ADAPTER.simulate(ADAPTER.build(mech), "best", 1e-4, 2 * span,
                                  np.array([0.0, span, 2 * span]))
    assert trajectory.status == "ok", trajectory.reason
    measured = start_accelerations(trajectory.times, trajectory.velocity,
                                   trajectory.angular_velocity)
    expected = accelerations(mech, initial_state(mech))
    np.testing.assert_allclose(measured.linear, expected.linear, rtol=0, atol=1e-4)
    np.testing.assert_allclose(measured.angular, expected.angular, rtol=0, atol=1e-4)


def test_a_one_joint_tree_runs():
    # With one degree of freedom pin.getFrameJacobian returns a 1-D array of 6, which broke the
    # start conversion ("LinAlgError: Incompatible dimensions", found by the generated-mechanism
    # suite).  A bar spun at 40 rad/s about a ground revolute, 0.01 s: Pinocchio's final rate
    # matches the in-house formulation's to 7.3e-13 rad/s (both RK4 at 1e-4); bound 1e-10.
    from mbh._adapters import get_adapter

    z, x = np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])
    bar = Body("bar", 1.0, np.diag([1 / 12, 1 / 12, 1e-3]), np.array([0.5, 0.0, 0.0]), np.eye(3))
    hinge = Joint("O", "revolute", "ground", "bar", np.zeros(3), np.array([-0.5, 0.0, 0.0]),
                  z, z, x, x)
    mech = Mechanism(name="one_joint", kind="spatial", bodies=(bar,), joints=(hinge,), forces=(),
                     gravity=np.array([0.0, -9.81, 0.0]), initial=InitialState("O", 0.0, 40.0),
                     duration=0.01, outputs=(), content_hash="one-joint-tree")
    rates = []
    for name in ("pinocchio", "inhouse"):
        adapter = get_adapter(name)
        run = adapter.simulate(adapter.build(mech), "best", 1e-4, 0.01, np.array([0.0, 0.01]))
        assert run.status == "ok", run.reason
        rates.append(run.angular_velocity[-1, 0, 2])
    assert abs(rates[0] - rates[1]) <= 1e-10


# --- projection and bare loop ------------------------------------------------------------------


class _LstsqProblem(ConstrainedProblem):
    """The projection as it was before one factorisation per step: a fresh least-squares solve
    (``numpy.linalg.lstsq``) at every Gauss–Newton iteration and for the velocity."""

    def project(self, t, q, v):
        for _ in range(self.settings.project_max_iter + 1):
            residual, jacobian = self.closure(q)
            if np.max(np.abs(residual)) <= self.settings.project_tol:
                break
            q = pin.integrate(self.model, q, -np.linalg.lstsq(jacobian, residual, rcond=None)[0])
        else:
            raise AssertionError("the lstsq projection did not converge")
        return q, v - np.linalg.lstsq(jacobian, jacobian @ v, rcond=None)[0]


def _rk4_projected(problem_class, mech, dt, n_steps):
    """Final joint state after ``n_steps`` RK4 steps with ``best``'s settings and
    ``problem_class``."""
    pm = ADAPTER.build(mech)
    problem = problem_class(pm, solver_settings(ADAPTER.method_spec("best")[1]))
    q, v = joint_state(pm, problem.kin_data, initial_state(mech))
    integrator = make_integrator("rk4", problem, 0.0, q, v, dt)
    for _ in range(n_steps):
        assert integrator.step() == "running", integrator.failure_reason
    return integrator.q, integrator.v


@pytest.mark.parametrize("name, dt, n_steps", [
    ("fourbar", 1e-3, 4000),              # planar loop closed by a 3-D point: rank 2 of 3 rows
    ("slider_crank", 1e-3, 4000),         # spatial, full row rank
    ("bricard", 1e-4, 1000),              # one redundant row
])
def test_one_factorisation_projects_like_lstsq(name, dt, n_steps):
    """The pseudo-inverse factored once per step (reused by the Gauss–Newton iterations and the
    velocity projection) against a fresh lstsq at every solve.  Measured max relative difference
    of the final joint state: 0 (bit for bit) on all three here, and over 4 s sampled every 10 ms
    of ``best`` at dt = 1e-3 at most 4.3e-13 (fourbar) and 5.1e-13 (slider_crank_planar): the
    chord iterations differ from Newton's by round-off only.  Two computation paths (SVD against
    LAPACK's gelsd): bound 1e-9 relative."""
    mech = load(name)
    new_q, new_v = _rk4_projected(ConstrainedProblem, mech, dt, n_steps)
    old_q, old_v = _rk4_projected(_LstsqProblem, mech, dt, n_steps)
    np.testing.assert_allclose(new_q, old_q, rtol=0, atol=1e-9 * np.max(np.abs(old_q)))
    np.testing.assert_allclose(new_v, old_v, rtol=0, atol=1e-9 * np.max(np.abs(old_v)))


def test_pseudo_inverse_is_the_minimum_norm_solution_of_a_rank_deficient_jacobian():
    """Bricard's closure Jacobian at the start (6 rows, 5 columns, rank 4): J⁺ r is lstsq's
    minimum-norm solution (measured 5.9e-16 relative apart) and J J⁺ J = J (measured 6.7e-16);
    bounds 1e-12."""
    mech = load("bricard")
    pm = ADAPTER.build(mech)
    problem = ConstrainedProblem(pm, solver_settings(ADAPTER.method_spec("best")[1]))
    q, _ = joint_state(pm, problem.kin_data, initial_state(mech))
    _, jacobian = problem.closure(q)
    assert np.linalg.matrix_rank(jacobian) == 4
    inverse = pseudo_inverse(jacobian)
    rhs = np.random.default_rng(0).normal(size=jacobian.shape[0])
    expected = np.linalg.lstsq(jacobian, rhs, rcond=None)[0]
    np.testing.assert_allclose(inverse @ rhs, expected, rtol=0, atol=1e-12 * np.abs(expected).max())
    np.testing.assert_allclose(jacobian @ inverse @ jacobian, jacobian, rtol=0, atol=1e-12)


@pytest.mark.parametrize("method", ["default", "best"])
def test_bare_loop_returns_its_time(method):
    assert ADAPTER.bare_loop(ADAPTER.build(load("fourbar")), method, 1e-3, 20) > 0.0


@pytest.mark.parametrize("name", ["fourbar", "slider_crank"])
def test_bare_loop_takes_the_adapters_steps(name):
    """The yardstick does the adapter's work: 500 steps of ``best`` at dt = 1e-3 in the plain loop
    end where the integrator ends (measured 1.9e-15 relative: the integrator's step is
    t_new − t, the loop's dt); bound 1e-9 relative."""
    mech = load(name)
    pm = ADAPTER.build(mech)
    problem = constrained_problem(pm, solver_settings(ADAPTER.method_spec("best")[1]))
    q, v = joint_state(pm, problem.kin_data, initial_state(mech))
    q, v = bare_steps(problem, bare_rule(problem, "rk4"), q, v, 1e-3, 500)
    expected_q, expected_v = _rk4_projected(ConstrainedProblem, mech, 1e-3, 500)
    np.testing.assert_allclose(q, expected_q, rtol=0, atol=1e-9 * np.max(np.abs(expected_q)))
    np.testing.assert_allclose(v, expected_v, rtol=0, atol=1e-9 * np.max(np.abs(expected_v)))


def test_bare_loop_refuses_a_multistep_integrator():
    with pytest.raises(UnsupportedCase, match="not an explicit one-step method"):
        ADAPTER.bare_loop(ADAPTER.build(load("fourbar")), "best:integrator=ab4", 1e-3, 10)


def test_round_off_singular_values_count_as_redundant():
    """Bricard at dt = 1e-2: its redundant closure direction has singular value 8.2e-15 and
    1.7e-14 of the largest in the first two steps (round-off, above lstsq's eps-based cut), and a
    projection that inverted it stepped 2.3 m and failed at 0.01 s.  With RANK_RTOL the run is
    ok over 4 s (measured); here 0.5 s, with the cut joint's gap between its two points
    (measured 3.9e-13 m; bound 1e-10 m)."""
    mech = load("bricard")
    trajectory = _run(mech, "best", 1e-2, 0.5)
    assert trajectory.status == "ok", trajectory.reason
    for joint in ADAPTER.build(mech).tree.cut_joints:
        assert _closure_gap(mech, trajectory, joint) < 1e-10
