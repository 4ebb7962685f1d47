"""Tests of the MuJoCo adapter: building, the shared start, faithfulness switches, accuracy and
failure reporting.  Tolerances are measured values (stated next to them) with margin."""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
import pytest
from tests.helpers import VERIFIED_SCENES
from scipy.spatial.transform import Rotation

from mbh._adapters.base import UnsupportedCase
from mbh._adapters.mujoco_adapter import MujocoAdapter, export_mjcf
from mbh._adapters.mujoco_adapter.build import mujoco_inertia
from mbh._adapters.mujoco_adapter.methods import INTEGRATORS
from mbh._harness.neutral.start import initial_state
from mbh._harness.model.mechanism import BodyTorque, JointActuation, SpringDamper
from mbh._harness.model.outputs import output_series
from mbh._harness.model.scenario import load, scenario_names

ADAPTER = MujocoAdapter()
SCENARIOS = scenario_names()
#: Cut joints MuJoCo's closure costs lead to (connect = 3 equations; see closure_equations).
EXPECTED_CUTS = {"fourbar": ("B",), "fourbar_spatial": ("B",), "slider_crank": ("A",),
                 "slider_crank_planar": ("A",), "double_fourbar": ("A1", "A2"), "bricard": ("C",),
                 "andrews": ("E3", "E4", "E6"), "parallelogram_fourbar": ("A",),
                 "stiff_fourbar": ("B",), "simple_pendulum": ()}
#: ``connect`` equalities: one per cut, two (points on the axis) for a spatial revolute cut.
EXPECTED_CONNECTS = {"bricard": 2}
#: Redundant closure equations: a connect on a planar revolute cut has one; the two connects of
#: Bricard's spatial revolute cut (6 equations for its 5) have one.
EXPECTED_REDUNDANT = {"fourbar": 1, "fourbar_spatial": 0, "slider_crank": 0,
                      "slider_crank_planar": 1, "double_fourbar": 2, "bricard": 1, "andrews": 3,
                      "parallelogram_fourbar": 1, "stiff_fourbar": 1, "simple_pendulum": 0}


@pytest.fixture(scope="module", params=SCENARIOS)
def case(request):
    """(mechanism, built model) of every shipped scenario."""
    mech = load(request.param)
    return mech, ADAPTER.build(mech)


def _times(duration: float, dt: float, every: float = 0.01) -> np.ndarray:
    """Sample times every ``every`` s (a multiple of ``dt``) from 0 to ``duration``."""
    return np.arange(int(round(duration / every)) + 1) * every


def _moved(mech, value=0.3, rate=2.0):
    """``mech`` started away from its reference pose and moving (a fresh initial-state key)."""
    initial = dataclasses.replace(mech.initial, value=value, rate=rate)
    return dataclasses.replace(mech, initial=initial, content_hash=f"{mech.content_hash}-moved")


# ------------------------------------------------------------------------------------ build


def test_build_every_scenario(case):
    mech, built = case
    assert built.tree.cut_joints == EXPECTED_CUTS[mech.name]
    assert built.model.nbody == len(mech.bodies) + 1
    assert built.model.neq == EXPECTED_CONNECTS.get(mech.name, len(built.tree.cut_joints))


def test_redundant_closure_note(case):
    mech, built = case
    trajectory = ADAPTER.simulate(built, "best", 1e-3, 0.01, np.array([0.0, 0.01]))
    redundant = EXPECTED_REDUNDANT[mech.name]
    assert built.tree.redundant_closure_equations == redundant
    # The note counts the rank of the equality rows at the start: the closure model's excess
    # plus the mechanism's own (Bricard's loop: 1 more, the in-house rank analysis's count).
    of_mechanism = {"bricard": 1}.get(mech.name, 0)
    total = redundant + of_mechanism
    notes = [note for note in trajectory.notes if "redundant closure" in note]
    assert len(notes) == (total > 0)
    if total:
        assert notes[0].startswith(f"{total} redundant closure equation(s) of ")
        assert notes[0].endswith(f": {of_mechanism} of the mechanism, {redundant} of the "
                                 f"closure model")


def test_cut_prismatic_loop_is_unsupported():
    mech = load("slider_crank_planar")
    slide = mech.joint("P")
    second = dataclasses.replace(slide, name="P2")  # a loop of two prismatic joints
    with pytest.raises(UnsupportedCase, match="prismatic"):
        ADAPTER.build(dataclasses.replace(mech, joints=(*mech.joints, second)))


