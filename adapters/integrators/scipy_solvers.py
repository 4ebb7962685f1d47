"""Adaptive SciPy solvers (``scipy.integrate`` ``OdeSolver`` classes) on y = (q, v).

``step()`` takes one internal adaptive step of the wrapped solver; ``dt`` is the first-step hint.

Projection
----------
``problem.project`` is applied after every internal step, as for the fixed-step methods.  When it
changes the state, the SciPy solver is re-initialised from the projected state at the next step,
with the step size it had proposed as its first step (LSODA, which does not expose it, picks its
own).  The restart is paid for honestly: the counters add up
over every solver instance (RK45/DOP853 re-evaluate f at the start, BDF/LSODA drop back to order 1
and Radau/BDF recompute the Jacobian).  With the identity projection nothing is restarted.
With a projection that changes the state every step the multistep solvers (bdf, lsoda) never
leave order 1 and take many times the steps, the one-step solvers the same (figures:
docs/measurements.md, section "Integrators").  Prefer the one-step solvers (or
the fixed-step methods) when the problem projects.

Counters
--------
``nfev`` counts acceleration evaluations through this package's counter, which includes the
finite-difference Jacobian columns (SciPy's own ``nfev`` leaves those out for Radau and BDF; a
problem with its own ``acceleration_jacobian`` differences in compiled code and counts them too);
``njev`` and ``nlu`` are SciPy's.
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import BDF, DOP853, LSODA, RK45, Radau

from mbh._adapters.integrators.base import Integrator, StepFailure
from mbh._adapters.integrators.newton import problem_jacobian

#: SciPy solvers that take a Jacobian (``jac``).
IMPLICIT_SOLVERS = (Radau, BDF, LSODA)


class ScipyIntegrator(Integrator):
    """One adaptive ``solver_class`` step per ``step()``.

    Parameters
    ----------
    problem, t0, q0, v0, dt
        As :class:`~mbh._adapters.integrators.base.Integrator`; ``dt`` is the first step.
    rtol, atol : float
        Relative and absolute tolerances of the local error (defaults 1e-6, 1e-9).
    max_step : float
        Largest step, s (default inf).
    min_step_ratio : float
        The run fails (:class:`StepFailure`, "step-size collapse") as soon as the solver's next
        step falls below ``min_step_ratio · dt`` (default 1e-5: 1e-8 s for a 1e-3 s hint).
        Without it a solver that cannot pass a singular configuration crawls on at steps of
        ~1e-12 s for a minute before SciPy gives up (figures: docs/measurements.md, section
        "Integrators").
    """

    adaptive = True
    euclidean_only = True
    defaults = {"rtol": 1e-6, "atol": 1e-9, "max_step": np.inf, "min_step_ratio": 1e-5}
    solver_class: type

    def __init__(self, problem, t0, q0, v0, dt, **params):
        super().__init__(problem, t0, q0, v0, dt, **params)
        self._njev_done = self._nlu_done = 0
        self._dense = None
        self._solver = self._start(self.dt)

    def _start(self, first_step):
        """A fresh SciPy solver at the current state, shape (2n,) state; the implicit solvers
        get the problem's own Jacobian when it has one (:func:`~.newton.problem_jacobian`)."""
        own_jacobian = {}
        if self.solver_class in IMPLICIT_SOLVERS and \
                getattr(self.problem, "acceleration_jacobian", None) is not None:
            own_jacobian["jac"] = self._jacobian
        return self.solver_class(self._f, self.t, np.concatenate([self.q, self.v]), np.inf,
                                 first_step=first_step, rtol=self.params["rtol"],
                                 atol=self.params["atol"], max_step=self.params["max_step"],
                                 **own_jacobian)

    def _jacobian(self, t, y):
        """∂f/∂y, shape (2n, 2n), at one more acceleration evaluation for a(t, q, v)."""
        return problem_jacobian(self, t, y, self._acceleration(t, y[:self.n], y[self.n:]))

    def _f(self, t, y):
        """f(t, y) = (v, a(t, q, v)), shape (2n,)."""
        return np.concatenate([y[self.n:], self._acceleration(t, y[:self.n], y[self.n:])])

    def _target_time(self) -> float:
        """Estimate of where the next step ends (t + last step size), for ``failure_time``."""
        return self.t + (self._solver.step_size or self.dt)

    def _step_impl(self):
        if not np.array_equal(self._solver.y, np.concatenate([self.q, self.v])):
            self._njev_done += self._solver.njev
            self._nlu_done += self._solver.nlu
            self._solver = self._start(getattr(self._solver, "h_abs", self._solver.step_size))
        message = self._solver.step()
        self.njev = self._njev_done + self._solver.njev
        self.nlu = self._nlu_done + self._solver.nlu
        if self._solver.status == "failed":
            raise StepFailure(message)
        smallest = self.params["min_step_ratio"] * self.dt
        if self._solver.status == "running" and self._solver.step_size < smallest:
            raise StepFailure(
                f"step-size collapse at t = {self._solver.t:.9g} s: the next step "
                f"{self._solver.step_size:.3g} s is below min_step_ratio·dt = {smallest:.3g} s "
                "(a singular configuration or a discontinuity this method cannot pass)")
        self._dense = self._solver.dense_output()
        y = self._solver.y
        return self._solver.t, y[:self.n].copy(), y[self.n:].copy()

    def dense(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(q, v) at ``t`` inside the last step, from the solver's interpolant.

        Parameters
        ----------
        t : float
            In [t_old, t_new] of the last step, s.  The interpolant is the solver's, before
            projection.

        Returns
        -------
        q, v : ndarray, shape (n,)
        """
        if self._dense is None:
            raise ValueError("dense: no step taken yet")
        low, high = sorted((self._dense.t_old, self._dense.t))
        if not low <= t <= high:
            raise ValueError(f"dense: t={t!r} is outside the last step [{low!r}, {high!r}]")
        y = self._dense(t)
        return y[:self.n], y[self.n:]


def _scipy_method(class_name, name, solver_class, order, doc):
    return type(class_name, (ScipyIntegrator,), {
        "__module__": __name__, "__doc__": doc, "name": name, "order": order,
        "solver_class": solver_class})


SCIPY_METHODS = [
    _scipy_method("ScipyRK45", "rk45", RK45, 5, "Dormand–Prince 5(4), scipy RK45."),
    _scipy_method("ScipyDOP853", "dop853", DOP853, 8, "Dormand–Prince 8(5,3), scipy DOP853."),
    _scipy_method("ScipyRadau", "radau", Radau, 5, "Radau IIA order 5, scipy Radau."),
    _scipy_method("ScipyBDF", "bdf", BDF, 5, "Variable-order BDF (NDF) up to order 5, scipy BDF."),
    _scipy_method("ScipyLSODA", "lsoda", LSODA, 12,
                  "ODEPACK LSODA: Adams up to order 12 / BDF up to 5, switching on stiffness."),
]
