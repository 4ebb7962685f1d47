"""Exudyn adapter: the scenario in redundant absolute coordinates, solved by Exudyn's implicit
second-order integrators at fixed steps.

Like the in-house formulation, Exudyn needs no spanning tree: every body is a node with its own
coordinates and every scenario joint becomes one Exudyn constraint.

Model translation
-----------------
* Planar scenarios: ``NodeRigidBody2D`` + ``ObjectRigidBody2D`` (x, y, φ per body),
  ``ObjectJointRevolute2D`` and ``ObjectJointPrismatic2D``.
* Spatial scenarios: ``NodeRigidBodyEP`` (Euler parameters, with Exudyn's own normalisation
  constraint) or ``NodeRigidBodyRotVecLG`` (rotation vector, Lie-group update), chosen by the
  method parameter ``rotation``; ``ObjectJointRevoluteZ``, ``ObjectJointSpherical`` and
  ``ObjectJointGeneric`` with ``constrainedAxes`` for the cylindrical, universal and
  prismatic/translational joints.  The joint frames are given to the markers as their ``localHT``.
* Gravity: ``LoadMassProportional``; joint actuation: body-fixed ``LoadTorqueVector`` /
  ``LoadForceVector`` pairs (they follow the joint axis); body forces and torques: world-fixed
  loads; spring-dampers: ``ObjectConnectorSpringDamper``.  Nothing else (no damping, no
  stabilisation springs).

Every run builds a fresh ``SystemContainer`` whose reference configuration is the harness's
assembled start (:func:`harness.initial.initial_state`), so displacement-type outputs of Exudyn are
never needed: the body states are read through ``SensorBody`` (``storeInternal=True``) as world
position, rotation matrix, velocity and angular velocity.

Methods
-------
``default``
    Exudyn's ``SolveDynamic`` defaults at fixed steps: generalized-α (index 3), spectral radius
    0.9, modified Newton, relative/absolute tolerance 1e-8/1e-10, at most 25 iterations.
``newmark``
    Newmark (``useNewmark``) with Exudyn's default β = 1/4, γ = 1/2, index 3; ``index2=true``
    switches to velocity-level constraints (Exudyn allows index 2 only with Newmark).
``trapezoidal``
    What Exudyn's ``TrapezoidalIndex2`` sets: Newmark β = 1/4, γ = 1/2 with index-2 constraints.
``best``
    The most accurate settings measured at a given step (see :data:`_BEST`).

Exudyn's explicit solvers are not offered: with ``eliminateConstraints=True`` they refuse these
constraints, and with ``eliminateConstraints=False`` they silently ignore the joints.
"""

from __future__ import annotations

import contextlib
import itertools
import math
import time
from dataclasses import dataclass

import exudyn as exu
import exudyn.itemInterface as eii
import numpy as np
from scipy.spatial.transform import Rotation

from adapters.base import Adapter, MethodSpec, UnsupportedCase
from harness.initial import initial_state
from harness.model import (
    GROUND,
    PLANAR_JOINT_TYPES,
    BodyForce,
    BodyTorque,
    Joint,
    JointActuation,
    Mechanism,
    SpringDamper,
)
from harness.trajectory import Trajectory

#: Newton and integrator settings shared by every method; the values are Exudyn's defaults for
#: ``SolveDynamic`` (``exu.SimulationSettings().timeIntegration``), read from exudyn 1.13.6.
_COMMON_PARAMS = {
    "rtol": 1e-8,              # newton.relativeTolerance
    "atol": 1e-10,             # newton.absoluteTolerance
    "max_iter": 25,            # newton.maxIterations
    "modified_newton": True,   # newton.useModifiedNewton
    "rotation": "ep",          # spatial nodes: "ep" (NodeRigidBodyEP) or "rotvec" (RotVecLG)
    "ignore_singular": False,  # ignoreSingularJacobian with EigenDense (redundant constraints)
}
_ROTATIONS = ("ep", "rotvec")
#: Generalized-α (index 3): Exudyn's default spectralRadius.
_GENALPHA_PARAMS = {"rho_inf": 0.9, **_COMMON_PARAMS}
#: Newmark: Exudyn's default newmarkBeta/newmarkGamma (undamped trapezoidal rule), index 3.
_NEWMARK_PARAMS = {"beta": 0.25, "gamma": 0.5, "index2": False, **_COMMON_PARAMS}
#: The most accurate settings measured (see tests/test_exudyn_adapter.py).
_BEST = {**_GENALPHA_PARAMS, "rtol": 1e-12, "atol": 1e-12, "modified_newton": False,
         "ignore_singular": True}