def test_export_mjcf_round_trips():
    xml = export_mjcf(load("slider_crank"))
    model = mujoco.MjModel.from_xml_string(xml)
    assert "connect" in xml
    assert [model.joint(i).name for i in range(model.njnt)] == ["O", "P", "U_1", "U_2"]


# ------------------------------------------------------------------------------ shared start


@pytest.mark.parametrize("name", VERIFIED_SCENES)
@pytest.mark.parametrize("moved", [False, True], ids=["reference", "moved"])
def test_first_sample_is_the_harness_initial_state(name, moved):
    mech = _moved(load(name)) if moved else load(name)
    trajectory = ADAPTER.simulate(ADAPTER.build(mech), "best", 1e-3, 0.01, np.array([0.0, 0.01]))
    expected = initial_state(mech)
    assert trajectory.status == "ok", trajectory.reason
    for key in ("position", "quaternion", "velocity", "angular_velocity"):
        np.testing.assert_allclose(getattr(trajectory, key)[0], getattr(expected, key),
                                   rtol=0, atol=1e-12, err_msg=key)


# ---------------------------------------------------------------------------- faithfulness


def test_no_contacts(case):
    model = case[1].model
    assert model.ngeom == 0
    assert model.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_CONTACT


def test_no_joint_damping(case):
    np.testing.assert_array_equal(case[1].model.dof_damping, 0.0)
    np.testing.assert_array_equal(case[1].model.dof_dampingpoly, 0.0)


def test_no_joint_stiffness(case):
    np.testing.assert_array_equal(case[1].model.jnt_stiffness, 0.0)
    np.testing.assert_array_equal(case[1].model.jnt_stiffnesspoly, 0.0)


def test_no_armature(case):
    np.testing.assert_array_equal(case[1].model.dof_armature, 0.0)


def test_no_friction_loss(case):
    np.testing.assert_array_equal(case[1].model.dof_frictionloss, 0.0)


def test_no_joint_limits(case):
    np.testing.assert_array_equal(case[1].model.jnt_limited, 0)


def test_no_actuators(case):
    assert case[1].model.nu == 0


def test_no_gravity_compensation(case):
    np.testing.assert_array_equal(case[1].model.body_gravcomp, 0.0)


def test_no_medium_forces(case):
    opt = case[1].model.opt
    assert (opt.density, opt.viscosity) == (0.0, 0.0)
    np.testing.assert_array_equal(opt.wind, 0.0)


def test_no_sleeping(case):
    assert not case[1].model.opt.enableflags & mujoco.mjtEnableBit.mjENBL_SLEEP


def test_exact_masses(case):
    mech, built = case
    np.testing.assert_array_equal(built.model.body_mass[built.body_ids], mech.masses)


def test_exact_inertias(case):
    mech, built = case
    model = built.model
    for body, index in zip(mech.bodies, built.body_ids):
        frame = Rotation.from_quat(model.body_iquat[index], scalar_first=True).as_matrix()
        tensor = frame @ np.diag(model.body_inertia[index]) @ frame.T
        # A slender body's zero moment is raised to INERTIA_FLOOR × its largest, a point mass's
        # to INERTIA_FLOOR × m r² about its farthest joint point, a flat body's in-plane moments
        # until A + B ≥ C (each noted).
        expected, _, _ = mujoco_inertia(mech, body)
        np.testing.assert_allclose(tensor, expected, rtol=0, atol=1e-12 * expected.max())
        np.testing.assert_array_equal(model.body_ipos[index], 0.0)


def test_a_point_mass_gets_a_floor_of_its_moment_about_its_joint_and_a_note():
    """The simple pendulum's 1 kg bob, 1 m from its pivot: 1e-9 × 1 kg·m² about every axis."""
    built = ADAPTER.build(load("simple_pendulum"))
    np.testing.assert_allclose(built.model.body_inertia[built.body_ids[0]], [1e-9] * 3,
                               rtol=1e-12)
    trajectory = ADAPTER.simulate(built, "best", 1e-3, 0.01, np.array([0.0, 0.01]))
    assert [note for note in trajectory.notes if "a point mass" in note] == [
        "body bob: principal moment 0 raised to 1e-09 kg·m² (1e-09 × m r² about its farthest "
        "joint point: a point mass) for MuJoCo, which requires positive inertia"]


