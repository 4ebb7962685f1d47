"""MuJoCo adapter: the neutral mechanism as an MJCF model built through ``mujoco.MjSpec``.

Model
-----
* The bodies form the spanning tree chosen by :func:`harness.topology.spanning_tree` with
  MuJoCo's closure costs (:func:`closure_equations`).  Each tree joint becomes hinge / slide /
  ball joints inside the child body, no dummy bodies: revolute = hinge, prismatic and
  translational = slide, cylindrical = slide + hinge, universal = two hinges (the parent-fixed
  cross axis first, then the child-fixed one), spherical = ball.
* Every body frame is the neutral body frame (origin at the centre of mass), so ``xpos``/``xquat``
  are the harness's body states; mass and the full centroidal inertia go in through
  ``fullinertia``.  The reference configuration is MuJoCo's ``qpos0``.
* Cut joints are closed by site-based ``connect`` equality constraints (3 equations each):
  spherical with one, planar revolute with one (1 redundant equation), spatial revolute with two
  along the axis (1 redundant).  MuJoCo has no equality that leaves a sliding or a second
  rotational freedom free, so cut prismatic, translational, cylindrical and universal joints are
  unsupported.
* Faithfulness: no geoms (and the contact flag off), no actuators, joint damping, stiffness,
  armature and friction loss explicitly zero, joints unlimited.  Spring-dampers are native
  spatial tendons between two sites (stiffness, damping, spring length).  Actuation of a tree
  joint is a constant ``qfrc_applied`` on its dof; body torques and forces at the centre of mass
  are constant ``xfrc_applied``; actuation of a cut joint and forces away from the centre of mass
  depend on the pose and are recomputed before every step (held constant within a step).

Methods
-------
Every method takes the parameters ``integrator`` (Euler, RK4, implicit, implicitfast, discrete),
``solref_timeconst`` (s; 0 = 2·dt, the smallest value MuJoCo's ``refsafe`` clamp lets through),
``solref_dampratio``, ``solimp0``, ``solimp1``, ``solimp_width`` (the equality constraints'
softness), ``iterations``, ``tolerance`` and ``solver`` (Newton, CG, PGS).  ``default`` is
MuJoCo's own defaults; ``best`` is RK4 with tight constraints; ``<integrator>`` and
``<integrator>-tight`` cover the product of integrators and the two softness presets.
"""

from __future__ import annotations

import copy
import time
from dataclasses import dataclass

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from adapters.base import Adapter, MethodSpec, UnsupportedCase
from harness.initial import initial_state
from harness.model import GROUND, BodyForce, BodyTorque, Joint, JointActuation, Mechanism, \
    SpringDamper
from harness.topology import SpanningTree, spanning_tree
from harness.trajectory import BodyStates, Trajectory

#: Integrator names accepted by the ``integrator`` parameter.
INTEGRATORS = {
    "Euler": mujoco.mjtIntegrator.mjINT_EULER,
    "RK4": mujoco.mjtIntegrator.mjINT_RK4,
    "implicit": mujoco.mjtIntegrator.mjINT_IMPLICIT,
    "implicitfast": mujoco.mjtIntegrator.mjINT_IMPLICITFAST,
    "discrete": mujoco.mjtIntegrator.mjINT_DISCRETE,
}
#: Right-hand-side (mj_forward) evaluations per step.
STAGES = {"Euler": 1, "RK4": 4, "implicit": 1, "implicitfast": 1, "discrete": 1}
SOLVERS = {
    "Newton": mujoco.mjtSolver.mjSOL_NEWTON,
    "CG": mujoco.mjtSolver.mjSOL_CG,
    "PGS": mujoco.mjtSolver.mjSOL_PGS,
}
#: Equality-constraint softness presets: MuJoCo's defaults and near-rigid constraints.
SOFTNESS = {
    "default": {"solref_timeconst": 0.02, "solref_dampratio": 1.0, "solimp0": 0.9,
                "solimp1": 0.95, "solimp_width": 0.001},
    "tight": {"solref_timeconst": 0.0, "solref_dampratio": 1.0, "solimp0": 0.9999,
              "solimp1": 0.9999, "solimp_width": 0.001},
}
#: solimp midpoint and power, MuJoCo's defaults (they only shape the width transition).
SOLIMP_SHAPE = (0.5, 2.0)
SOLVER_DEFAULTS = {"iterations": 100, "tolerance": 1e-8, "solver": "Newton"}
#: Cut-joint closure cost when MuJoCo cannot close the joint at all (never preferred).
UNCLOSABLE = 1000
#: Warnings that mean the state went bad (MuJoCo then resets the simulation and carries on).
DIVERGENCE_WARNINGS = np.array([mujoco.mjtWarning.mjWARN_BADQPOS, mujoco.mjtWarning.mjWARN_BADQVEL,
                                mujoco.mjtWarning.mjWARN_BADQACC], dtype=int)