_SENSED = ("Position", "RotationMatrix", "Velocity", "AngularVelocity")


@dataclass(frozen=True)
class ExudynModel:
    """What :meth:`ExudynAdapter.build` returns: the mechanism, checked for Exudyn.

    Each :meth:`ExudynAdapter.simulate` call builds a fresh Exudyn system from it, so one model
    serves any number of runs.

    Attributes
    ----------
    mechanism : Mechanism
    _unenforced_joints : bool
        Test-only hook: run Exudyn's explicit RK4 with ``eliminateConstraints=False``, the known
        trap in which Exudyn ignores every joint while reporting success.  Never offered as a method.
    """

    mechanism: Mechanism
    _unenforced_joints: bool = False


class ExudynAdapter(Adapter):
    """Exudyn (redundant absolute coordinates, implicit index-3/index-2 integrators)."""

    name = "exudyn"

    def version(self) -> str:
        return f"exudyn {exu.__version__}"

    def methods(self) -> list[MethodSpec]:
        return [
            MethodSpec("default", "Exudyn SolveDynamic defaults at fixed steps: generalized-alpha "
                       "(index 3), spectral radius 0.9, modified Newton", dict(_GENALPHA_PARAMS)),
            MethodSpec("newmark", "Newmark (useNewmark), index 3 unless index2=true; "
                       "gamma > 1/2 damps and is first order", dict(_NEWMARK_PARAMS)),
            MethodSpec("trapezoidal", "Exudyn TrapezoidalIndex2: undamped Newmark (beta=1/4, "
                       "gamma=1/2) with index-2 constraints", {**_NEWMARK_PARAMS, "index2": True}),
            MethodSpec("best", "most accurate measured: generalized-alpha (index 3), full Newton, "
                       "tolerances 1e-12", dict(_BEST)),
        ]

    def build(self, mechanism: Mechanism) -> ExudynModel:
        """Check that Exudyn can represent ``mechanism``.

        Raises
        ------
        UnsupportedCase
            A planar scenario with a joint type Exudyn has no 2D joint for.
        """
        if mechanism.planar:
            for joint in mechanism.joints:
                if joint.type not in PLANAR_JOINT_TYPES:
                    raise UnsupportedCase(f"planar joint {joint.name!r} of type {joint.type!r}: "
                                          f"Exudyn 2D joints are {', '.join(PLANAR_JOINT_TYPES)}")
        return ExudynModel(mechanism)

    def simulate(self, model: ExudynModel, method: str, dt: float, t_end: float,
                 sample_times: np.ndarray) -> Trajectory:
        """Run ``model`` with ``method`` at the fixed step ``dt`` up to ``t_end``.

        Parameters
        ----------
        model : ExudynModel
        method : str
            ``NAME[:key=value,...]``, see :meth:`methods`.
        dt, t_end : float
            Step and end time, s; ``round(t_end / dt)`` steps are taken.
        sample_times : ndarray, shape (n_samples,)
            Integer multiples of ``dt`` (0 included); the state after step ``round(t / dt)`` is
            recorded for each.

        Returns
        -------
        Trajectory
            ``failed`` when Exudyn raises (e.g. Newton does not converge), ``diverged`` when the
            states stop being finite; the samples reached are kept.
        """
        spec, params = self.method_spec(method)
        _validate_run(dt, t_end, sample_times)
        _validate_params(params)
        mech = model.mechanism
        steps = round(t_end / dt)
        indices = np.rint(np.asarray(sample_times, dtype=float) / dt).astype(int)
        notes = _notes(mech, spec.name, params)
        with _quiet():
            try:
                system = ExudynSystem(mech, params["rotation"])
                settings = _settings(params, dt, steps, _write_period(indices, dt))
            except Exception as error:  # engine exceptions are results (DESIGN rule 5)
                return Trajectory.empty(len(mech.bodies), status="failed",
                                        reason=f"model rejected: {_describe(error)}",
                                        failure_time=0.0, notes=notes)
            solver = _unenforced_solver(settings) if model._unenforced_joints \
                else exu.MainSolverImplicitSecondOrder()
            run = system.run(solver, settings, dt)
        return system.trajectory(run, indices, dt, notes)