def test_exact_gravity(case):
    mech, built = case
    np.testing.assert_array_equal(built.model.opt.gravity, mech.gravity)


def test_spring_damper_is_a_native_tendon():
    mech = load("fourbar")
    spring = SpringDamper("s", "ground", "coupler", np.array([1.0, 2.0, 0.0]), np.zeros(3),
                          stiffness=500.0, damping=20.0, free_length=1.5)
    model = ADAPTER.build(dataclasses.replace(mech, forces=(*mech.forces, spring))).model
    assert model.ntendon == 1
    assert (model.tendon_stiffness[0], model.tendon_damping[0]) == (500.0, 20.0)
    np.testing.assert_array_equal(model.tendon_stiffnesspoly, 0.0)
    np.testing.assert_array_equal(model.tendon_dampingpoly, 0.0)
    np.testing.assert_array_equal(model.tendon_lengthspring[0], [1.5, 1.5])
    assert model.tendon_limited[0] == 0 and model.tendon_frictionloss[0] == 0.0


# ---------------------------------------------------------------------------------- methods


def test_default_method_is_mujoco_defaults():
    params = ADAPTER.method_spec("default")[1]
    reference = mujoco.MjSpec()
    equality = reference.add_equality()
    assert params["integrator"] == "Euler"
    assert reference.option.integrator == mujoco.mjtIntegrator.mjINT_EULER
    assert (params["iterations"], params["tolerance"]) == (reference.option.iterations,
                                                           reference.option.tolerance)
    assert reference.option.solver == mujoco.mjtSolver.mjSOL_NEWTON and params["solver"] == "Newton"
    np.testing.assert_array_equal(equality.solref, [params["solref_timeconst"],
                                                    params["solref_dampratio"]])
    np.testing.assert_array_equal(equality.solimp[:3], [params["solimp0"], params["solimp1"],
                                                        params["solimp_width"]])


def test_unknown_method_lists_valid_ones(case):
    with pytest.raises(ValueError, match="valid: default, best"):
        ADAPTER.simulate(case[1], "nonsense", 1e-3, 0.01, np.array([0.0]))


def test_bad_integrator_is_named(case):
    with pytest.raises(ValueError, match="'integrator'"):
        ADAPTER.simulate(case[1], "default:integrator=leapfrog", 1e-3, 0.01, np.array([0.0]))


# ------------------------------------------------------------------------------------ loads


def _final_state(mech, method="best"):
    built = ADAPTER.build(mech)
    trajectory = ADAPTER.simulate(built, method, 1e-3, 0.5, _times(0.5, 1e-3, every=0.5))
    assert trajectory.status == "ok", trajectory.reason
    return trajectory


@pytest.mark.parametrize("joint, body, sign", [("O", "crank", 1.0), ("R", "rocker", -1.0),
                                               ("B", "coupler", 1.0)],
                         ids=["tree", "flipped-tree", "cut"])
def test_joint_actuation_equals_body_torques(joint, body, sign):
    """A joint torque on a tree, a flipped tree and a cut joint equals the body torques it means.

    Measured position difference at 0.5 s: 0 for the tree joints, 1.8e-15 m for the cut joint
    (recomputed per step); the extra torque itself moves the bodies by 0.02–0.05 m.
    """
    mech = load("fourbar")
    value = 300.0
    actuated = dataclasses.replace(mech, forces=(*mech.forces, JointActuation(joint, value)))
    spec = mech.joint(joint)
    torque = np.array([0.0, 0.0, value * sign])
    torques = [BodyTorque(body, torque)]
    other = spec.body1 if body == spec.body2 else spec.body2
    if other != "ground":
        torques.append(BodyTorque(other, -torque))
    as_torques = dataclasses.replace(mech, forces=(*mech.forces, *torques))
    np.testing.assert_allclose(_final_state(actuated).position,
                               _final_state(as_torques).position, rtol=0, atol=1e-12)


# --------------------------------------------------------------------------------- accuracy

