"""The Exudyn system of one run: :class:`ExudynSystem` translates the mechanism into a fresh
``SystemContainer`` at the harness's assembled start, runs a solver on it and reads the sensed body
states back as :class:`~mbh._harness.model.trajectory.BodyStates` per stored step.

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
assembled start (:func:`mbh._harness.neutral.start.initial_state`), so displacement-type outputs of Exudyn are
never needed: the body states are read through ``SensorBody`` (``storeInternal=True``) as world
position, rotation matrix, velocity and angular velocity.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import exudyn as exu
import exudyn.itemInterface as eii
import numpy as np
from scipy.spatial.transform import Rotation

from mbh._adapters.exudyn_adapter.state import _quaternion_rate, _quaternions
from mbh._harness.neutral.start import initial_state
from mbh._harness.model.mechanism import (
    GROUND,
    BodyForce,
    BodyTorque,
    Joint,
    JointActuation,
    Mechanism,
    SpringDamper,
)
from mbh._harness.common.status import CaseStatus
from mbh._harness.model.trajectory import BodyStates

_SENSED = ("Position", "RotationMatrix", "Velocity", "AngularVelocity")


def _describe(error: BaseException) -> str:
    text = " ".join(str(error).split())
    return f"{type(error).__name__}: {text[:300]}"


# ---------------------------------------------------------------------------------------------
# joint frames


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


# ---------------------------------------------------------------------------------------------
# the Exudyn system of one run


@dataclass
class _Run:
    """How the stepping ended: status, reason, the last good time and solver counters.

    Attributes
    ----------
    t_good : float or None
        Time of the last completed step of a failed run, s (None when it ran to the end).
    """

    status: CaseStatus
    reason: str
    t_good: float | None
    counters: dict
    steps: int


class ExudynSystem:
    """One Exudyn ``SystemContainer`` holding ``mech`` at its assembled start.

    Parameters
    ----------
    mech : Mechanism
    rotation : {"ep", "rotvec"}
        Node type of spatial bodies (see the module notes).
    sensors : bool
        Add the body sensors :meth:`sensed` reads (False: a system that is only solved, for
        :meth:`~mbh._adapters.exudyn_adapter.adapter.ExudynAdapter.bare_loop`).
    """

    def __init__(self, mech: Mechanism, rotation: str, sensors: bool = True):
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
                        for key in (_SENSED if sensors else ())}
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

    def _frame_marker(self, body: str, point: np.ndarray, rotation=np.eye(3)):  # noqa: B008
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
            # The in-plane normal: the joint's own normal may be z (perpendicular to an in-plane
            # axis too), which would leave the slide line unconstrained.
            normalMarker1=list(np.cross([0.0, 0.0, 1.0], joint.axis2)), constrainRotation=True))

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
        reported failure becomes a ``failed`` :class:`_Run` whose last good time is the end of
        the step before the one that failed (Exudyn's ``currentTime`` is the failed step's end)."""
        try:
            success = solver.SolveSystem(self.mbs, settings)
            reason = "" if success else f"exudyn solver failed: {solver.GetErrorString()}"
        except Exception as error:  # noqa: BLE001 — Newton failures are results (rule 6)
            success, reason = False, _describe(error)
        if success:
            return _Run(CaseStatus.OK, "", None, _counters(solver),
                        int(settings.timeIntegration.numberOfSteps))
        steps = max(round(float(solver.it.currentTime) / dt) - 1, 0)
        return _Run(CaseStatus.FAILED, reason, steps * dt, _counters(solver), steps)

    def sensed(self, dt: float) -> dict[int, BodyStates]:
        """Body states of every stored sensor row, keyed by step index round(t / dt)."""
        data = {key: self._stored(key) for key in _SENSED}
        if not data["Position"].size:
            return {}
        rotations = data["RotationMatrix"][:, :, 1:10].reshape(len(data["Position"]), -1, 3, 3)
        quaternions = np.stack([_quaternions(rotations[:, b], self.start.quaternion[b])
                                for b in range(len(self.bodies))], axis=1)
        steps = np.rint(data["Position"][:, 0, 0] / dt).astype(int)
        return {int(step): BodyStates(data["Position"][row, :, 1:4], quaternions[row],
                                      data["Velocity"][row, :, 1:4],
                                      data["AngularVelocity"][row, :, 1:4])
                for row, step in enumerate(steps)}

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
