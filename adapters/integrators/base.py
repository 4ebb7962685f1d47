"""The problem protocol and the integrator base class.

The in-house formulation reduces the equations of motion to a second-order ODE

    q̈ = a(t, q, v),   v = q̇,

(Rouvinen 2003, eq. 77 with a stabilisation, ch. 5) and may correct the state after each step (the
direct violation correction, Rouvinen 2003, eq. 137).  :class:`Integrator` is the common base of every
method in this package, modelled on ``scipy.integrate.OdeSolver``: its public
:meth:`~Integrator.step` owns the time, the status and the cost counters and calls the private
``_step_impl`` of the method.

Configuration spaces
--------------------
``q`` may be a point of a Lie group (Pinocchio's configuration vector) whose length differs from
the length ``n`` of the velocity ``v``.  A position is then only ever changed through
``problem.advance(q, dq)`` (q ⊕ dq) with ``dq`` of shape (n,), a tangent vector.  The explicit
one-step methods (:mod:`.nystrom`) honour this; the multistep, implicit and SciPy methods combine
positions linearly and require ``len(q) == len(v)`` (checked at construction).

A problem whose group is not commutative (rotations in space) also provides, so that the explicit
methods keep their order there (:mod:`.nystrom`, "Lie groups"):

* ``increment_rate(q, dq, v) -> ndarray (n,)``: the rate k = dexp⁻¹_dq(v) at which the increment
  dq must change for q ⊕ dq to move with velocity v (the inverse of the Jacobian of q ⊕ dq with
  respect to dq, applied to v);
* optionally ``chart_velocity(q, dq, w) -> ndarray (n,)``, the velocity of q ⊕ dq when dq moves
  with rate w (dexp_dq(w)), and ``chart_acceleration(q, dq, w, a) -> ndarray (n,)``, the second
  derivative of dq when moreover the velocity changes at rate a; Nyström tableaus of order > 1
  that are not Runge–Kutta methods (rkn4) need them.

Failures
--------
``step()`` never raises for a numerical failure: a non-finite state or one whose norm exceeds
``divergence_limit`` sets ``status = IntegratorState.DIVERGED``; a ``FloatingPointError``,
``LinAlgError`` or ``ValueError`` raised by the problem, or a method's own failure
(:class:`StepFailure`, e.g. Newton not converging), sets ``status = IntegratorState.FAILED``.
Either way ``failure_time`` is the time the failed step was heading for, ``failure_reason`` says
why, and ``t, q, v`` keep the last good state.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

from mbh._harness.common.status import IntegratorState


@runtime_checkable
class SecondOrderProblem(Protocol):
    """What an integrator needs from a mechanism model.

    Attributes
    ----------
    n : int
        Number of velocity coordinates (length of ``v``).
    """

    n: int

    def acceleration(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """q̈ = a(t, q, v), shape (n,)."""

    def project(self, t: float, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Post-step correction of ``(q, v)`` (e.g. Rouvinen 2003, eq. 137); same shapes out."""

    def advance(self, q: np.ndarray, dq: np.ndarray) -> np.ndarray:
        """Position update q ⊕ dq, with ``dq`` a tangent vector of shape (n,)."""