#: Largest allowed difference between the harness's initial state and MuJoCo's version of it.
INITIAL_TOLERANCE = 1e-12
_SLIDING = ("prismatic", "translational")
_Z = np.array([0.0, 0.0, 1.0])


def closure_equations(mech: Mechanism, joint: Joint) -> int:
    """Constraint equations MuJoCo needs to close a loop cut at ``joint``.

    Parameters
    ----------
    mech : Mechanism
        Decides whether a revolute cut is planar (one ``connect``) or spatial (two).
    joint : Joint

    Returns
    -------
    int
        3 per ``connect`` equality; :data:`UNCLOSABLE` for joint types MuJoCo cannot close.
    """
    if joint.type == "spherical":
        return 3
    if joint.type == "revolute":
        return 3 if mech.planar else 6
    return UNCLOSABLE


@dataclass(frozen=True)
class _Loads:
    """Applied loads, split into constant ones and pose-dependent ones.

    Attributes
    ----------
    qfrc : ndarray, shape (nv,)
        Generalized forces on tree-joint dofs (N·m or N).
    xfrc : ndarray, shape (nbody, 6)
        Constant world force and torque on bodies at their centres of mass.
    point_forces : tuple of (int, ndarray (3,), ndarray (3,))
        MuJoCo body id, world force (N), application point in the body frame (m).
    cut_torques : tuple of (int, int, ndarray (3,), float)
        Body ids of ``body1`` (0 = world) and ``body2``, joint axis in ``body1``'s frame, torque
        about it on ``body2`` (N·m; the reaction acts on ``body1``).
    """

    qfrc: np.ndarray
    xfrc: np.ndarray
    point_forces: tuple
    cut_torques: tuple

    @property
    def moving(self) -> bool:
        """True when some load depends on the pose and must be recomputed every step."""
        return bool(self.point_forces or self.cut_torques)


@dataclass(frozen=True)
class MujocoModel:
    """What :meth:`MujocoAdapter.build` returns.

    Attributes
    ----------
    mechanism : Mechanism
    tree : SpanningTree
    spec : mujoco.MjSpec
        The compiled specification (``spec.to_xml()`` is the MJCF).
    model : mujoco.MjModel
        The compiled model at MuJoCo's defaults; :meth:`MujocoAdapter.simulate` works on a copy.
    body_ids : ndarray of int, shape (n_bodies,)
        MuJoCo body id of each mechanism body (declaration order).
    loads : _Loads
    """

    mechanism: Mechanism
    tree: SpanningTree
    spec: mujoco.MjSpec
    model: mujoco.MjModel
    body_ids: np.ndarray
    loads: _Loads


# --------------------------------------------------------------------------------------------
# Building the specification


