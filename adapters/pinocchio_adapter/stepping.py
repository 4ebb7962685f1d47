"""How the harness's integrators step a Pinocchio configuration: on its Lie group, at full order.

Pinocchio's velocity ``v`` of a spherical, free-flyer or planar joint is a tangent vector at the
*current* configuration, and ``pin.integrate(q, dq)`` composes q ⊕ dq on the joint's group
(SO(3), SE(3), SE(2)).  These groups do not commute, so a Runge–Kutta method whose stages combine
velocities at different configurations loses its order (to 2) unless each stage velocity V_i is
mapped to the rate of the increment, k_i = dexp⁻¹_{Θ_i}(V_i) (Runge–Kutta–Munthe-Kaas,
:mod:`mbh._adapters.integrators.nystrom`, "Lie groups").  Pinocchio gives that map exactly:
``pin.dIntegrate(model, q, dq, ARG1)`` is the Jacobian of q ⊕ dq with respect to dq, expressed
in the tangent space at q ⊕ dq, so k solves ``dIntegrate · k = V``.

Models whose joints all live on commutative groups (revolute, prismatic, universal, the
cylindrical composite; R^k or the circle) need no correction and keep the plain composition.
Nyström tableaus that are not Runge–Kutta methods (rkn4) also need the chart's second derivative,
which Pinocchio does not expose; the integrator refuses them on a non-commutative model with a
clear message (the adapter reports the case as unsupported).

:func:`bare_steps` is the yardstick of the adapter's overhead (``Adapter.bare_loop``): the same
explicit one-step rule, Pinocchio's constraint dynamics and ``pin.integrate`` and the same
projection, in a plain loop without the integrator's bookkeeping, counters or checks.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from mbh._adapters.base import UnsupportedCase
from mbh._adapters.integrators import integrator_class
from mbh._adapters.integrators.nystrom import NystromIntegrator, step_rule
from mbh._adapters.pinocchio_adapter.build import PinocchioModel
from mbh._adapters.pinocchio_adapter.dynamics import ConstrainedProblem, SolverSettings

#: Joint models whose configuration group is not commutative (SO(3), SE(3), SE(2)).  The
#: Euler-angle ``JointModelSphericalZYX`` (a vector space) matches too, which is harmless: its
#: ``dIntegrate`` is the identity.
_NON_COMMUTATIVE = ("JointModelSpherical", "JointModelFreeFlyer", "JointModelPlanar")


class LieGroupProblem(ConstrainedProblem):
    """:class:`ConstrainedProblem` on a non-commutative configuration group.

    Adds :meth:`increment_rate`, with which the explicit Runge–Kutta methods of
    :mod:`mbh._adapters.integrators` step by Runge–Kutta–Munthe-Kaas.
    """

    def increment_rate(self, q: np.ndarray, dq: np.ndarray, v: np.ndarray) -> np.ndarray:
        """k = dexp⁻¹_dq(v): solves ``pin.dIntegrate(q, dq, ARG1) k = v``, shape (nv,)."""
        jacobian = pin.dIntegrate(self.model, q, dq, pin.ArgumentPosition.ARG1)
        return np.linalg.solve(jacobian, v)


def is_commutative(model: pin.Model) -> bool:
    """True when every joint of ``model`` moves on a commutative group (R^k or the circle)."""
    return all(_commutative_joint(joint) for joint in model.joints)


def _commutative_joint(joint) -> bool:
    """A joint model, a composite judged by its parts."""
    if joint.shortname() == "JointModelComposite":
        return all(_commutative_joint(part) for part in joint.extract().joints)
    return not joint.shortname().startswith(_NON_COMMUTATIVE)


def constrained_problem(pm: PinocchioModel, settings: SolverSettings) -> ConstrainedProblem:
    """The second-order problem of ``pm``: a :class:`LieGroupProblem` when its tree holds a
    spherical, free-flyer or planar joint, else the plain :class:`ConstrainedProblem`."""
    problem_class = ConstrainedProblem if is_commutative(pm.model) else LieGroupProblem
    return problem_class(pm, settings)


def bare_rule(problem: ConstrainedProblem, integrator: str) -> tuple:
    """The step rule the integrator ``integrator`` takes on ``problem``
    (:func:`~mbh._adapters.integrators.nystrom.step_rule`), its stages calling Pinocchio directly
    (:meth:`ConstrainedProblem.engine_acceleration`), for :func:`bare_steps`.

    Returns
    -------
    step : callable
        ``step(t, q, v, h, tableau) -> (q_new, v_new)``.
    tableau : NystromTableau

    Raises
    ------
    UnsupportedCase
        For a method that is not an explicit one-step method, or a Nyström tableau that needs
        the exponential chart on a non-commutative tree.
    """
    method = integrator_class(integrator)
    if not issubclass(method, NystromIntegrator):
        raise UnsupportedCase(f"{integrator} is not an explicit one-step method: no bare loop")
    try:
        return step_rule(method, problem, problem.engine_acceleration), method.tableau
    except ValueError as error:
        raise UnsupportedCase(str(error)) from error


def bare_steps(problem: ConstrainedProblem, rule: tuple, q: np.ndarray, v: np.ndarray,
               dt: float, n_steps: int) -> tuple[np.ndarray, np.ndarray]:
    """``n_steps`` steps of ``dt`` (s) of ``rule`` (:func:`bare_rule`) from ``(q, v)``, each
    followed by ``problem.project``: Pinocchio's constraint dynamics
    (:meth:`ConstrainedProblem.engine_acceleration`) and ``pin.integrate`` in a plain loop.

    Parameters
    ----------
    problem : ConstrainedProblem
    rule : tuple
        ``(step, tableau)`` from :func:`bare_rule`.
    q : ndarray, shape (nq,)
    v : ndarray, shape (nv,)
    dt : float
        s.
    n_steps : int

    Returns
    -------
    q : ndarray, shape (nq,)
    v : ndarray, shape (nv,)
    """
    step, tableau = rule
    project = problem.project
    for k in range(n_steps):
        t = k * dt
        q, v = step(t, q, v, dt, tableau)
        q, v = project(t + dt, q, v)
    return q, v