class SecondOrderSystem:
    """Mixin with the Euclidean defaults: ``advance`` is ``q + dq``, ``project`` is the identity.

    A plain problem subclasses it and defines ``n`` and ``acceleration`` only.
    """

    n: int

    def advance(self, q: np.ndarray, dq: np.ndarray) -> np.ndarray:
        """q ⊕ dq = q + dq (Euclidean configuration space)."""
        return q + dq

    def project(self, t: float, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """No correction: returns ``(q, v)`` unchanged (the same objects)."""
        return q, v


class StepFailure(Exception):
    """Raised inside ``_step_impl`` when a method cannot complete a step; becomes ``failed``."""


#: Exceptions from the problem that end a run as ``failed`` instead of propagating.
PROBLEM_ERRORS = (FloatingPointError, np.linalg.LinAlgError, ValueError, StepFailure)


class Integrator:
    """Base class of the fixed-step and adaptive integrators.

    Parameters
    ----------
    problem : SecondOrderProblem
        Provides ``n``, ``acceleration``, ``project`` and ``advance``.
    t0 : float
        Initial time, s.
    q0 : array_like, shape (m,)
        Initial positions (``m == n`` unless the configuration space is a Lie group).
    v0 : array_like, shape (n,)
        Initial velocities.
    dt : float
        Step size, s (> 0); the first-step hint for adaptive methods.
    **params
        Method parameters; :meth:`parameter_defaults` lists them with their defaults.
        ``divergence_limit`` (default 1e8): a state whose ``q`` or ``v`` 2-norm exceeds it is
        diverged.

    Attributes
    ----------
    t : float
        Current time, s.
    q : ndarray, shape (m,)
    v : ndarray, shape (n,)
    dt : float
    status : IntegratorState
        ``running`` while it steps, ``diverged`` or ``failed`` once it stopped.
    failure_reason : str or None
    failure_time : float or None
    nfev, njev, nlu, n_newton, n_steps : int
        Acceleration evaluations (finite-difference Jacobian columns included), Jacobian
        evaluations, LU factorisations, Newton iterations, completed steps.
    """

    #: User-facing name (key of the registry in :mod:`mbh._adapters.integrators`).
    name: str = ""
    #: Order of accuracy (for adaptive methods: of the propagated solution).
    order: int = 0
    #: True when ``step()`` chooses its own step size.
    adaptive: bool = False
    #: True when the method combines positions linearly and so needs ``len(q) == len(v)``.
    euclidean_only: bool = False
    #: Parameters this class adds, with their defaults (merged along the MRO).
    defaults: dict = {"divergence_limit": 1e8}

    def __init__(self, problem, t0, q0, v0, dt, **params):
        self.problem = _validate_problem(problem)
        self.n = int(problem.n)
        self.q = _vector("q0", q0)
        self.v = _vector("v0", v0, self.n)
        if self.euclidean_only and self.q.shape != self.v.shape:
            raise ValueError(f"q0 has length {self.q.size} but v0 has length {self.v.size}: "
                             f"method {self.name!r} needs a Euclidean configuration "
                             "(len(q) == len(v)); use an explicit one-step method on a Lie group")
        self.t0 = self.t = _finite("t0", t0)
        self.dt = _finite("dt", dt)
        if self.dt <= 0:
            raise ValueError(f"dt must be > 0, got {dt!r}")
        self.params = self.resolve_params(params)
        self.status = IntegratorState.RUNNING
        self.failure_reason: str | None = None
        self.failure_time: float | None = None
        self.nfev = self.njev = self.nlu = self.n_newton = self.n_steps = 0

    @classmethod
    def parameter_defaults(cls) -> dict:
        """Every parameter of the method with its default value."""
        merged = {}
        for klass in reversed(cls.__mro__):
            merged.update(vars(klass).get("defaults", {}))
        return merged

    @classmethod
    def resolve_params(cls, given: dict) -> dict:
        """Defaults overridden by ``given``; an unknown key raises a ValueError naming it."""
        defaults = cls.parameter_defaults()
        unknown = sorted(set(given) - set(defaults))
        if unknown:
            raise ValueError(f"method {cls.name!r} has no parameter {', '.join(unknown)} "
                             f"(valid: {', '.join(sorted(defaults))})")
        resolved = dict(defaults)
        for key, value in given.items():
            try:
                resolved[key] = type(defaults[key])(value)
            except (TypeError, ValueError):
                raise ValueError(f"parameter {key!r} of method {cls.name!r} expects a "
                                 f"{type(defaults[key]).__name__}, got {value!r}") from None
        return resolved

    def step(self) -> IntegratorState:
        """Advance one step (by exactly ``dt`` for fixed-step methods), then project.

        Returns
        -------
        status : IntegratorState
            The status after the step; a no-op returning it when not ``running``.
        """
        if self.status != IntegratorState.RUNNING:
            return self.status
        new = self._checked(self._target_time(), self._step_impl)
        if new is not None:
            self.t, self.q, self.v = new
            self.n_steps += 1
        return self.status

    def _checked(self, t_target: float, take):
        """``take()`` → (t_new, q, q̇), projected by the problem and checked for a finite state
        within ``divergence_limit``; None after failing the run (at ``t_target`` when the step
        raised, else at t_new).  The integrator's state is not changed."""
        try:
            t_new, q_new, v_new = take()
            q_new, v_new = self.problem.project(t_new, q_new, v_new)
            q_new = np.asarray(q_new, dtype=float)
            v_new = np.asarray(v_new, dtype=float)
        except PROBLEM_ERRORS as exc:
            self._fail(IntegratorState.FAILED, t_target, f"{type(exc).__name__}: {exc}")
            return None
        limit = self.params["divergence_limit"]
        # One dot product per vector (ndarray.dot: a third of the cost of @ on short vectors);
        # NaN and inf propagate into their sum (not into max()).
        squared_q, squared_v = float(q_new.dot(q_new)), float(v_new.dot(v_new))
        if not np.isfinite(squared_q + squared_v):
            self._fail(IntegratorState.DIVERGED, t_new, "non-finite state")
            return None
        if max(squared_q, squared_v) > limit * limit:
            self._fail(IntegratorState.DIVERGED, t_new,
                       f"state norm exceeds divergence_limit={limit:g}")
            return None
        return t_new, q_new, v_new

    def _target_time(self) -> float:
        """End time of the next fixed step, t0 + (n_steps + 1)·dt (no accumulated drift)."""
        return self.t0 + (self.n_steps + 1) * self.dt

    def _fail(self, status: IntegratorState, time: float, reason: str) -> None:
        self.status = status
        self.failure_time = float(time)
        self.failure_reason = reason

    def _acceleration(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """``problem.acceleration`` with the ``nfev`` count and a shape check, shape (n,)."""
        self.nfev += 1
        a = np.asarray(self.problem.acceleration(t, q, v), dtype=float)
        if a.shape != (self.n,):
            raise ValueError(f"acceleration returned shape {a.shape}, expected ({self.n},)")
        return a

    def _step_impl(self) -> tuple[float, np.ndarray, np.ndarray]:
        """Take one step from ``(self.t, self.q, self.v)``; return ``(t_new, q_new, v_new)``."""
        raise NotImplementedError


def _validate_problem(problem):
    missing = [name for name in ("n", "acceleration", "project", "advance")
               if not hasattr(problem, name)]
    if missing:
        raise TypeError(f"problem lacks {', '.join(missing)} (subclass SecondOrderSystem for the "
                        "default project/advance)")
    return problem


def _finite(name: str, value) -> float:
    number = float(value)
    if not np.isfinite(number):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return number


def _vector(name: str, value, length: int | None = None) -> np.ndarray:
    array = np.array(value, dtype=float)
    if array.ndim != 1 or (length is not None and array.size != length):
        expected = f"({length},)" if length is not None else "1-D"
        raise ValueError(f"{name} must have shape {expected}, got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must be finite")
    return array