def _pose(mech: Mechanism, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Reference rotation (3×3, body → world) and CoM position (3,) of body ``name`` or ground."""
    if name == GROUND:
        return np.eye(3), np.zeros(3)
    body = mech.bodies[mech.body_index(name)]
    return body.rotation, body.position


def _quat(rotation: np.ndarray) -> np.ndarray:
    """Scalar-first unit quaternion of a rotation matrix, shape (4,)."""
    return Rotation.from_matrix(rotation).as_quat(scalar_first=True)


def _elementary_joints(joint: Joint, flipped: bool, parent_to_child: np.ndarray) -> list:
    """MuJoCo joints that make up one tree joint, as ``(suffix, mjtJoint, axis in child frame)``.

    ``parent_to_child`` (3×3) maps parent-frame vectors into the child frame at the reference.
    """
    child_axis = joint.axis1 if flipped else joint.axis2
    hinge, slide = mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtJoint.mjJNT_SLIDE
    if joint.type == "revolute":
        return [("", hinge, child_axis)]
    if joint.type in _SLIDING:
        return [("", slide, child_axis)]
    if joint.type == "cylindrical":
        return [("_slide", slide, child_axis), ("_hinge", hinge, child_axis)]
    if joint.type == "universal":
        parent_axis = parent_to_child @ (joint.axis2 if flipped else joint.axis1)
        return [("_1", hinge, parent_axis), ("_2", hinge, child_axis)]
    return [("", mujoco.mjtJoint.mjJNT_BALL, _Z)]


def _add_body(spec_parent, mech: Mechanism, name: str, parent: str):
    """Add body ``name`` under ``spec_parent`` at its reference pose relative to ``parent``."""
    rot_p, pos_p = _pose(mech, parent)
    body = mech.bodies[mech.body_index(name)]
    inertia = body.inertia
    added = spec_parent.add_body(name=name, pos=rot_p.T @ (body.position - pos_p),
                                 quat=_quat(rot_p.T @ body.rotation))
    added.mass = body.mass
    added.ipos = np.zeros(3)
    added.fullinertia = [inertia[0, 0], inertia[1, 1], inertia[2, 2],
                         inertia[0, 1], inertia[0, 2], inertia[1, 2]]
    added.explicitinertial = True
    added.gravcomp = 0.0
    return added


def _add_tree_joint(spec_body, mech: Mechanism, joint: Joint, flipped: bool, parent: str) -> None:
    """Add the MuJoCo joints of tree joint ``joint`` to ``spec_body`` (the child)."""
    rot_p, _ = _pose(mech, parent)
    rot_c, _ = _pose(mech, spec_body.name)
    anchor = joint.point1 if flipped else joint.point2
    for suffix, kind, axis in _elementary_joints(joint, flipped, rot_c.T @ rot_p):
        spec_body.add_joint(name=joint.name + suffix, type=kind, axis=axis, pos=anchor,
                            limited=mujoco.mjtLimited.mjLIMITED_FALSE, damping=[0.0, 0.0, 0.0],
                            stiffness=[0.0, 0.0, 0.0], armature=0.0, frictionloss=0.0)


def _add_site(bodies: dict, body: str, name: str, point: np.ndarray) -> str:
    """Add a site ``name`` at ``point`` (body frame) of ``body``; returns its name."""
    bodies[body].add_site(name=name, pos=point)
    return name


def _add_connect(spec: mujoco.MjSpec, bodies: dict, joint: Joint, name: str,
                 offset: float) -> None:
    """A site-based ``connect`` between the joint points shifted ``offset`` m along the axis."""
    site1 = _add_site(bodies, joint.body1, f"{name}_1", joint.point1 + offset * joint.axis1)
    site2 = _add_site(bodies, joint.body2, f"{name}_2", joint.point2 + offset * joint.axis2)
    spec.add_equality(name=name, type=mujoco.mjtEq.mjEQ_CONNECT,
                      objtype=mujoco.mjtObj.mjOBJ_SITE, name1=site1, name2=site2)


def _add_closure(spec: mujoco.MjSpec, bodies: dict, mech: Mechanism, joint: Joint) -> None:
    """Close the loop at cut joint ``joint`` with ``connect`` equalities."""
    if closure_equations(mech, joint) == UNCLOSABLE:
        raise UnsupportedCase(f"joint {joint.name!r} ({joint.type}) is cut and MuJoCo has no "
                              f"equality constraint that closes a {joint.type} joint")
    _add_connect(spec, bodies, joint, joint.name, 0.0)
    if joint.type == "revolute" and not mech.planar:
        _add_connect(spec, bodies, joint, f"{joint.name}_axis", 1.0)


def _add_spring(spec: mujoco.MjSpec, bodies: dict, spring: SpringDamper) -> None:
    """A spatial tendon between two sites carrying the spring-damper."""
    tendon = spec.add_tendon(name=spring.name, stiffness=[spring.stiffness, 0.0, 0.0],
                             damping=[spring.damping, 0.0, 0.0],
                             springlength=[spring.free_length, spring.free_length],
                             limited=mujoco.mjtLimited.mjLIMITED_FALSE, armature=0.0,
                             frictionloss=0.0)
    tendon.wrap_site(_add_site(bodies, spring.body1, f"{spring.name}_1", spring.point1))
    tendon.wrap_site(_add_site(bodies, spring.body2, f"{spring.name}_2", spring.point2))


def _make_spec(mech: Mechanism, tree: SpanningTree) -> mujoco.MjSpec:
    """The MuJoCo specification of ``mech`` with tree ``tree`` (not yet compiled)."""
    spec = mujoco.MjSpec()
    spec.modelname = mech.name
    spec.option.gravity = np.asarray(mech.gravity, dtype=float)
    spec.option.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    bodies = {GROUND: spec.worldbody}
    for name in tree.order:
        parent = tree.parent[name]
        bodies[name] = _add_body(bodies[parent], mech, name, parent)
        joint = mech.joint(tree.parent_joint[name])
        _add_tree_joint(bodies[name], mech, joint, tree.flipped[joint.name], parent)
    for name in tree.cut_joints:
        _add_closure(spec, bodies, mech, mech.joint(name))
    for force in mech.forces:
        if isinstance(force, SpringDamper):
            _add_spring(spec, bodies, force)
    return spec


# --------------------------------------------------------------------------------------------
# Loads


def _body_id(model: mujoco.MjModel, name: str) -> int:
    """MuJoCo body id of ``name`` (0 for ground, the world body)."""
    return 0 if name == GROUND else model.body(name).id


def _joint_dof(model: mujoco.MjModel, joint: Joint) -> int:
    """Dof address of the coordinate that ``JointActuation`` drives on tree joint ``joint``."""
    suffix = "_hinge" if joint.type == "cylindrical" else ""
    return model.jnt_dofadr[model.joint(joint.name + suffix).id]


def _loads(mech: Mechanism, tree: SpanningTree, model: mujoco.MjModel) -> _Loads:
    """Sort the mechanism's forces into constant generalized / body loads and moving ones."""
    qfrc, xfrc = np.zeros(model.nv), np.zeros((model.nbody, 6))
    point_forces, cut_torques = [], []
    for force in mech.forces:
        if isinstance(force, JointActuation):
            joint = mech.joint(force.joint)
            if joint.name in tree.cut_joints:
                cut_torques.append((_body_id(model, joint.body1), _body_id(model, joint.body2),
                                    joint.axis1, force.value))
            else:
                sign = -1.0 if tree.flipped[joint.name] else 1.0
                qfrc[_joint_dof(model, joint)] += sign * force.value
        elif isinstance(force, BodyTorque):
            xfrc[_body_id(model, force.body), 3:] += force.torque
        elif isinstance(force, BodyForce):
            xfrc[_body_id(model, force.body), :3] += force.force
            if np.any(force.point != 0.0):
                point_forces.append((_body_id(model, force.body), force.force, force.point))
    return _Loads(qfrc, xfrc, tuple(point_forces), tuple(cut_torques))


def _moving_wrenches(loads: _Loads, data: mujoco.MjData) -> np.ndarray:
    """``xfrc_applied`` (nbody, 6) at the current pose (``data.xmat`` must be current)."""
    xfrc = loads.xfrc.copy()
    for body, force, point in loads.point_forces:
        xfrc[body, 3:] += np.cross(data.xmat[body].reshape(3, 3) @ point, force)
    for body1, body2, axis, value in loads.cut_torques:
        torque = value * (data.xmat[body1].reshape(3, 3) @ axis)
        xfrc[body2, 3:] += torque
        xfrc[body1, 3:] -= torque
    xfrc[0] = 0.0
    return xfrc


# --------------------------------------------------------------------------------------------
# Initial state: body states -> joint coordinates


def _angle_about(rotation: np.ndarray, axis: np.ndarray) -> float:
    """Angle (rad) of ``rotation`` (3×3), a rotation about unit ``axis``."""
    skew = rotation - rotation.T
    sine = 0.5 * axis @ np.array([skew[2, 1], skew[0, 2], skew[1, 0]])
    return float(np.arctan2(sine, 0.5 * (np.trace(rotation) - 1.0)))


def _joint_coordinates(model: mujoco.MjModel, body: int, rotation: np.ndarray,
                       translation: np.ndarray) -> np.ndarray:
    """``qpos`` entries of body ``body``'s joints for a given motion from the reference.

    Parameters
    ----------
    rotation : ndarray, shape (3, 3)
        Rotation of the child from its reference pose, in its reference frame.
    translation : ndarray, shape (3,)
        Displacement of the child's origin from its reference position, same frame, m.
    """
    start, count = model.body_jntadr[body], model.body_jntnum[body]
    coordinates, remaining = [], rotation
    for joint in range(start, start + count):
        kind, axis = model.jnt_type[joint], model.jnt_axis[joint]
        if kind == mujoco.mjtJoint.mjJNT_SLIDE:
            coordinates.append(axis @ translation)
        elif kind == mujoco.mjtJoint.mjJNT_BALL:
            coordinates.extend(_quat(remaining))
        elif joint + 1 < start + count and model.jnt_type[joint + 1] == mujoco.mjtJoint.mjJNT_HINGE:
            following = model.jnt_axis[joint + 1]
            moved = remaining @ following
            angle = np.arctan2(np.cross(axis, following) @ moved, following @ moved)
            coordinates.append(angle)
            remaining = Rotation.from_rotvec(-angle * axis).as_matrix() @ remaining
        else:
            coordinates.append(_angle_about(remaining, axis))
    return np.array(coordinates)


def _initial_qpos(built: MujocoModel, states: BodyStates) -> np.ndarray:
    """Joint coordinates that put every body at ``states``' pose, shape (nq,)."""
    mech, model = built.mechanism, built.model
    rotations = Rotation.from_quat(states.quaternion, scalar_first=True).as_matrix()
    qpos = model.qpos0.copy()
    for index, body in enumerate(mech.bodies):
        parent = built.tree.parent[body.name]
        if parent == GROUND:
            rot_p, pos_p = np.eye(3), np.zeros(3)
        else:
            rot_p, pos_p = rotations[mech.body_index(parent)], states.position[mech.body_index(parent)]
        mj_body = built.body_ids[index]
        frame = Rotation.from_quat(model.body_quat[mj_body], scalar_first=True).as_matrix()
        relative = frame.T @ rot_p.T @ rotations[index]
        shift = frame.T @ (rot_p.T @ (states.position[index] - pos_p) - model.body_pos[mj_body])
        address = model.jnt_qposadr[model.body_jntadr[mj_body]]
        coordinates = _joint_coordinates(model, mj_body, relative, shift)
        qpos[address:address + len(coordinates)] = coordinates
    return qpos


def _initial_qvel(built: MujocoModel, data: mujoco.MjData, states: BodyStates) -> np.ndarray:
    """Joint rates that reproduce ``states``' velocities (least squares on CoM Jacobians)."""
    model = built.model
    jacobians, targets = [], []
    for index, body in enumerate(built.body_ids):
        jacp, jacr = np.zeros((3, model.nv)), np.zeros((3, model.nv))
        mujoco.mj_jacBodyCom(model, data, jacp, jacr, body)
        jacobians += [jacp, jacr]
        targets += [states.velocity[index], states.angular_velocity[index]]
    solution, *_ = np.linalg.lstsq(np.vstack(jacobians), np.concatenate(targets), rcond=None)
    return solution


def _body_states(built: MujocoModel, model: mujoco.MjModel, data: mujoco.MjData,
                 previous: np.ndarray) -> BodyStates:
    """Body states from ``data.qpos``/``qvel`` (recomputes kinematics and CoM velocities).

    ``previous`` (n_bodies, 4) are the last reported quaternions: each new one takes the sign
    that keeps it on the same hemisphere.
    """
    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)
    mujoco.mj_comVel(model, data)
    ids = built.body_ids
    velocity = np.zeros((len(ids), 6))
    for row, body in zip(velocity, ids):
        mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_BODY, body, row, 0)
    quaternion = data.xquat[ids].copy()
    quaternion *= np.where(np.sum(quaternion * previous, axis=1) < 0.0, -1.0, 1.0)[:, None]
    return BodyStates(position=data.xpos[ids].copy(), quaternion=quaternion,
                      velocity=velocity[:, 3:], angular_velocity=velocity[:, :3])