# ---------------------------------------------------------------------------------------------
# validation


def _validate_run(dt: float, t_end: float, sample_times) -> None:
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be a positive finite step, got {dt!r}")
    if not (np.isfinite(t_end) and round(t_end / dt) >= 1):
        raise ValueError(f"t_end must be a finite time of at least one step dt, got {t_end!r}")
    times = np.asarray(sample_times, dtype=float)
    if times.ndim != 1 or times.size == 0:
        raise ValueError("sample_times must be a non-empty 1-D array of times")
    k = times / dt
    if np.any(np.abs(k - np.rint(k)) > 1e-6) or np.any(times < 0) or np.any(times > t_end + dt / 2):
        raise ValueError("sample_times must be integer multiples of dt within [0, t_end]")


def _validate_params(params: dict) -> None:
    if params.get("rotation", "ep") not in _ROTATIONS:
        raise ValueError(f"parameter 'rotation' must be one of {', '.join(_ROTATIONS)}, "
                         f"got {params['rotation']!r}")
    if "rho_inf" in params and not 0.0 <= params["rho_inf"] <= 1.0:
        raise ValueError(f"parameter 'rho_inf' must lie in [0, 1], got {params['rho_inf']!r}")
    if "gamma" in params and not (params["gamma"] >= 0.5 and params["beta"] > 0):
        raise ValueError(f"parameters 'beta' > 0 and 'gamma' >= 1/2 required, got "
                         f"beta={params['beta']!r}, gamma={params['gamma']!r}")
    for key in ("rtol", "atol"):
        if not params[key] > 0:
            raise ValueError(f"parameter {key!r} must be positive, got {params[key]!r}")
    if params["max_iter"] < 1:
        raise ValueError(f"parameter 'max_iter' must be at least 1, got {params['max_iter']!r}")


def _notes(mech: Mechanism, name: str, params: dict) -> list[str]:
    if mech.planar:
        return [f"exudyn {name}: planar model with NodeRigidBody2D "
                f"(parameter 'rotation' is not used)"]
    node = "NodeRigidBodyEP" if params["rotation"] == "ep" else "NodeRigidBodyRotVecLG"
    return [f"exudyn {name}: spatial model with {node}"]


# ---------------------------------------------------------------------------------------------
# settings


def _write_period(indices: np.ndarray, dt: float) -> float:
    """Sensor period: the largest multiple of ``dt`` that hits every sampled step, s."""
    steps = int(np.gcd.reduce(indices[indices > 0])) if np.any(indices > 0) else 1
    return steps * dt