#: max |crank angle(best, dt = 1e-3) − crank angle(best, dt = 1e-4)| over the run, rad, measured:
#: fourbar 3.8e-5, fourbar_spatial 6.0e-5, slider_crank 1.25e-3, slider_crank_planar 1.28e-3
#: (margin ~4×).
BEST_AGREEMENT = {"fourbar": 1.5e-4, "fourbar_spatial": 2.5e-4, "slider_crank": 5e-3,
                  "slider_crank_planar": 5e-3}


@pytest.mark.parametrize("name", VERIFIED_SCENES)
def test_best_agrees_with_a_fine_step(name):
    mech = load(name)
    built = ADAPTER.build(mech)
    times = _times(mech.duration, 1e-3)
    coarse = ADAPTER.simulate(built, "best", 1e-3, mech.duration, times)
    fine = ADAPTER.simulate(built, "best", 1e-4, mech.duration, times)
    assert (coarse.status, fine.status) == ("ok", "ok")
    error = np.max(np.abs(output_series(mech, coarse, "crank_angle")
                          - output_series(mech, fine, "crank_angle")))
    assert error < BEST_AGREEMENT[mech.name]


# ---------------------------------------------------------------------------------- failure


def test_blow_up_is_diverged_with_its_time():
    """Measured: Euler with MuJoCo's default softness at dt = 1e-2 on the planar slider-crank
    raises a bad-qacc warning at step 192 (t = 1.92 s); MuJoCo itself would reset and go on.
    The last good state is the one after step 191."""
    mech = load("slider_crank_planar")
    times = _times(mech.duration, 1e-2)
    trajectory = ADAPTER.simulate(ADAPTER.build(mech), "default", 1e-2, mech.duration, times)
    assert trajectory.status == "diverged"
    assert trajectory.failure_time == pytest.approx(1.91)
    assert trajectory.n_samples == 192
    assert np.all(np.isfinite(trajectory.position))


@pytest.mark.parametrize("every, samples", [(0.1, 20), (4.0, 1)])
def test_divergence_inside_a_chunk_is_found_by_replay(every, samples):
    """The blow-up above (step 192) with 10 and 400 steps per ``mj_step`` call: the warning is
    seen after the chunk, the run replayed from its start finds the same step and last good
    state (1.91 s), and every sample before the chunk is kept."""
    mech = load("slider_crank_planar")
    times = _times(mech.duration, 1e-2, every)
    trajectory = ADAPTER.simulate(ADAPTER.build(mech), "default", 1e-2, mech.duration, times)
    assert trajectory.status == "diverged"
    assert trajectory.failure_time == pytest.approx(1.91)
    assert trajectory.steps == 192
    assert trajectory.n_samples == samples


def test_divergence_warnings_are_the_bad_state_ones():
    from mbh._adapters.mujoco_adapter.stepping import DIVERGENCE_WARNINGS

    watched = range(mujoco.mjtWarning.mjNWARNING)[DIVERGENCE_WARNINGS]
    assert list(watched) == [mujoco.mjtWarning.mjWARN_BADQPOS, mujoco.mjtWarning.mjWARN_BADQVEL,
                             mujoco.mjtWarning.mjWARN_BADQACC]


@pytest.mark.parametrize("method", ["default", "best"])
def test_bare_loop_takes_the_steps_in_one_call(monkeypatch, method):
    calls = []

    def counted(model, data, nstep=1):
        step(model, data, nstep)
        calls.append((nstep, data.time, model.opt.integrator))

    step = mujoco.mj_step
    monkeypatch.setattr(mujoco, "mj_step", counted)
    seconds = ADAPTER.bare_loop(ADAPTER.build(load("fourbar")), method, 1e-3, 250)
    assert isinstance(seconds, float) and seconds > 0.0
    integrator = ADAPTER.method_spec(method)[1]["integrator"]
    assert calls == [(250, pytest.approx(0.25, rel=1e-12), INTEGRATORS[integrator])]


def test_engine_exception_is_failed(monkeypatch, case):
    def broken(*args, **kwargs):
        raise mujoco.FatalError("simulated engine error")

    monkeypatch.setattr(mujoco, "mj_step", broken)
    trajectory = ADAPTER.simulate(case[1], "best", 1e-3, 0.01, np.array([0.0, 0.01]))
    assert trajectory.status == "failed"
    assert "simulated engine error" in trajectory.reason
    assert trajectory.n_samples == 1 and trajectory.failure_time == 0.0