def _state_mismatch(a: BodyStates, b: BodyStates) -> float:
    """Largest absolute difference between two sets of body states."""
    return max(float(np.max(np.abs(getattr(a, key) - getattr(b, key)), initial=0.0))
               for key in ("position", "quaternion", "velocity", "angular_velocity"))


def _start(built: MujocoModel, model: mujoco.MjModel, data: mujoco.MjData,
           states: BodyStates) -> BodyStates:
    """Set ``data`` to the harness's initial state; returns MuJoCo's own view of it.

    Raises
    ------
    RuntimeError
        If MuJoCo's body states differ from ``states`` by more than :data:`INITIAL_TOLERANCE`.
    """
    data.qpos[:] = _initial_qpos(built, states)
    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)
    data.qvel[:] = _initial_qvel(built, data, states)
    reached = _body_states(built, model, data, states.quaternion)
    mismatch = _state_mismatch(reached, states)
    if mismatch > INITIAL_TOLERANCE:
        raise RuntimeError(f"joint coordinates reproduce the initial body states only to "
                           f"{mismatch:.3g} (> {INITIAL_TOLERANCE:g})")
    return reached


# --------------------------------------------------------------------------------------------
# Stepping


def _diverged(data: mujoco.MjData) -> bool:
    """True when a divergence warning was raised since :func:`_clear_warnings`."""
    return bool(data.warning.number[DIVERGENCE_WARNINGS].any())