def _settings(params: dict, dt: float, steps: int,
              write_period: float) -> exu.SimulationSettings:
    """Exudyn settings for ``steps`` fixed steps of ``dt``: generalized-α when ``params`` has
    ``rho_inf``, Newmark otherwise."""
    settings = exu.SimulationSettings()
    settings.solution.file.write = False
    settings.solution.sensors.writePeriod = write_period
    settings.show.statistics = False
    settings.show.computationTime = False
    if params["ignore_singular"]:
        # only honoured by Eigen's full-pivot LU: with the default EXUdense it has no effect
        settings.linearSolver.solverType = exu.LinearSolverType.EigenDense
        settings.linearSolver.ignoreSingularJacobian = True
    integration = settings.timeIntegration
    integration.verboseMode = 0
    integration.startTime = 0.0
    integration.endTime = steps * dt
    integration.numberOfSteps = steps
    integration.adaptiveStep = False
    integration.automaticStepSize = False
    newton = integration.newton
    newton.relativeTolerance = params["rtol"]
    newton.absoluteTolerance = params["atol"]
    newton.maxIterations = params["max_iter"]
    newton.useModifiedNewton = params["modified_newton"]
    alpha = integration.generalizedAlpha
    integration.solverType = exu.DynamicSolverType.GeneralizedAlpha
    if "rho_inf" in params:
        alpha.spectralRadius = params["rho_inf"]
    else:
        alpha.useNewmark = True
        alpha.newmarkBeta = params["beta"]
        alpha.newmarkGamma = params["gamma"]
        alpha.useIndex2Constraints = params["index2"]
    return settings


def _unenforced_solver(settings: exu.SimulationSettings) -> exu.MainSolverExplicit:
    """The trap the tests must catch: explicit RK4 that drops the constraints without a word."""
    settings.timeIntegration.solverType = exu.DynamicSolverType.RK44
    settings.timeIntegration.explicit.eliminateConstraints = False
    return exu.MainSolverExplicit()


@contextlib.contextmanager
def _quiet():
    """Keep Exudyn from printing to the console for the duration of a run."""
    previous = exu.config.printToConsole
    exu.config.printToConsole = False
    try:
        yield
    finally:
        exu.config.printToConsole = previous


def _describe(error: BaseException) -> str:
    text = " ".join(str(error).split())
    return f"{type(error).__name__}: {text[:300]}"


# ---------------------------------------------------------------------------------------------
# kinematic helpers


