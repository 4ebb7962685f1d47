"""Explicit one-step methods for q̈ = a(t, q, v), all written as Runge–Kutta–Nyström schemes.

A Nyström tableau (c, A, Ā, b, b̄) advances (q, v) by h with stages

    Q_i = q ⊕ h (c_i v + h Σ_j Ā_ij a_j),   V_i = v + h Σ_j A_ij a_j,
    a_i = a(t + c_i h, Q_i, V_i),
    q_{n+1} = q ⊕ h (v + h Σ_i b̄_i a_i),     v_{n+1} = v + h Σ_i b_i a_i.

Every position change is ``problem.advance(q, dq)`` with ``dq`` h times a combination of the
velocity and of h·accelerations — a tangent vector of shape (n,) — so these methods also integrate
on a Lie group (``len(q) != len(v)``).

A classical Runge–Kutta method (c, A, b) applied to the first-order system y = (q, v),
f = (v, a) (seed 002 eq. 94) is the Nyström scheme with Ā = A·A and b̄ = b·A (substitute the
velocity stages into the position stages), so Euler (eq. 98), Heun (eqs. 99–101) and RK4
(eqs. 102–106) share one implementation with the symplectic Euler and the Nyström RKN4 methods.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from adapters.integrators.base import Integrator


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
    """

    c: np.ndarray
    a: np.ndarray
    abar: np.ndarray
    b: np.ndarray
    bbar: np.ndarray

    @classmethod
    def from_runge_kutta(cls, c, a, b) -> NystromTableau:
        """The Nyström form of the Butcher tableau (c, A, b) applied to y = (q, v)."""
        c, a, b = (np.array(x, dtype=float) for x in (c, a, b))
        return cls(c=c, a=a, abar=a @ a, b=b, bbar=b @ a)


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


class NystromIntegrator(Integrator):
    """Fixed-step explicit one-step method defined by the class attribute ``tableau``."""

    tableau: NystromTableau

    def _step_impl(self):
        t_new = self._target_time()
        q_new, v_new = nystrom_step(self._acceleration, self.problem.advance, self.t, self.q,
                                    self.v, t_new - self.t, self.tableau)
        return t_new, q_new, v_new


class Euler(NystromIntegrator):
    """Explicit Euler, y_{n+1} = y_n + h f(t_n, y_n) (seed 002 eq. 98); order 1."""

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
    """Heun's method (improved Euler), seed 002 eqs. 99–101; order 2.

    y_{n+1} = y_n + h/2 (k_1 + k_2) with k_1 = f(t_n, y_n), k_2 = f(t_n + h, y_n + h k_1).
    Eq. 99 prints ``(k_1 + 2 k_2)``, which is not even consistent (weights sum to 3/2); the
    weights here are the standard ones the text's names (Heun, modified trapezoid) refer to.
    """

    name = "heun"
    order = 2
    tableau = NystromTableau.from_runge_kutta(c=[0.0, 1.0], a=[[0.0, 0.0], [1.0, 0.0]],
                                              b=[0.5, 0.5])


class RK4(NystromIntegrator):
    """Classical fourth-order Runge–Kutta method, seed 002 eqs. 102–106; order 4."""

    name = "rk4"
    order = 4
    tableau = NystromTableau.from_runge_kutta(
        c=[0.0, 0.5, 0.5, 1.0],
        a=[[0.0, 0.0, 0.0, 0.0], [0.5, 0.0, 0.0, 0.0], [0.0, 0.5, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]],
        b=[1 / 6, 1 / 3, 1 / 3, 1 / 6])


class RKN4(NystromIntegrator):
    """Classical fourth-order Runge–Kutta–Nyström method for q̈ = a(t, q, v) (seed 002 §4.1).

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
        RK4.tableau,
        abar=np.array([[0.0, 0.0, 0.0, 0.0], [0.125, 0.0, 0.0, 0.0], [0.125, 0.0, 0.0, 0.0],
                       [0.0, 0.0, 0.5, 0.0]]))
