"""Newton iteration for the implicit stage of the implicit multistep methods.

An implicit linear multistep step (Rouvinen 2003, eq. 107 with b_0 ≠ 0) on the first-order system
y = (q, v), f(t, y) = (v, a(t, q, v)) (eq. 94) asks for y_{n+1} solving

    r(y) = y − γ f(t_{n+1}, y) − ψ = 0,

with γ = h β_0 and ψ gathering the known history terms.  Newton's method solves it with the
iteration matrix M = I − γ J, J ≈ ∂f/∂y by forward differences.  As in Gear's codes (and scipy's
``BDF``), J and the LU factors of M are kept across iterations and steps and refreshed only when
the iteration converges slowly or not at all.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import lu_factor, lu_solve

from mbh._adapters.integrators.base import StepFailure

#: An iteration whose correction shrinks by less than this factor is "slow": the Jacobian is
#: refreshed (if it was not computed in this step already) and the step restarted.
SLOW_RATE = 0.5


def first_order_jacobian(acceleration, t, y, a0):
    """Forward-difference Jacobian of f(t, y) = (v, a(t, q, v)), y = (q, v).

    Parameters
    ----------
    acceleration : callable
        ``acceleration(t, q, v) -> ndarray, shape (n,)``.
    t : float
    y : ndarray, shape (2n,)
    a0 : ndarray, shape (n,)
        ``acceleration(t, q, v)`` at ``y``.

    Returns
    -------
    J : ndarray, shape (2n, 2n)
        [[0, I], [∂a/∂q, ∂a/∂v]]; costs 2n acceleration evaluations.
    """
    n = a0.size
    jacobian = np.zeros((2 * n, 2 * n))
    jacobian[:n, n:] = np.eye(n)
    for j in range(2 * n):
        shifted = y.copy()
        shifted[j] += np.sqrt(np.finfo(float).eps) * max(1.0, abs(y[j]))
        step = shifted[j] - y[j]
        jacobian[n:, j] = (acceleration(t, shifted[:n], shifted[n:]) - a0) / step
    return jacobian


def problem_jacobian(owner, t, y, a0):
    """J of f(t, y) = (v, a(t, q, v)), shape (2n, 2n): from the problem's own
    ``acceleration_jacobian(t, q, v, a0) -> (n, 2n)`` when it has one (e.g. differences taken in
    compiled code), else :func:`first_order_jacobian`; either way the 2n evaluations count in
    ``owner.nfev``."""
    own = getattr(owner.problem, "acceleration_jacobian", None)
    if own is None:
        return first_order_jacobian(owner._acceleration, t, y, a0)
    n = a0.size
    jacobian = np.zeros((2 * n, 2 * n))
    jacobian[:n, n:] = np.eye(n)
    jacobian[n:] = own(t, y[:n], y[n:], a0)
    owner.nfev += 2 * n
    return jacobian


def non_convergence(max_iter: int, tol: float, t: float) -> str:
    """Why a step failed when Newton's iteration toward t (s) did not converge, as both stepping
    paths word it (:class:`NewtonSolver`, :mod:`mbh._adapters.inhouse.stepping.compiled_multistep`)."""
    return f"Newton iteration did not converge in {max_iter} iterations to tol={tol:g} at t={t:.6g}"


def scaled_norm(dy, y):
    """max_i |dy_i| / (1 + |y_i|): the mixed absolute/relative size of a Newton correction."""
    return float(np.max(np.abs(dy) / (1.0 + np.abs(y))))


class NewtonSolver:
    """Solves r(y) = y − γ f(t, y) − ψ = 0 with a re-used finite-difference Jacobian.

    Parameters
    ----------
    owner : Integrator
        Supplies ``_acceleration`` (counted in ``nfev``) and the counters ``njev``, ``nlu``,
        ``n_newton``, which this solver increments.
    tol : float
        Convergence when :func:`scaled_norm` of the Newton correction is ≤ ``tol``.
    max_iter : int
        Iterations allowed per attempt.
    """

    def __init__(self, owner, tol: float, max_iter: int):
        if not tol > 0:
            raise ValueError(f"tol must be > 0, got {tol!r}")
        if max_iter < 1:
            raise ValueError(f"max_iter must be >= 1, got {max_iter!r}")
        self.owner = owner
        self.tol = tol
        self.max_iter = max_iter
        self.jacobian = None
        self.lu = None
        self.gamma = None

    def solve(self, t, y_guess, psi, gamma, jacobian_point):
        """Solve the implicit stage.

        Parameters
        ----------
        t : float
            t_{n+1}.
        y_guess : ndarray, shape (2n,)
            Starting iterate (a predictor).
        psi : ndarray, shape (2n,)
        gamma : float
            h β_0 (β normalised so that α_0 = 1).
        jacobian_point : tuple (t, y, a)
            Where to evaluate J when it must be (re)computed: the last accepted state and its
            acceleration, shape (2n,) and (n,).

        Returns
        -------
        y : ndarray, shape (2n,)

        Raises
        ------
        StepFailure
            When the iteration does not converge even with a fresh Jacobian.
        """
        fresh = self.jacobian is None
        if fresh:
            self._refresh_jacobian(*jacobian_point)
        if self.lu is None or gamma != self.gamma:
            self._factor(gamma)
        while True:
            y, converged = self._iterate(t, y_guess, psi, stop_when_slow=not fresh)
            if converged:
                return y
            if fresh:
                raise StepFailure(non_convergence(self.max_iter, self.tol, t))
            self._refresh_jacobian(*jacobian_point)
            self._factor(gamma)
            fresh = True

    def _iterate(self, t, y, psi, stop_when_slow):
        n = y.size // 2
        previous = None
        for _ in range(self.max_iter):
            f = np.concatenate([y[n:], self.owner._acceleration(t, y[:n], y[n:])])
            dy = lu_solve(self.lu, -(y - self.gamma * f - psi), check_finite=False)
            self.owner.n_newton += 1
            y = y + dy
            size = scaled_norm(dy, y)
            if not np.isfinite(size):
                return y, False
            if size <= self.tol:
                return y, True
            if stop_when_slow and previous is not None and size > SLOW_RATE * previous:
                return y, False
            previous = size
        return y, False

    def _refresh_jacobian(self, t, y, a):
        self.jacobian = problem_jacobian(self.owner, t, y, a)
        self.owner.njev += 1
        self.lu = None

    def _factor(self, gamma):
        self.lu = lu_factor(np.eye(self.jacobian.shape[0]) - gamma * self.jacobian)
        self.gamma = gamma
        self.owner.nlu += 1
