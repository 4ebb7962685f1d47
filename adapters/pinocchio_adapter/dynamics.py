"""The equations of motion of a :class:`PinocchioModel` as a second-order problem.

:class:`ConstrainedProblem` implements the protocol of :mod:`adapters.integrators`:
``acceleration`` calls ``pin.constraintDynamics`` (tree dynamics with the loop closures, solved by
Pinocchio's proximal method with its Baumgarte corrector), ``advance`` is ``pin.integrate`` (the
configuration stays on its manifold; :mod:`.stepping` adds the dexp⁻¹ map for trees with
non-commutative joints), and ``project`` optionally pulls the state back onto the
loop-closure manifold (seed 002 eq. 137: Gauss–Newton on the cut-joint residuals with Pinocchio's
constraint Jacobian, then a least-squares velocity projection).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from adapters.integrators.base import StepFailure
from adapters.pinocchio_adapter.build import PinocchioModel
from adapters.pinocchio_adapter.state import frame_jacobian
from harness.model import GROUND, BodyForce, BodyTorque, JointActuation, SpringDamper


@dataclass(frozen=True)
class SolverSettings:
    """Constraint-solver settings of a method.

    Attributes
    ----------
    kp, kd : float
        Baumgarte corrector gains (1/s², 1/s) of every loop-closure constraint.
    mu : float
        Proximal regularisation of ``pin.ProximalSettings``.
    max_iter : int
        Proximal iterations allowed per solve.
    accuracy : float
        Absolute (and relative) accuracy of the proximal iterations.
    project : bool
        Project the state onto the loop-closure manifold after every step.
    project_tol : float
        Largest constraint residual (m) the position projection leaves.
    project_max_iter : int
        Gauss–Newton iterations allowed per position projection.
    """

    kp: float
    kd: float
    mu: float
    max_iter: int
    accuracy: float
    project: bool
    project_tol: float
    project_max_iter: int


class ProjectionFailure(ValueError):
    """The position projection did not reach its tolerance."""


class ConstrainedProblem:
    """q̈ = a(t, q, v) of a Pinocchio model with loop closures.

    Parameters
    ----------
    pm : PinocchioModel
    settings : SolverSettings

    Attributes
    ----------
    n : int
        Number of velocity coordinates (``pm.model.nv``).
    counters : dict
        ``constraint_dynamics_calls``, ``proximal_iterations`` (summed), ``max_relative_residual``
        of the proximal solves, ``newton_iterations`` (Gauss–Newton iterations of the position
        projection), ``jacobian_evals`` (constraint Jacobians of the projection).
    """

    def __init__(self, pm: PinocchioModel, settings: SolverSettings):
        self.pm = pm
        self.model = pm.model
        self.n = pm.model.nv
        self.settings = settings
        self.prox = pin.ProximalSettings(settings.accuracy, settings.mu, settings.max_iter)
        gains = pin.BaumgarteCorrectorParameters(settings.kp, settings.kd)
        self.constraints = pin.StdVec_RigidConstraintModel()
        for constraint in pm.constraints:
            copy = pin.RigidConstraintModel(constraint)
            copy.setBaumgarteCorrectorParameters(gains)
            self.constraints.append(copy)
        self.data, self.cdata = self._fresh_data()
        pin.initConstraintDynamics(self.model, self.data, self.constraints, self.cdata)
        self.kin_data, self.kin_cdata = self._fresh_data()
        self._loads = [force for force in pm.mechanism.forces if _is_load(force, pm)]
        self.counters = {"constraint_dynamics_calls": 0, "proximal_iterations": 0,
                         "max_relative_residual": 0.0, "newton_iterations": 0,
                         "jacobian_evals": 0}

    def _fresh_data(self) -> tuple:
        """A ``pin.Data`` and constraint datas of their own (never shared between algorithms)."""
        cdata = pin.StdVec_RigidConstraintData()
        for constraint in self.constraints:
            cdata.append(constraint.createData())
        return self.model.createData(), cdata

    def advance(self, q: np.ndarray, dq: np.ndarray) -> np.ndarray:
        """q ⊕ dq on the configuration manifold (``pin.integrate``), shape (nq,)."""
        return pin.integrate(self.model, q, dq)

    def acceleration(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Joint accelerations from ``pin.constraintDynamics``, shape (nv,).

        Raises
        ------
        FloatingPointError
            If Pinocchio returns a non-finite acceleration (the message gives the proximal
            solver's iterations and residuals).
        StepFailure
            If Pinocchio raises.
        """
        tau = self.pm.tau_joint + self._load_forces(q, v) if self._loads else self.pm.tau_joint
        try:
            a = pin.constraintDynamics(self.model, self.data, q, v, tau, self.constraints,
                                       self.cdata, self.prox)
        except RuntimeError as exc:
            raise StepFailure(f"pin.constraintDynamics raised: {exc}") from exc
        counters = self.counters
        counters["constraint_dynamics_calls"] += 1
        counters["proximal_iterations"] += self.prox.iter
        counters["max_relative_residual"] = max(counters["max_relative_residual"],
                                                self.prox.relative_residual)
        if not np.all(np.isfinite(a)):
            raise FloatingPointError(
                f"pin.constraintDynamics returned a non-finite acceleration at t = {t:.6g} s "
                f"(proximal mu = {self.prox.mu:g}, {self.prox.iter} of {self.prox.max_iter} "
                f"iteration(s), relative residual {self.prox.relative_residual:.3g})")
        return a

    def project(self, t: float, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pull ``(q, v)`` onto the loop-closure manifold when the method asks for it.

        Returns
        -------
        q : ndarray, shape (nq,)
        v : ndarray, shape (nv,)

        Raises
        ------
        ProjectionFailure
            If the position residual stays above ``project_tol``.
        """
        if not self.settings.project or not len(self.constraints):
            return q, v
        for _ in range(self.settings.project_max_iter + 1):
            residual, jacobian = self.closure(q)
            if np.max(np.abs(residual)) <= self.settings.project_tol:
                break
            self.counters["newton_iterations"] += 1
            q = pin.integrate(self.model, q, -np.linalg.lstsq(jacobian, residual, rcond=None)[0])
        else:
            raise ProjectionFailure(f"position projection left a closure residual of "
                                    f"{np.max(np.abs(residual)):.3g} m after "
                                    f"{self.settings.project_max_iter} iterations")
        return q, v - np.linalg.lstsq(jacobian, jacobian @ v, rcond=None)[0]

    def closure(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Loop-closure residual and its Jacobian at ``q``.

        Returns
        -------
        residual : ndarray, shape (m,)
            Position of each constraint's first anchor relative to its second, in the first
            anchor's axes, m (``-c1Mc2.translation``).
        jacobian : ndarray, shape (m, nv)
            ``pin.getConstraintsJacobian``: the velocity of the first anchor relative to the
            second in the first anchor's axes, so the residual's rate where it vanishes.
        """
        model, data, cdata = self.model, self.kin_data, self.kin_cdata
        pin.computeJointJacobians(model, data, q)
        for constraint, constraint_data in zip(self.constraints, cdata):
            constraint.calc(model, data, constraint_data)
        self.counters["jacobian_evals"] += 1
        residual = -np.concatenate([d.c1Mc2.translation for d in cdata])
        return residual, pin.getConstraintsJacobian(model, data, self.constraints, cdata)

    def _load_forces(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Generalized forces of body forces, torques, springs and cut-joint actuations."""
        model, data = self.model, self.kin_data
        pin.computeJointJacobians(model, data, q)
        pin.forwardKinematics(model, data, q, v)
        pin.updateFramePlacements(model, data)
        wrenches = np.zeros((len(self.pm.body_frames), 6))
        for load in self._loads:
            _add_wrenches(self.pm, data, load, wrenches)
        tau = np.zeros(self.n)
        for frame, wrench in zip(self.pm.body_frames, wrenches):
            jacobian = frame_jacobian(model, data, frame, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
            tau += jacobian.T @ wrench
        return tau


def _is_load(force, pm: PinocchioModel) -> bool:
    """Whether ``force`` needs body wrenches (all but actuations of tree joints)."""
    return not (isinstance(force, JointActuation) and force.joint in pm.joint_ids)


def _point_motion(pm: PinocchioModel, data: pin.Data, body: str, point: np.ndarray) -> tuple:
    """World position and velocity of ``point`` (body frame) of ``body``; ground is fixed.

    Returns
    -------
    position, velocity : ndarray, shape (3,)
        m, m/s.
    lever : ndarray, shape (3,)
        From the body's centre of mass to the point, world axes, m.
    """
    if body == GROUND:
        return point, np.zeros(3), np.zeros(3)
    frame = pm.body_frames[pm.mechanism.body_index(body)]
    pose = data.oMf[frame]
    twist = pin.getFrameVelocity(pm.model, data, frame, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
    lever = pose.rotation @ point
    return pose.translation + lever, twist.linear + np.cross(twist.angular, lever), lever


def _apply(pm: PinocchioModel, body: str, wrenches: np.ndarray, force: np.ndarray,
           torque: np.ndarray, lever: np.ndarray) -> None:
    """Add ``force`` at ``lever`` from the CoM plus ``torque`` (world) to ``body``'s wrench."""
    if body == GROUND:
        return
    index = pm.mechanism.body_index(body)
    wrenches[index, :3] += force
    wrenches[index, 3:] += torque + np.cross(lever, force)


def _add_wrenches(pm: PinocchioModel, data: pin.Data, load, wrenches: np.ndarray) -> None:
    """Add the world wrenches (about each CoM, shape (n_bodies, 6)) of one load."""
    zero = np.zeros(3)
    if isinstance(load, BodyForce):
        lever = _point_motion(pm, data, load.body, load.point)[2]
        _apply(pm, load.body, wrenches, load.force, zero, lever)
    elif isinstance(load, BodyTorque):
        _apply(pm, load.body, wrenches, zero, load.torque, zero)
    elif isinstance(load, SpringDamper):
        x1, v1, lever1 = _point_motion(pm, data, load.body1, load.point1)
        x2, v2, lever2 = _point_motion(pm, data, load.body2, load.point2)
        length = np.linalg.norm(x2 - x1)
        unit = (x2 - x1) / length
        tension = load.stiffness * (length - load.free_length) + load.damping * unit @ (v2 - v1)
        _apply(pm, load.body1, wrenches, tension * unit, zero, lever1)
        _apply(pm, load.body2, wrenches, -tension * unit, zero, lever2)
    else:
        _cut_actuation(pm, data, load, wrenches)


def _cut_actuation(pm: PinocchioModel, data: pin.Data, load: JointActuation,
                   wrenches: np.ndarray) -> None:
    """Equal and opposite torques (revolute) of an actuation on a cut joint."""
    joint = pm.mechanism.joint(load.joint)
    if joint.body2 == GROUND:
        axis = joint.axis2
    else:
        axis = data.oMf[pm.body_frames[pm.mechanism.body_index(joint.body2)]].rotation @ joint.axis2
    zero = np.zeros(3)
    _apply(pm, joint.body2, wrenches, zero, load.value * axis, zero)
    _apply(pm, joint.body1, wrenches, zero, -load.value * axis, zero)