def _frame(first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """Right-handed rotation matrix with columns ``first``, ``second``, ``first × second``."""
    x = np.asarray(first, dtype=float)
    y = np.asarray(second, dtype=float)
    return np.column_stack([x, y, np.cross(x, y)])


def _joint_frames(joint: Joint) -> tuple[np.ndarray, np.ndarray]:
    """Joint frames (body frame → joint frame) on ``body1`` and ``body2``, shape (3, 3) each.

    ``ObjectJointRevoluteZ`` and a cylindrical ``ObjectJointGeneric`` turn about the frames' z;
    a prismatic/translational generic joint slides along x; a universal generic joint keeps
    body1's y perpendicular to body2's z (Exudyn's one-locked-rotation equation).
    """
    if joint.type in ("revolute", "cylindrical", "spherical"):
        return (_frame(joint.normal1, np.cross(joint.axis1, joint.normal1)),
                _frame(joint.normal2, np.cross(joint.axis2, joint.normal2)))
    if joint.type in ("prismatic", "translational"):
        return _frame(joint.axis1, joint.normal1), _frame(joint.axis2, joint.normal2)
    if joint.type == "universal":
        return (_frame(joint.normal1, joint.axis1),
                _frame(joint.normal2, np.cross(joint.axis2, joint.normal2)))
    raise ValueError(f"joint {joint.name!r}: unknown type {joint.type!r}")


#: constrainedAxes of ObjectJointGeneric per joint type (translations x, y, z; rotations x, y, z).
_GENERIC_AXES = {
    "cylindrical": [1, 1, 0, 1, 1, 0],
    "prismatic": [0, 1, 1, 1, 1, 1],
    "translational": [0, 1, 1, 1, 1, 1],
    "universal": [1, 1, 1, 1, 0, 0],
}


def _quaternion_rate(quaternion: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """Euler-parameter rates θ̇ = ½ [0, ω] ⊗ θ for a world angular velocity, shape (4,)."""
    w, x, y, z = quaternion
    wx, wy, wz = omega
    return 0.5 * np.array([-wx * x - wy * y - wz * z,
                           wx * w + wy * z - wz * y,
                           -wx * z + wy * w + wz * x,
                           wx * y - wy * x + wz * w])


def _quaternions(rotations: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Scalar-first quaternions of ``rotations`` (shape (n, 3, 3)), signs continuous from
    ``reference`` (shape (4,)); shape (n, 4)."""
    quats = Rotation.from_matrix(rotations).as_quat(scalar_first=True)
    previous = reference
    for i, quat in enumerate(quats):
        if np.dot(quat, previous) < 0:
            quats[i] = -quat
        previous = quats[i]
    return quats


# ---------------------------------------------------------------------------------------------
# the Exudyn system of one run


@dataclass
class _Run:
    """How the stepping ended: status, reason, failure time, wall time and solver counters."""

    status: str
    reason: str
    failure_time: float | None
    wall_time_s: float
    counters: dict
    steps: int


class ExudynSystem:
    """One Exudyn ``SystemContainer`` holding ``mech`` at its assembled start."""

    def __init__(self, mech: Mechanism, rotation: str):
        self.mech = mech
        self.rotation = rotation
        self.start = initial_state(mech)
        self.container = exu.SystemContainer()
        self.mbs = self.container.AddSystem()
        self.ground = self.mbs.AddObject(eii.ObjectGround())
        self.bodies = [self._add_body(i) for i in range(len(mech.bodies))]
        for joint in mech.joints:
            self._add_joint(joint)
        self._add_gravity()
        for force in mech.forces:
            self._add_force(force)
        self.sensors = {key: [self._add_sensor(body, key) for body in self.bodies]
                        for key in _SENSED}
        self.mbs.Assemble()

    # --- bodies -------------------------------------------------------------------------------

    def _add_body(self, index: int):
        body = self.mech.bodies[index]
        p = self.start.position[index]
        q = self.start.quaternion[index]
        v = self.start.velocity[index]
        w = self.start.angular_velocity[index]
        if self.mech.planar:
            angle = 2.0 * math.atan2(q[3], q[0])
            node = self.mbs.AddNode(eii.NodeRigidBody2D(referenceCoordinates=[p[0], p[1], angle],
                                                        initialVelocities=[v[0], v[1], w[2]]))
            return self.mbs.AddObject(eii.ObjectRigidBody2D(mass=body.mass,
                                                            inertia=body.inertia[2, 2],
                                                            nodeNumber=node))
        if self.rotation == "ep":
            node = eii.NodeRigidBodyEP(referenceCoordinates=[*p, *q],
                                       initialVelocities=[*v, *_quaternion_rate(q, w)])
        else:
            rotation = Rotation.from_quat(q, scalar_first=True)
            local_omega = rotation.inv().apply(w)
            node = eii.NodeRigidBodyRotVecLG(referenceCoordinates=[*p, *rotation.as_rotvec()],
                                             initialVelocities=[*v, *local_omega])
        inertia = np.asarray(body.inertia, dtype=float)
        return self.mbs.AddObject(eii.ObjectRigidBody(
            mass=body.mass, nodeNumber=self.mbs.AddNode(node),
            inertia=[inertia[0, 0], inertia[1, 1], inertia[2, 2],
                     inertia[1, 2], inertia[0, 2], inertia[0, 1]]))

    def _object(self, name: str):
        return self.ground if name == GROUND else self.bodies[self.mech.body_index(name)]

    # --- markers ------------------------------------------------------------------------------

    def _point_marker(self, body: str, point: np.ndarray):
        return self.mbs.AddMarker(eii.MarkerBodyPosition(bodyNumber=self._object(body),
                                                         localPosition=list(point)))

    def _frame_marker(self, body: str, point: np.ndarray, rotation=np.eye(3)):
        ht = exu.HT(rotation=np.asarray(rotation), translation=list(point))
        return self.mbs.AddMarker(eii.MarkerBodyRigid(bodyNumber=self._object(body), localHT=ht))

    # --- joints -------------------------------------------------------------------------------

    def _add_joint(self, joint: Joint) -> None:
        if self.mech.planar:
            self._add_planar_joint(joint)
        elif joint.type == "spherical":
            markers = [self._point_marker(joint.body1, joint.point1),
                       self._point_marker(joint.body2, joint.point2)]
            self.mbs.AddObject(eii.ObjectJointSpherical(name=joint.name, markerNumbers=markers))
        else:
            frame1, frame2 = _joint_frames(joint)
            markers = [self._frame_marker(joint.body1, joint.point1, frame1),
                       self._frame_marker(joint.body2, joint.point2, frame2)]
            if joint.type == "revolute":
                item = eii.ObjectJointRevoluteZ(name=joint.name, markerNumbers=markers)
            else:
                item = eii.ObjectJointGeneric(name=joint.name, markerNumbers=markers,
                                              constrainedAxes=_GENERIC_AXES[joint.type])
            self.mbs.AddObject(item)

    def _add_planar_joint(self, joint: Joint) -> None:
        if joint.type == "revolute":
            markers = [self._point_marker(joint.body1, joint.point1),
                       self._point_marker(joint.body2, joint.point2)]
            self.mbs.AddObject(eii.ObjectJointRevolute2D(name=joint.name, markerNumbers=markers))
            return
        markers = [self._frame_marker(joint.body1, joint.point1),
                   self._frame_marker(joint.body2, joint.point2)]
        self.mbs.AddObject(eii.ObjectJointPrismatic2D(
            name=joint.name, markerNumbers=markers, axisMarker0=list(joint.axis1),
            normalMarker1=list(joint.normal2), constrainRotation=True))

    # --- forces -------------------------------------------------------------------------------

    def _add_gravity(self) -> None:
        for body in self.bodies:
            marker = self.mbs.AddMarker(eii.MarkerBodyMass(bodyNumber=body))
            self.mbs.AddLoad(eii.LoadMassProportional(markerNumber=marker,
                                                      loadVector=list(self.mech.gravity)))

    def _add_force(self, force) -> None:
        if isinstance(force, JointActuation):
            self._add_actuation(force)
        elif isinstance(force, BodyForce):
            self._load(eii.LoadForceVector, force.body, force.point, force.force, body_fixed=False)
        elif isinstance(force, BodyTorque):
            self._load(eii.LoadTorqueVector, force.body, np.zeros(3), force.torque,
                       body_fixed=False)
        elif isinstance(force, SpringDamper):
            markers = [self._point_marker(force.body1, force.point1),
                       self._point_marker(force.body2, force.point2)]
            self.mbs.AddObject(eii.ObjectConnectorSpringDamper(
                name=force.name, markerNumbers=markers, referenceLength=force.free_length,
                stiffness=force.stiffness, damping=force.damping))
        else:
            raise TypeError(f"force {force!r}: unknown force type {type(force).__name__}")

    def _add_actuation(self, actuation: JointActuation) -> None:
        """Equal and opposite follower loads about/along the joint axis: body2 gets +value,
        body1 the reaction; each load is fixed in the body frame that holds its axis."""
        joint = self.mech.joint(actuation.joint)
        load = eii.LoadTorqueVector if joint.type in ("revolute", "cylindrical") \
            else eii.LoadForceVector
        sides = ((joint.body2, joint.point2, joint.axis2, actuation.value),
                 (joint.body1, joint.point1, joint.axis1, -actuation.value))
        for body, point, axis, value in sides:
            if body != GROUND:
                self._load(load, body, point, value * np.asarray(axis), body_fixed=True)

    def _load(self, load_type, body: str, point: np.ndarray, vector: np.ndarray,
              body_fixed: bool) -> None:
        marker = self._frame_marker(body, point)
        self.mbs.AddLoad(load_type(markerNumber=marker, loadVector=list(vector),
                                   bodyFixed=body_fixed))

    # --- sensors ------------------------------------------------------------------------------

    def _add_sensor(self, body, key: str):
        return self.mbs.AddSensor(eii.SensorBody(
            bodyNumber=body, localPosition=[0.0, 0.0, 0.0], writeToFile=False,
            storeInternal=True, outputVariableType=getattr(exu.OutputVariableType, key)))

    # --- running ------------------------------------------------------------------------------

    def run(self, solver, settings: exu.SimulationSettings, dt: float) -> _Run:
        """Take the fixed steps ``dt`` (s) of ``settings`` with ``solver``; an exception or a
        reported failure becomes a ``failed`` :class:`_Run` whose failure time is the end of the
        step that failed."""
        start = time.perf_counter()
        try:
            success = solver.SolveSystem(self.mbs, settings)
            reason = "" if success else f"exudyn solver failed: {solver.GetErrorString()}"
        except Exception as error:  # Newton failure etc. are results (DESIGN rule 5)
            success, reason = False, _describe(error)
        wall = time.perf_counter() - start
        if success:
            return _Run("ok", "", None, wall, _counters(solver),
                        int(settings.timeIntegration.numberOfSteps))
        failure_time = float(solver.it.currentTime)
        return _Run("failed", reason, failure_time, wall, _counters(solver),
                    max(round(failure_time / dt) - 1, 0))

    def trajectory(self, run: _Run, indices: np.ndarray, dt: float,
                   notes: list[str]) -> Trajectory:
        """Samples at steps ``indices`` from the sensors, with the run's status."""
        data = {key: self._stored(key) for key in _SENSED}
        stored_times = data["Position"][:, 0, 0] if data["Position"].size else np.zeros(0)
        row_of = {int(step): row for row, step in enumerate(np.rint(stored_times / dt))}
        rows = list(itertools.takewhile(lambda row: row is not None,
                                        (row_of.get(int(step)) for step in indices)))
        reached = len(rows)
        rotations = data["RotationMatrix"][rows, :, 1:10].reshape(reached, -1, 3, 3)
        arrays = {
            "position": data["Position"][rows, :, 1:4],
            "quaternion": np.stack([_quaternions(rotations[:, b], self.start.quaternion[b])
                                    for b in range(len(self.bodies))], axis=1),
            "velocity": data["Velocity"][rows, :, 1:4],
            "angular_velocity": data["AngularVelocity"][rows, :, 1:4],
        }
        status, reason, failure_time = run.status, run.reason, run.failure_time
        finite = np.all([np.isfinite(a).all(axis=(1, 2)) for a in arrays.values()], axis=0)
        if not finite.all():
            reached = int(np.argmin(finite))
            status, reason = "diverged", "non-finite body states"
            failure_time = float(indices[reached] * dt)
        elif status == "ok" and reached < len(indices):
            status = "failed"
            reason = f"exudyn stored no sensor sample for t = {indices[reached] * dt:g} s"
        return Trajectory(
            times=indices[:reached] * dt,
            **{key: value[:reached] for key, value in arrays.items()},
            status=status, reason=reason, failure_time=failure_time,
            wall_time_s=run.wall_time_s, steps=run.steps, counters=run.counters, notes=notes)

    def _stored(self, key: str) -> np.ndarray:
        """Stored sensor rows of every body, shape (n_rows, n_bodies, 1 + n_values)."""
        return np.stack([np.asarray(self.mbs.GetSensorStoredData(sensor))
                         for sensor in self.sensors[key]], axis=1)


def _counters(solver) -> dict:
    """Exudyn's solver statistics as harness cost counters."""
    it = solver.it
    return {"newton_iterations": int(it.newtonStepsCount),
            "jacobian_evals": int(it.newtonJacobiCount),
            "rejected_modified_newton_steps": int(it.rejectedModifiedNewtonSteps)}