def _clear_warnings(data: mujoco.MjData) -> None:
    """Zero the divergence warning counters.

    Comparing counts is not enough: MuJoCo's automatic reset clears the counters before it
    records the warning that caused it, so a second divergence leaves the count at 1.
    """
    data.warning.number[DIVERGENCE_WARNINGS] = 0


def _step_once(model: mujoco.MjModel, data: mujoco.MjData, loads: _Loads) -> None:
    """One step, with the pose-dependent loads refreshed first when there are any."""
    if loads.moving:
        mujoco.mj_kinematics(model, data)
        data.xfrc_applied[:] = _moving_wrenches(loads, data)
    mujoco.mj_step(model, data)


def _first_bad_step(model: mujoco.MjModel, data: mujoco.MjData, loads: _Loads,
                    count: int) -> int | None:
    """Step ``count`` times one by one; the 1-based step that raised a divergence warning."""
    _clear_warnings(data)
    for step in range(1, count + 1):
        _step_once(model, data, loads)
        if _diverged(data):
            return step
    return None


def _advance(model: mujoco.MjModel, data: mujoco.MjData, loads: _Loads, count: int) -> int | None:
    """Take ``count`` steps; the 1-based index of the step that diverged, else None.

    Without pose-dependent loads the steps run inside MuJoCo (``mj_step(nstep=count)``); if that
    raised a warning, the chunk is replayed from a saved state step by step to find which step.
    """
    if loads.moving:
        return _first_bad_step(model, data, loads, count)
    kind = mujoco.mjtState.mjSTATE_INTEGRATION
    saved = np.empty(mujoco.mj_stateSize(model, kind))
    mujoco.mj_getState(model, data, saved, kind)
    _clear_warnings(data)
    mujoco.mj_step(model, data, count)
    if not _diverged(data):
        return None
    mujoco.mj_setState(model, data, saved, kind)
    return _first_bad_step(model, data, loads, count)


