"""The equations of motion of a :class:`PinocchioModel` as a second-order problem.

:class:`ConstrainedProblem` implements the protocol of :mod:`mbh._adapters.integrators`:
``acceleration`` calls ``pin.constraintDynamics`` (tree dynamics with the loop closures, solved by
Pinocchio's proximal method with its Baumgarte corrector), ``advance`` is ``pin.integrate`` (the
configuration stays on its manifold; :mod:`.stepping` adds the dexp⁻¹ map for trees with
non-commutative joints), and ``project`` optionally pulls the state back onto the
loop-closure manifold (Rouvinen 2003, eq. 137: Gauss–Newton on the cut-joint residuals with Pinocchio's
constraint Jacobian, then a minimum-norm velocity projection).

One factorisation per projection
--------------------------------
The projection factors the closure Jacobian J (m × nv) once, at the configuration the step
arrived at, as its pseudo-inverse J⁺ from a singular value decomposition truncated at
:data:`RANK_RTOL` · σ_max: rank-revealing, so redundant closure rows (the planar revolute closed
by a 3-D point, Bricard's loop) cost nothing.  The Gauss–Newton iterations reuse J⁺, a chord
iteration: the configuration moves by about the residual, so J changes by about that relative
amount, and the iteration takes as many iterations as Newton's.  The velocity is projected with
the same J⁺ applied to J v at the final configuration; the velocity violation stays at round-off,
as with a fresh least-squares solve.  Figures: docs/measurements.md, section "Engines".
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from mbh._adapters import closure_notes
from mbh._adapters.integrators.base import StepFailure
from mbh._adapters.pinocchio_adapter.build import PinocchioModel
from mbh._adapters.pinocchio_adapter.state import frame_jacobian
from mbh._harness.model.mechanism import GROUND, BodyForce, BodyTorque, JointActuation, SpringDamper


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


#: The cost counters of :class:`ConstrainedProblem`, in the order the case row lists them.
COUNTER_NAMES = ("constraint_dynamics_calls", "proximal_iterations", "max_relative_residual",
                 "unconverged_solves", "newton_iterations", "jacobian_evals",
                 "projection_factorizations")

#: A proximal solve whose relative residual (``ProximalSettings.relative_residual`` after the call)
#: stays above this counts as unconverged: its iteration was not settling, it was driving the
#: multiplier of inconsistent rows up.  Measured with ``best`` (accuracy 1e-12, 20 iterations) at
#: dt 1e-3 s (benchmarks/hard_loops.py): largest residual 128 (Bennett's 4R) and 12 (Bricard),
#: where the error is 1e6x the in-house formulation's; 1.8e-5 (the parallel-revolute four-bar)
#: and 2.4e-7 (the flat parallelogram), whose solves also stop at ``max_iter`` but whose error is
#: within 1.4x of the best engine's; 1e-12 on the shipped four-bars and slider-cranks.
UNCONVERGED_RESIDUAL = 1e-2


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
    constraint_dynamics_calls, proximal_iterations : int
        Calls of ``pin.constraintDynamics`` and their proximal iterations (summed).
    max_relative_residual : float
        The largest relative residual of the proximal solves.
    unconverged_solves : int
        Proximal solves that ended with a relative residual above :data:`UNCONVERGED_RESIDUAL`.
    newton_iterations, jacobian_evals, projection_factorizations : int
        Gauss–Newton iterations of the position projection, constraint Jacobians of the
        projection, pseudo-inverses of the closure Jacobian (one per projection).
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
        # Python lists of the pybind vectors' elements (the same objects): iterating a
        # StdVec_RigidConstraint* costs ~3.5 µs per pass, a list ~0.2 µs.
        self._closure_pairs = list(zip(self.constraints, self.kin_cdata))
        self._loads = [force for force in pm.mechanism.forces if _is_load(force, pm)]
        # Plain attributes, not a dict: the right-hand side updates three of them per call,
        # and attribute updates save ~0.07 µs of a symplectic-Euler step's ~5.5 µs.
        self.constraint_dynamics_calls = self.proximal_iterations = 0
        self.max_relative_residual = 0.0
        self.unconverged_solves = 0
        self.newton_iterations = self.jacobian_evals = self.projection_factorizations = 0

    @property
    def counters(self) -> dict:
        """The cost counters (the attributes above) by name."""
        return {name: getattr(self, name) for name in COUNTER_NAMES}

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
        try:
            a = self.counted_acceleration(t, q, v)
        except RuntimeError as exc:
            raise StepFailure(f"pin.constraintDynamics raised: {exc}") from exc
        if not math.isfinite(a.sum()):  # NaN or ±inf anywhere makes the sum non-finite
            raise FloatingPointError(
                f"pin.constraintDynamics returned a non-finite acceleration at t = {t:.6g} s "
                f"(proximal mu = {self.prox.mu:g}, {self.prox.iter} of {self.prox.max_iter} "
                f"iteration(s), relative residual {self.prox.relative_residual:.3g})")
        return a

    def counted_acceleration(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """:meth:`engine_acceleration` with the cost counters (calls, proximal iterations, the
        largest relative residual) and no checks, shape (nv,): the right-hand side of the
        adapter's unchecked steps (:meth:`~mbh._adapters.integrators.nystrom.NystromIntegrator.
        steps_unchecked`), whose failing steps :meth:`acceleration` takes again."""
        a = self.engine_acceleration(t, q, v)
        prox = self.prox
        self.constraint_dynamics_calls += 1
        self.proximal_iterations += prox.iter
        residual = prox.relative_residual
        if residual > self.max_relative_residual:
            self.max_relative_residual = residual
        if residual > UNCONVERGED_RESIDUAL:
            self.unconverged_solves += 1
        return a

    def engine_acceleration(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """``pin.constraintDynamics`` at ``(q, v)`` with the mechanism's loads, shape (nv,): what
        :meth:`acceleration` returns, without its counters and checks (Pinocchio's exceptions
        propagate)."""
        tau = self.pm.tau_joint + self._load_forces(q, v) if self._loads else self.pm.tau_joint
        return pin.constraintDynamics(self.model, self.data, q, v, tau, self.constraints,
                                      self.cdata, self.prox)

    def project(self, t: float, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pull ``(q, v)`` onto the loop-closure manifold when the method asks for it.

        Returns
        -------
        q : ndarray, shape (nq,)
        v : ndarray, shape (nv,)

        Raises
        ------
        ProjectionFailure
            If the position residual stays above ``project_tol`` after ``project_max_iter``
            Gauss–Newton iterations (see the module notes: one pseudo-inverse serves them all).
        """
        settings = self.settings
        if not settings.project or not self._closure_pairs:
            return q, v
        residual, jacobian = self.closure(q)
        inverse = pseudo_inverse(jacobian)
        self.projection_factorizations += 1
        for iteration in itertools.count():
            worst = np.abs(residual).max()
            if worst <= settings.project_tol:
                break
            if iteration == settings.project_max_iter:
                raise ProjectionFailure(f"position projection left a closure residual of "
                                        f"{worst:.3g} m after {iteration} iterations")
            self.newton_iterations += 1
            q = pin.integrate(self.model, q, -(inverse @ residual))
            residual, jacobian = self.closure(q)
        return q, v - inverse @ (jacobian @ v)

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
        self.jacobian_evals += 1
        return self.uncounted_closure(q)

    def uncounted_closure(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`closure` off the cost counters (for the note of :func:`redundancy_notes`)."""
        model, data = self.model, self.kin_data
        pin.computeJointJacobians(model, data, q)
        for constraint, constraint_data in self._closure_pairs:
            constraint.calc(model, data, constraint_data)
        residual = -np.concatenate([d.c1Mc2.translation for _, d in self._closure_pairs])
        return residual, pin.getConstraintsJacobian(model, data, self.constraints, self.kin_cdata)

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


#: Singular values of a closure Jacobian at or below this fraction of the largest count as zero.
#: Redundant rows leave round-off, not zeros (on Bricard's loop above the eps · max(m, nv) cut-off
#: of ``numpy.linalg.lstsq(rcond=None)``, where kept it turned a ~1e-12 m residual into a
#: metres-long step; figures: docs/measurements.md, section "Engines").  A direction 1e-10 below
#: the largest could only be corrected by a step 1e10 times the residual, which is no correction
#: either.
RANK_RTOL = 1e-10


def pseudo_inverse(jacobian: np.ndarray) -> np.ndarray:
    """Moore–Penrose pseudo-inverse of a closure Jacobian, shape (nv, m) from (m, nv).

    Singular values at or below :data:`RANK_RTOL` · σ_max count as zero, so J⁺ r is the
    minimum-norm least-squares solution with redundant rows (rank-deficient J) ignored.
    ``numpy.linalg.pinv(jacobian, rcond=RANK_RTOL)`` is the same matrix to round-off, but slower;
    this is paid once a step on Pinocchio's clock.
    """
    u, sigma, vt = np.linalg.svd(jacobian, full_matrices=False)
    kept = sigma > RANK_RTOL * sigma[0]
    return (vt[kept].T / sigma[kept]) @ u[:, kept].T


def redundancy_notes(problem: ConstrainedProblem, q: np.ndarray) -> list[str]:
    """The note counting the redundant closure equations at an assembled configuration ``q``
    (:func:`mbh._adapters.closure_notes.redundancy_notes`), from the closure Jacobian the adapter
    builds (:meth:`ConstrainedProblem.closure`) and the rank cut its projection uses
    (:data:`RANK_RTOL`); ``q`` should be the assembled start."""
    if not problem.constraints:
        return []
    _, jacobian = problem.uncounted_closure(q)
    return closure_notes.redundancy_notes(jacobian, problem.pm.tree.redundant_closure_equations,
                                          RANK_RTOL)


def proximal_notes(problem: ConstrainedProblem) -> list[str]:
    """The note naming the engine's limit when proximal solves of the run did not converge.

    ``pin.constraintDynamics`` solves the closure rows by a proximal iteration with an absolute
    regularisation ``mu`` and no rank-revealing treatment of dependent rows.  Where a spatial
    overconstrained loop's redundant rows stop being consistent (an explicit integrator's stages
    off the closure manifold), the iteration cannot satisfy them and its multiplier grows by
    about residual / mu per iteration; the acceleration error grows with ``max_iter`` / mu
    (docs/measurements.md, "Engine settings on hard loops").  The note counts those solves
    (:data:`UNCONVERGED_RESIDUAL`) and gives the largest residual, both measured in the run.

    Returns
    -------
    list of str
        One note when any solve ended unconverged, none otherwise.
    """
    count = problem.unconverged_solves
    if count == 0:
        return []
    return [f"engine limit: {count} of {problem.constraint_dynamics_calls} "
            f"pin.constraintDynamics solves ended unconverged (relative residual above "
            f"{UNCONVERGED_RESIDUAL:g}, largest {problem.max_relative_residual:.3g}, after at "
            f"most {problem.prox.max_iter} proximal iterations, mu = {problem.prox.mu:g}): "
            f"Pinocchio's proximal solver cannot satisfy redundant closure rows that an "
            f"integrator's stages off the closure manifold make inconsistent, and the error "
            f"grows as max_iter / mu (docs/measurements.md, \"Engine settings on hard loops\")"]


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
