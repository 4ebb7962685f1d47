"""Explicit one-step methods for q̈ = a(t, q, v), all written as Runge–Kutta–Nyström schemes.

A Nyström tableau (c, A, Ā, b, b̄) advances (q, v) by h with stages

    Q_i = q ⊕ h (c_i v + h Σ_j Ā_ij a_j),   V_i = v + h Σ_j A_ij a_j,
    a_i = a(t + c_i h, Q_i, V_i),
    q_{n+1} = q ⊕ h (v + h Σ_i b̄_i a_i),     v_{n+1} = v + h Σ_i b_i a_i.

Every position change is ``problem.advance(q, dq)`` with ``dq`` h times a combination of the
velocity and of h·accelerations — a tangent vector of shape (n,) — so these methods also integrate
on a Lie group (``len(q) != len(v)``).

Lie groups
----------
On a commutative group (the circle, a torus) q ⊕ dq composes exactly and the formulas above keep
their order.  On a non-commutative one (rotations in space) the velocity v lives in the tangent
space of the *moving* point, and composing stage velocities linearly drops a commutator term of
order h³ (local): the global order falls to 2.  A problem on such a group provides
``increment_rate`` (and, for Nyström tableaus of order > 2, ``chart_velocity`` and
``chart_acceleration``; :mod:`.base`), and the step is taken in the exponential chart
q(t) = q_n ⊕ Θ(t) around the current point, where Θ lives in a vector space:

* Runge–Kutta tableaus (Euler, Heun, RK4): Runge–Kutta–Munthe-Kaas (H. Munthe-Kaas, *High order
  Runge–Kutta methods on manifolds*, Appl. Numer. Math. 29, 1999; A. Iserles, H. Munthe-Kaas,
  S. Nørsett, A. Zanna, *Lie-group methods*, Acta Numerica 9, 2000, §5.1).  The tableau is
  applied to Θ̇ = dexp⁻¹_Θ(V), V̇ = a(t, q_n ⊕ Θ, V), Θ(0) = 0, with the exact dexp⁻¹
  (:func:`munthe_kaas_step`); the classical order carries over.
* Nyström tableaus (RKN4): the tableau is applied to the chart's own second-order equation
  Θ̈ = F(t, Θ, Θ̇), F = dexp⁻¹_Θ(a − (d/dt dexp_Θ) Θ̇) (:func:`chart_nystrom_step`): an ODE in a
  vector space, so the Nyström order conditions hold unchanged (the same re-centred chart that
  RKMK uses, Iserles et al. §5.1, here with the second derivative).  RKN4 written as a
  partitioned method with dexp⁻¹ only is not an option: its position tableau is implicit
  (Â₂₂ = 1/4) and fails an order-4 condition (Σ b̂ Â (ĉ c) = 1/8, not 1/12) once the position
  equation depends on Θ.
* Symplectic Euler (order 1) keeps the plain composition, which is exact to O(h²) per step.

A classical Runge–Kutta method (c, A, b) applied to the first-order system y = (q, v),
f = (v, a) (Rouvinen 2003, eq. 94) is the Nyström scheme with Ā = A·A and b̄ = b·A (substitute the
velocity stages into the position stages), so Euler (eq. 98), Heun (eqs. 99–101) and RK4
(eqs. 102–106) share one implementation with the symplectic Euler and the Nyström RKN4 methods,
and so do the fifth- and eighth-order Dormand–Prince formulas (RK5, RK8) that the adaptive RK45
and DOP853 advance with.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import partial

import numpy as np
from scipy.integrate import DOP853, RK45

from mbh._adapters.integrators.base import Integrator
from mbh._harness.common.status import IntegratorState


@dataclass(frozen=True)
class NystromTableau:
    """Coefficients of an explicit Runge–Kutta–Nyström scheme with s stages.

    Attributes
    ----------
    c : ndarray, shape (s,)
        Stage times as fractions of h.
    a : ndarray, shape (s, s)
        Velocity-stage coefficients (strictly lower triangular).
    abar : ndarray, shape (s, s)
        Position-stage coefficients of the h² term (strictly lower triangular).
    b : ndarray, shape (s,)
        Velocity-update weights.
    bbar : ndarray, shape (s,)
        Position-update weights of the h² term.
    runge_kutta : bool
        True when the tableau is a Runge–Kutta method (c, A, b) in Nyström form (Ā = A·A,
        b̄ = b·A), so that it has a Munthe-Kaas form on Lie groups.
    """

    c: np.ndarray
    a: np.ndarray
    abar: np.ndarray
    b: np.ndarray
    bbar: np.ndarray
    runge_kutta: bool = False

    @classmethod
    def from_runge_kutta(cls, c, a, b) -> NystromTableau:
        """The Nyström form of the Butcher tableau (c, A, b) applied to y = (q, v)."""
        c, a, b = (np.array(x, dtype=float) for x in (c, a, b))
        return cls(c=c, a=a, abar=a @ a, b=b, bbar=b @ a, runge_kutta=True)


def nystrom_step(acceleration, advance, t, q, v, h, tableau):
    """One step of an explicit Nyström scheme (module docstring formulas).

    Parameters
    ----------
    acceleration : callable
        ``acceleration(t, q, v) -> ndarray, shape (n,)``.
    advance : callable
        ``advance(q, dq) -> q ⊕ dq``.
    t : float
    q : ndarray, shape (m,)
    v : ndarray, shape (n,)
    h : float
        Step size, s.
    tableau : NystromTableau

    Returns
    -------
    q_new : ndarray, shape (m,)
    v_new : ndarray, shape (n,)
    """
    stages = []
    for i, c_i in enumerate(tableau.c):
        dq = (c_i * h) * v
        v_stage = v
        for j, k_j in enumerate(stages):  # strictly lower triangular: skip the zeros
            if tableau.abar[i, j]:
                dq = dq + (h * h * tableau.abar[i, j]) * k_j
            if tableau.a[i, j]:
                v_stage = v_stage + (h * tableau.a[i, j]) * k_j
        stages.append(acceleration(t + c_i * h, advance(q, dq), v_stage))
    dq = h * v
    v_new = v
    for j, k_j in enumerate(stages):
        if tableau.bbar[j]:
            dq = dq + (h * h * tableau.bbar[j]) * k_j
        if tableau.b[j]:
            v_new = v_new + (h * tableau.b[j]) * k_j
    return advance(q, dq), v_new


def munthe_kaas_step(acceleration, problem, t, q, v, h, tableau):
    """One Runge–Kutta–Munthe-Kaas step of the Runge–Kutta tableau (c, A, b) (module docstring).

    Stages Θ_i = h Σ_j A_ij k_j, V_i = v + h Σ_j A_ij a_j, a_i = a(t + c_i h, q ⊕ Θ_i, V_i) and
    k_i = dexp⁻¹_{Θ_i}(V_i) (``problem.increment_rate``); q_{n+1} = q ⊕ h Σ b_i k_i,
    v_{n+1} = v + h Σ b_i a_i.  Arguments and returns as :func:`nystrom_step` (``problem``
    provides ``advance`` and ``increment_rate``); ``tableau.runge_kutta`` must be true.
    """
    rates, stages = [], []
    for i, c_i in enumerate(tableau.c):
        dq = np.zeros_like(v)
        v_stage = v
        for j, (k_j, a_j) in enumerate(zip(rates, stages)):
            if tableau.a[i, j]:
                dq = dq + (h * tableau.a[i, j]) * k_j
                v_stage = v_stage + (h * tableau.a[i, j]) * a_j
        stages.append(acceleration(t + c_i * h, problem.advance(q, dq), v_stage))
        rates.append(problem.increment_rate(q, dq, v_stage))
    dq = np.zeros_like(v)
    v_new = v
    for b_j, k_j, a_j in zip(tableau.b, rates, stages):
        dq = dq + (h * b_j) * k_j
        v_new = v_new + (h * b_j) * a_j
    return problem.advance(q, dq), v_new


def chart_nystrom_step(acceleration, problem, t, q, v, h, tableau):
    """One step of a Nyström tableau on Θ̈ = F(t, Θ, Θ̇) in the exponential chart at q.

    Stages Θ_i = c_i h v + h² Σ_j Ā_ij F_j, W_i = v + h Σ_j A_ij F_j (chart rates; W = v at Θ = 0),
    V_i = dexp_{Θ_i}(W_i) (``problem.chart_velocity``), a_i = a(t + c_i h, q ⊕ Θ_i, V_i) and
    F_i = ``problem.chart_acceleration(q, Θ_i, W_i, a_i)``; the update uses b̄ and b likewise and
    maps the new chart rate back to a velocity.  Arguments and returns as :func:`nystrom_step`.
    """
    forces = []
    for i, c_i in enumerate(tableau.c):
        dq = (c_i * h) * v
        w = v
        for j, f_j in enumerate(forces):
            if tableau.abar[i, j]:
                dq = dq + (h * h * tableau.abar[i, j]) * f_j
            if tableau.a[i, j]:
                w = w + (h * tableau.a[i, j]) * f_j
        a_i = acceleration(t + c_i * h, problem.advance(q, dq), problem.chart_velocity(q, dq, w))
        forces.append(problem.chart_acceleration(q, dq, w, a_i))
    dq = h * v
    w = v
    for bbar_j, b_j, f_j in zip(tableau.bbar, tableau.b, forces):
        dq = dq + (h * h * bbar_j) * f_j
        w = w + (h * b_j) * f_j
    return problem.advance(q, dq), problem.chart_velocity(q, dq, w)


def step_rule(method, problem, acceleration):
    """The step function ``rule(t, q, v, h, tableau) -> (q_new, v_new)`` that the
    :class:`NystromIntegrator` subclass ``method`` takes on ``problem``, its stages calling
    ``acceleration(t, q, v)``: :func:`nystrom_step` for a Euclidean or commutative configuration
    space (no ``increment_rate`` on the problem) and for order ≤ 1, :func:`munthe_kaas_step` for a
    Runge–Kutta tableau on a non-commutative group, else :func:`chart_nystrom_step`.

    Raises
    ------
    ValueError
        When the chart step needs ``chart_velocity`` or ``chart_acceleration`` and the problem
        lacks them.
    """
    commutative = not hasattr(problem, "increment_rate")
    if commutative or (method.order <= 1 and not method.tableau.runge_kutta):
        return partial(nystrom_step, acceleration, problem.advance)
    if method.tableau.runge_kutta:
        return partial(munthe_kaas_step, acceleration, problem)
    missing = [name for name in ("chart_velocity", "chart_acceleration")
               if not hasattr(problem, name)]
    if missing:
        raise ValueError(f"method {method.name!r} on a non-commutative Lie group steps in the "
                         f"exponential chart and needs the problem's {' and '.join(missing)}, "
                         "which this problem does not provide; use a Runge–Kutta method "
                         "(rk4, heun, euler), which needs only increment_rate")
    return partial(chart_nystrom_step, acceleration, problem)


class NystromIntegrator(Integrator):
    """Fixed-step explicit one-step method defined by the class attribute ``tableau``.

    Picks the step rule once, at construction: :func:`nystrom_step` for a Euclidean or
    commutative configuration space (no ``increment_rate`` on the problem) and for order ≤ 1,
    :func:`munthe_kaas_step` for a Runge–Kutta tableau on a non-commutative group, else
    :func:`chart_nystrom_step`, which needs the problem's ``chart_velocity`` and
    ``chart_acceleration`` (a ValueError says so when they are missing).
    """

    tableau: NystromTableau

    def __init__(self, problem, t0, q0, v0, dt, **params):
        super().__init__(problem, t0, q0, v0, dt, **params)
        self._rule = self._step_rule()

    def _step_rule(self):
        return step_rule(type(self), self.problem, self._acceleration)

    def _step_impl(self):
        t_new = self._target_time()
        q_new, v_new = self._rule(self.t, self.q, self.v, t_new - self.t, self.tableau)
        return t_new, q_new, v_new

    def step_through(self, ends, steps: int) -> IntegratorState:
        """Steps of this method ending at the times ``ends`` (s, increasing, the last on the grid
        ``steps`` grid steps on), each projected and checked as :meth:`step` does; together they
        count as ``steps`` steps (a placed passage, :mod:`mbh._adapters.inhouse.formulations.fold`).  A failure
        leaves the state at the grid point before them.

        Returns
        -------
        status : IntegratorState
        """
        if self.status != IntegratorState.RUNNING:
            return self.status
        t, q, v = self.t, self.q, self.v
        for t_new in ends:
            new = self._checked(t_new, lambda: (t_new, *self._rule(t, q, v, t_new - t,  # noqa: B023
                                                                    self.tableau)))
            if new is None:
                return self.status
            t, q, v = new
        self.t, self.q, self.v = t, q, v
        self.n_steps += steps
        return self.status

    def steps_unchecked(self, count: int, rule) -> IntegratorState:
        """``count`` steps by ``rule``, a step rule of this method (:func:`step_rule`) over a
        right-hand side without the problem's own per-call checks, projected as :meth:`step`
        projects them and checked once, on the last state.

        A finite last state within ``divergence_limit`` keeps all ``count`` steps: the same
        arithmetic as ``count`` calls of :meth:`step` when ``rule``'s right-hand side returns the
        problem's accelerations (``nfev`` counts one evaluation per stage).  Otherwise, or when
        a step raises (anything), the state goes back to where it was and :meth:`step` takes the
        steps again one by one, failing the first bad one with its reason or letting a
        non-problem error through, as it does; the evaluations of the replayed steps are then
        made twice.  NaN and inf carry to the last state, so only a state that leaves the
        divergence limit and comes back within the ``count`` steps goes unnoticed, where checked
        steps would have stopped it.  Checking once per call instead of once per step saves two
        dot products a step (~0.7 µs, an eighth of a Pinocchio symplectic-Euler step).

        Returns
        -------
        status : IntegratorState
            The status after the last step.
        """
        if self.status != IntegratorState.RUNNING or count <= 0:
            return self.status
        limit = self.params["divergence_limit"] ** 2
        project, tableau, t0, dt = self.problem.project, self.tableau, self.t0, self.dt
        t, q, v = self.t, self.q, self.v
        try:
            for k in range(self.n_steps + 1, self.n_steps + count + 1):
                t_new = t0 + k * dt  # as _target_time(): no accumulated drift
                q, v = rule(t, q, v, t_new - t, tableau)
                q, v = project(t_new, q, v)  # two calls: a star-unpacked one costs ~0.1 µs more
                t = t_new
            q, v = np.asarray(q, dtype=float), np.asarray(v, dtype=float)
            good = float(q.dot(q)) <= limit and float(v.dot(v)) <= limit
        except Exception:  # noqa: BLE001 — replayed by step(), which words or re-raises it
            good = False
        if not good:  # NaN fails the comparisons too
            for _ in range(count):
                if self.step() != IntegratorState.RUNNING:
                    break
            return self.status
        self.t, self.q, self.v = t, q, v
        self.n_steps += count
        self.nfev += count * tableau.c.size
        return self.status


class Euler(NystromIntegrator):
    """Explicit Euler, y_{n+1} = y_n + h f(t_n, y_n) (Rouvinen 2003, eq. 98); order 1."""

    name = "euler"
    order = 1
    tableau = NystromTableau.from_runge_kutta(c=[0.0], a=[[0.0]], b=[1.0])


class SymplecticEuler(NystromIntegrator):
    """Symplectic Euler: v_{n+1} = v_n + h a(t_n, q_n, v_n), q_{n+1} = q_n ⊕ h v_{n+1}; order 1.

    As a Nyström scheme: one stage, b = b̄ = 1.
    """

    name = "symplectic-euler"
    order = 1
    tableau = NystromTableau(c=np.array([0.0]), a=np.zeros((1, 1)), abar=np.zeros((1, 1)),
                             b=np.array([1.0]), bbar=np.array([1.0]))


class Heun(NystromIntegrator):
    """Heun's method (improved Euler), Rouvinen 2003, eqs. 99–101; order 2.

    y_{n+1} = y_n + h/2 (k_1 + k_2) with k_1 = f(t_n, y_n), k_2 = f(t_n + h, y_n + h k_1).
    Eq. 99 prints ``(k_1 + 2 k_2)``, which is not even consistent (weights sum to 3/2); the
    weights here are the standard ones the text's names (Heun, modified trapezoid) refer to.
    """

    name = "heun"
    order = 2
    tableau = NystromTableau.from_runge_kutta(c=[0.0, 1.0], a=[[0.0, 0.0], [1.0, 0.0]],
                                              b=[0.5, 0.5])


class RK4(NystromIntegrator):
    """Classical fourth-order Runge–Kutta method, Rouvinen 2003, eqs. 102–106; order 4."""

    name = "rk4"
    order = 4
    tableau = NystromTableau.from_runge_kutta(
        c=[0.0, 0.5, 0.5, 1.0],
        a=[[0.0, 0.0, 0.0, 0.0], [0.5, 0.0, 0.0, 0.0], [0.0, 0.5, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]],
        b=[1 / 6, 1 / 3, 1 / 3, 1 / 6])


class RKN4(NystromIntegrator):
    """Classical fourth-order Runge–Kutta–Nyström method for q̈ = a(t, q, v) (Rouvinen 2003, §4.1).

    The velocity-dependent form (E. Kreyszig, *Advanced Engineering Mathematics*, RKN method):
    with k_1 = h/2 a(t, q, v), K = h/2 (v + k_1/2), k_2 = h/2 a(t + h/2, q + K, v + k_1),
    k_3 = h/2 a(t + h/2, q + K, v + k_2), L = h (v + k_3), k_4 = h/2 a(t + h, q + L, v + 2 k_3):
    q_{n+1} = q + h (v + (k_1 + k_2 + k_3)/3), v_{n+1} = v + (k_1 + 2 k_2 + 2 k_3 + k_4)/3.
    The velocity stages and weights are RK4's; the position stages differ (Ā_21 = Ā_31 = 1/8,
    Ā_43 = 1/2, where RK4 in Nyström form has Ā_31 = 1/4, Ā_42 = 1/2): positions come straight
    from the accelerations, and stages 2 and 3 share one position.  Order 4.
    """

    name = "rkn4"
    order = 4
    tableau = replace(
        RK4.tableau, runge_kutta=False,
        abar=np.array([[0.0, 0.0, 0.0, 0.0], [0.125, 0.0, 0.0, 0.0], [0.125, 0.0, 0.0, 0.0],
                       [0.0, 0.0, 0.5, 0.0]]))


class RK5(NystromIntegrator):
    """Dormand–Prince's explicit fifth-order Runge–Kutta formula at a fixed step; order 5.

    The six-stage solution formula of RK45 (J. R. Dormand, P. J. Prince, *A family of embedded
    Runge–Kutta formulae*, J. Comput. Appl. Math. 6, 1980; Hairer, Nørsett, Wanner I, §II.5)
    without its error estimator: between RK4 and RK8 in accuracy on the front.  SciPy's
    coefficients (``scipy.integrate.RK45``'s ``C``, ``A``, ``B``; ``A`` lacks the last, all-zero
    column of the square tableau).  Like :class:`RK8`, not for singular passages: its error there
    grows as the step shrinks (figures: docs/measurements.md, section "Integrators").
    """

    name = "rk5"
    order = 5
    tableau = NystromTableau.from_runge_kutta(
        c=RK45.C, a=np.hstack([RK45.A, np.zeros((RK45.n_stages, 1))]), b=RK45.B)


class RK8(NystromIntegrator):
    """Dormand–Prince's explicit eighth-order Runge–Kutta formula at a fixed step; order 8.

    The 12-stage solution formula of DOP853 (E. Hairer, S. P. Nørsett, G. Wanner, *Solving
    Ordinary Differential Equations I*, 2nd ed., §II.10; P. J. Prince, J. R. Dormand, *High order
    embedded Runge–Kutta formulae*, J. Comput. Appl. Math. 7, 1981), without its error estimators
    and step control: the explicit Runge–Kutta family of Rouvinen 2003, §4 carried to a high order, for
    the accurate end of the front, where a step of 1e-2 s already reaches 1e-9 rad on the seed
    scenes.  The coefficients are SciPy's (``scipy.integrate.DOP853``'s ``C``, ``A``, ``B``).

    Through singular passages its error grows as the step shrinks: its twelve stages probe the
    configuration close to a fold, where the index-1 accelerations grow like the inverse of
    Φ_q's smallest singular value.  On the plain grid it can lose to rk4 by orders of magnitude
    there; placed passages (:mod:`mbh._adapters.inhouse.formulations.fold`) with proj_tol 1e-15 bring it back to
    ~1e-10 m on double_fourbar.  Away from folds it is the most accurate method per cost.  The
    figures and the commands that reproduce them: docs/measurements.md, "rk8 through singular
    passages".
    """

    name = "rk8"
    order = 8
    tableau = NystromTableau.from_runge_kutta(c=DOP853.C, a=DOP853.A, b=DOP853.B)