# --------------------------------------------------------------------------------------------
# Methods and configuration


def _check_choice(name: str, value: str, choices: dict) -> None:
    """ValueError naming parameter ``name`` unless ``value`` is one of ``choices``."""
    if value not in choices:
        raise ValueError(f"parameter {name!r} must be one of {', '.join(choices)}, got {value!r}")


def _check_params(params: dict) -> None:
    """Validate resolved method parameters, naming the bad one."""
    _check_choice("integrator", params["integrator"], INTEGRATORS)
    _check_choice("solver", params["solver"], SOLVERS)
    for key in ("solimp0", "solimp1"):
        if not 0.0 < params[key] < 1.0:
            raise ValueError(f"parameter {key!r} must lie in (0, 1), got {params[key]!r}")
    for key in ("solref_timeconst", "solimp_width", "tolerance"):
        if params[key] < 0.0:
            raise ValueError(f"parameter {key!r} must be >= 0, got {params[key]!r}")
    for key in ("solref_dampratio", "iterations"):
        if params[key] <= 0:
            raise ValueError(f"parameter {key!r} must be > 0, got {params[key]!r}")


def _configured(model: mujoco.MjModel, params: dict, dt: float) -> mujoco.MjModel:
    """A copy of ``model`` with the method's options and equality softness at step ``dt``."""
    configured = copy.copy(model)
    configured.opt.timestep = dt
    configured.opt.integrator = INTEGRATORS[params["integrator"]]
    configured.opt.solver = SOLVERS[params["solver"]]
    configured.opt.iterations = params["iterations"]
    configured.opt.tolerance = params["tolerance"]
    configured.eq_solref[:] = (params["solref_timeconst"] or 2.0 * dt, params["solref_dampratio"])
    configured.eq_solimp[:] = (params["solimp0"], params["solimp1"], params["solimp_width"],
                               *SOLIMP_SHAPE)
    return configured


def _method_specs() -> list[MethodSpec]:
    """``default``, ``best`` and every integrator with each softness preset."""
    def spec(name, description, integrator, softness):
        params = {"integrator": integrator, **SOFTNESS[softness], **SOLVER_DEFAULTS}
        return MethodSpec(name, description, params)

    specs = [spec("default", "MuJoCo's defaults: Euler, default equality softness "
                  "(solref 0.02 s / 1, solimp 0.9 / 0.95 / 0.001)", "Euler", "default"),
             spec("best", "RK4 with near-rigid equalities (solref time constant 2·dt, solimp "
                  "0.9999 / 0.9999 / 0.001)", "RK4", "tight")]
    for integrator in INTEGRATORS:
        specs.append(spec(integrator.lower(), f"{integrator} with MuJoCo's default equality "
                          f"softness", integrator, "default"))
        specs.append(spec(f"{integrator.lower()}-tight", f"{integrator} with near-rigid "
                          f"equalities (solref 2·dt, solimp 0.9999)", integrator, "tight"))
    return specs


def _sample_steps(dt: float, t_end: float, sample_times) -> tuple[np.ndarray, int]:
    """Step index of each sample time and the total number of steps.

    Raises
    ------
    ValueError
        Naming ``dt``, ``t_end`` or ``sample_times`` when they are not usable.
    """
    if not dt > 0.0:
        raise ValueError(f"dt must be > 0, got {dt!r}")
    if not t_end > 0.0:
        raise ValueError(f"t_end must be > 0, got {t_end!r}")
    times = np.asarray(sample_times, dtype=float)
    steps = np.rint(times / dt).astype(int)
    n_steps = int(round(t_end / dt))
    if times.ndim != 1 or np.any(np.abs(steps * dt - times) > 1e-9 * np.maximum(1.0, times)):
        raise ValueError("sample_times must be a 1-D array of integer multiples of dt")
    if np.any(np.diff(steps) < 0) or np.any(steps < 0) or np.any(steps > n_steps):
        raise ValueError("sample_times must be increasing and lie in [0, t_end]")
    return steps, n_steps


def _notes(built: MujocoModel, model: mujoco.MjModel) -> list[str]:
    """Facts a reader of a run must know."""
    notes = []
    redundant = built.tree.redundant_closure_equations
    if redundant > 0:
        notes.append(f"{redundant} redundant closure equation(s)")
    if model.neq:
        solref = ", ".join(f"{value:g}" for value in model.eq_solref[0])
        solimp = ", ".join(f"{value:g}" for value in model.eq_solimp[0])
        notes.append(f"equality solref ({solref}), solimp ({solimp}); MuJoCo's refsafe clamps "
                     f"the time constant to >= 2·dt")
    if built.loads.moving:
        notes.append("pose-dependent loads (cut-joint actuation, off-centre forces) are "
                     "recomputed once per step and held constant within it")
    return notes


# --------------------------------------------------------------------------------------------
# The adapter


class MujocoAdapter(Adapter):
    """MuJoCo through its spec API (see the module docstring for the model and methods)."""

    name = "mujoco"

    def version(self) -> str:
        return f"mujoco {mujoco.__version__}"

    def methods(self) -> list[MethodSpec]:
        return _method_specs()

    def build(self, mechanism: Mechanism) -> MujocoModel:
        """Compile ``mechanism``; raises :class:`UnsupportedCase` for unclosable cut joints."""
        tree = spanning_tree(mechanism, lambda joint: closure_equations(mechanism, joint))
        spec = _make_spec(mechanism, tree)
        model = spec.compile()
        body_ids = np.array([model.body(body.name).id for body in mechanism.bodies])
        return MujocoModel(mechanism, tree, spec, model, body_ids, _loads(mechanism, tree, model))

    def simulate(self, model: MujocoModel, method: str, dt: float, t_end: float,
                 sample_times) -> Trajectory:
        """Run ``method`` at step ``dt`` (s) to ``t_end`` (s) from the harness's initial state.

        Returns a :class:`Trajectory` sampled after step ``round(t / dt)`` of each sample time;
        ``diverged`` (with ``failure_time``) when MuJoCo raises a bad-qpos/qvel/qacc warning,
        ``failed`` when the engine raises.  Raises ValueError for an unknown method, a bad
        parameter or unusable times.
        """
        _, params = self.method_spec(method)
        _check_params(params)
        steps, n_steps = _sample_steps(dt, t_end, sample_times)
        return _Run(model, params, dt).run(np.asarray(sample_times, dtype=float), steps, n_steps)


class _Run:
    """One simulation: the configured model, its data and the samples collected so far."""

    def __init__(self, built: MujocoModel, params: dict, dt: float):
        self.built, self.dt = built, dt
        self.model = _configured(built.model, params, dt)
        self.data = mujoco.MjData(self.model)
        self.data.qfrc_applied[:] = built.loads.qfrc
        self.data.xfrc_applied[:] = built.loads.xfrc
        self.stages = STAGES[params["integrator"]]
        self.states: list[BodyStates] = []
        self.wall, self.done = 0.0, 0

    def run(self, times: np.ndarray, steps: np.ndarray, n_steps: int) -> Trajectory:
        """Step through every sample, then on to ``n_steps``; failures become a status."""
        try:
            previous = _start(self.built, self.model, self.data,
                              initial_state(self.built.mechanism)).quaternion
            for target in (*steps, n_steps):
                bad = self._advance_to(int(target))
                if bad is not None:
                    return self._trajectory(times, "diverged", "MuJoCo raised a bad qpos/qvel/"
                                            "qacc warning (it would reset and carry on)",
                                            bad * self.dt)
                if len(self.states) < len(steps):
                    self.states.append(_body_states(self.built, self.model, self.data, previous))
                    previous = self.states[-1].quaternion
        except Exception as error:  # an engine failure is a result, not a crash (DESIGN rule 5)
            return self._trajectory(times, "failed", f"{type(error).__name__}: {error}",
                                    self.done * self.dt)
        return self._trajectory(times, "ok", "", None)

    def _advance_to(self, target: int) -> int | None:
        """Step until ``target`` steps are done; the global index of a diverged step, else None."""
        count = target - self.done
        if count <= 0:
            return None
        start = time.perf_counter()
        bad = _advance(self.model, self.data, self.built.loads, count)
        self.wall += time.perf_counter() - start
        if bad is not None:
            self.done += bad
            return self.done
        self.done = target
        return None

    def _trajectory(self, times, status: str, reason: str, failure_time) -> Trajectory:
        kwargs = dict(status=status, reason=reason, failure_time=failure_time,
                      wall_time_s=self.wall, steps=self.done,
                      counters={"rhs_evals": self.done * self.stages},
                      notes=_notes(self.built, self.model))
        if not self.states:
            return Trajectory.empty(len(self.built.mechanism.bodies), **kwargs)
        return Trajectory.from_samples(times, self.states, **kwargs)


def export_mjcf(mech: Mechanism) -> str:
    """The MJCF text of the model :meth:`MujocoAdapter.build` makes for ``mech``.

    Raises
    ------
    UnsupportedCase
        When MuJoCo cannot represent ``mech``.
    """
    return MujocoAdapter().build(mech).spec.to_xml()
