"""Linear multistep methods: Adams–Bashforth, Adams–Moulton, Gear (BDF), and the AB–AM
predictor–corrector (Rouvinen 2003, §4.2).

All of them work on the first-order state y = (q, v), f(t, y) = (v, a(t, q, v)) (eq. 94), with the
general form (eq. 107, normalised to α_0 = 1 and with the f terms moved to the right)

    Σ_{j=0}^{p} α_j y_{n+1−j} = h Σ_{j=0}^{k} β_j f_{n+1−j}.

β_0 = 0 gives an explicit method; otherwise the implicit stage is solved by Newton iteration
(:mod:`.newton`).  The methods are not self-starting: the first ``history_length − 1`` steps are
classical RK4 steps (eqs. 102–106) and the method takes over once that many past points exist.
Each step evaluates f once at the current (projected) state, so the history always holds f of the
states actually accepted (a start step therefore costs 1 + 4 acceleration evaluations).  Positions are combined linearly, so ``len(q) == len(v)`` is required.

Coefficients are the seed's tables, transcribed with their printed denominators:

* table 2 (Adams–Bashforth): ``abk`` uses k past f values and has order k.  The table writes the
  b_j with eq. 107's sign (−3, 1 for k = 2, …); its k = 1 row prints b_1 = +1, inconsistent with
  the other rows; AB1 is the explicit Euler method (eq. 98).
* table 3 (Adams–Moulton): row k uses k values of f (f_{n+1} … f_{n+2−k}), i.e. k − 1 past steps,
  and has order k.  ``amk`` follows the table: **amk has order k** (am1 = backward Euler,
  am2 = trapezoidal rule, am4 = eq. 109).
* table 4 (Gear): ``bdfp`` uses p past values of y and has order p.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from mbh._adapters.integrators.base import Integrator
from mbh._adapters.integrators.newton import NewtonSolver
from mbh._adapters.integrators.nystrom import RK4, nystrom_step

#: Table 2: k → (denominator, (β_1 … β_k)) for y_{n+1} = y_n + h/D Σ β_j f_{n+1−j}.
ADAMS_BASHFORTH = {
    1: (1, (1,)),
    2: (2, (3, -1)),
    3: (12, (23, -16, 5)),
    4: (24, (55, -59, 37, -9)),
    5: (720, (1901, -2774, 2616, -1274, 251)),
}
#: Table 3: k → (denominator, (β_0 … β_{k−1})) for y_{n+1} = y_n + h/D Σ β_j f_{n+1−j}.
ADAMS_MOULTON = {
    1: (1, (1,)),
    2: (2, (1, 1)),
    3: (12, (5, 8, -1)),
    4: (24, (9, 19, -5, 1)),
    5: (720, (251, 646, -264, 106, -19)),
}
#: Table 4 as printed: p → (b_0, (a_0 … a_p)) for Σ a_j y_{n+1−j} + h b_0 f_{n+1} = 0.
GEAR = {
    1: (-1, (1, -1)),
    2: (-2, (3, -4, 1)),
    3: (-6, (11, -18, 9, -2)),
    4: (-12, (25, -48, 36, -16, 3)),
}


def adams_coefficients(denominator, betas, implicit):
    """(α, β) of an Adams method from a table row; shapes (2,) and (k + 1,)."""
    beta = np.array(betas, dtype=float) / denominator
    if not implicit:
        beta = np.concatenate([[0.0], beta])
    return np.array([1.0, -1.0]), beta


def gear_coefficients(b0, alphas):
    """(α, β) of a Gear/BDF method from a table 4 row; shapes (p + 1,) and (1,)."""
    alpha = np.array(alphas, dtype=float)
    return alpha / alpha[0], np.array([-b0 / alpha[0]])


def points_read(alpha, beta):
    """Number of accepted points (y_n, f_n), (y_{n−1}, f_{n−1}), … that (α, β) reads."""
    return max(alpha.size, beta.size) - 1


class MultistepIntegrator(Integrator):
    """Fixed-step multistep method on y = (q, v): history keeping and the RK4 start.

    Subclasses define the property ``history_length`` (points read) and ``_multistep``.
    """

    euclidean_only = True

    def __init__(self, problem, t0, q0, v0, dt, **params):
        super().__init__(problem, t0, q0, v0, dt, **params)
        #: (y_{n+1−j}, f_{n+1−j}) for j = 1, 2, …, newest first; shapes (2n,).
        self.history = deque(maxlen=self.history_length)

    def _step_impl(self):
        t_new = self._target_time()
        a = self._acceleration(self.t, self.q, self.v)
        y = np.concatenate([self.q, self.v])
        self.history.appendleft((y, np.concatenate([self.v, a])))
        if len(self.history) < self.history_length:
            q_new, v_new = nystrom_step(self._acceleration, self.problem.advance, self.t, self.q,
                                        self.v, self.dt, RK4.tableau)
            return t_new, q_new, v_new
        y_new = self._multistep(t_new, a)
        return t_new, y_new[:self.n], y_new[self.n:]

    def _explicit_part(self, alpha, beta):
        """ψ = −Σ_{j≥1} α_j y_{n+1−j} + h Σ_{j≥1} β_j f_{n+1−j}, shape (2n,) (eq. 107)."""
        psi = np.zeros(2 * self.n)
        for j, (y, f) in enumerate(self.history, start=1):
            if j < alpha.size:
                psi -= alpha[j] * y
            if j < beta.size:
                psi += self.dt * beta[j] * f
        return psi

    def _f(self, t, y):
        """f(t, y) = (v, a(t, q, v)), shape (2n,)."""
        return np.concatenate([y[self.n:], self._acceleration(t, y[:self.n], y[self.n:])])

    @property
    def history_length(self) -> int:
        raise NotImplementedError

    def _multistep(self, t_new, a):
        """y_{n+1}, shape (2n,), once the history is full; ``a`` is a(t_n, q_n, v_n)."""
        raise NotImplementedError


class LinearMultistep(MultistepIntegrator):
    """A method of the form eq. 107 given by the class attributes ``alpha``, ``beta``.

    Implicit methods (β_0 ≠ 0) take the parameters ``tol`` and ``max_iter`` of the Newton
    iteration, started from the explicit Euler predictor y_n + h f_n.
    """

    alpha: np.ndarray
    beta: np.ndarray

    def __init__(self, problem, t0, q0, v0, dt, **params):
        super().__init__(problem, t0, q0, v0, dt, **params)
        if self.beta[0] != 0.0:
            self.newton = NewtonSolver(self, self.params["tol"], self.params["max_iter"])

    @property
    def history_length(self) -> int:
        return points_read(self.alpha, self.beta)

    def _multistep(self, t_new, a):
        psi = self._explicit_part(self.alpha, self.beta)
        if self.beta[0] == 0.0:
            return psi
        y, f = self.history[0]
        return self.newton.solve(t_new, y + self.dt * f, psi, self.dt * self.beta[0],
                                 jacobian_point=(self.t, y, a))


class PredictorCorrector(MultistepIntegrator):
    """PECE predictor–corrector (Rouvinen 2003, fig. 15): predict with the explicit method
    (``predictor`` = (α, β)), evaluate f there, correct once with the implicit method
    (``corrector``), and evaluate f at the corrected point (at the start of the next step).
    Two acceleration evaluations per step, no iteration.
    """

    predictor: tuple[np.ndarray, np.ndarray]
    corrector: tuple[np.ndarray, np.ndarray]

    @property
    def history_length(self) -> int:
        return max(points_read(*self.predictor), points_read(*self.corrector))

    def _multistep(self, t_new, a):
        y_predicted = self._explicit_part(*self.predictor)
        alpha, beta = self.corrector
        return self._explicit_part(alpha, beta) + self.dt * beta[0] * self._f(t_new, y_predicted)


def _method(base, class_name, name, order, doc, defaults=None, **coefficients):
    """A concrete subclass of ``base`` with its coefficients as class attributes."""
    attributes = {"__module__": __name__, "__doc__": doc, "name": name, "order": order,
                  **coefficients}
    if defaults is not None:
        attributes["defaults"] = defaults
    return type(class_name, (base,), attributes)


ADAMS_MOULTON_DEFAULTS = {"tol": 1e-10, "max_iter": 10}
#: Gear's Newton iteration stops where Adams–Moulton's does.  The seed's comparison iterates to
#: 1e-5 (``mbh seed-table`` passes that), but a step's iteration error then outweighs the
#: method's truncation error and adds up over the steps, so the error no longer falls with dt:
#: bdf4+direct, first 2 s, largest output error against the reference at dt 1e-2 / 1e-3 /
#: 1e-4 s, tol 1e-5 → 1e-10: bricard 7.4e-7 / 6.2e-7 / 6.2e-9 → 4.8e-7 / 4.8e-11 / 3.4e-13;
#: slider_crank_planar 0.57 / 7.0e-4 / 1.5e-4 → Newton failure at 1.65 s / 6.1e-4 / 4.4e-8;
#: parallelogram_fourbar 5.5e-5 / 6.3e-6 / 1.9e-5, all ``ok``, → failed at the first singular
#: passage, 4.0e-6 / 4.3e-10 / 9.7e-14 before it; Andrews' squeezer at 1e-5 s 1.8e-6 → 4.9e-8.
#: It costs up to a third more time (bricard at 1e-4 s: 11.1 → 14.6 s).
GEAR_DEFAULTS = {"tol": 1e-10, "max_iter": 10}

ADAMS_BASHFORTH_METHODS = [
    _method(LinearMultistep, f"AdamsBashforth{k}", f"ab{k}", k,
            f"Adams–Bashforth, {k} step(s), order {k} (Rouvinen 2003, table 2).",
            **dict(zip(("alpha", "beta"), adams_coefficients(*row, implicit=False))))
    for k, row in ADAMS_BASHFORTH.items()
]
ADAMS_MOULTON_METHODS = [
    _method(LinearMultistep, f"AdamsMoulton{k}", f"am{k}", k,
            f"Adams–Moulton of order {k} ({k - 1} past step(s); Rouvinen 2003, table 3), Newton "
            "iteration to ``tol``.", defaults=ADAMS_MOULTON_DEFAULTS,
            **dict(zip(("alpha", "beta"), adams_coefficients(*row, implicit=True))))
    for k, row in ADAMS_MOULTON.items()
]
GEAR_METHODS = [
    _method(LinearMultistep, f"Gear{p}", f"bdf{p}", p,
            f"Gear's backward differentiation formula of order {p} (Rouvinen 2003, table 4), Newton "
            "iteration to ``tol`` with a re-used finite-difference Jacobian.",
            defaults=GEAR_DEFAULTS,
            **dict(zip(("alpha", "beta"), gear_coefficients(*row))))
    for p, row in GEAR.items()
]
ABM4 = _method(PredictorCorrector, "AdamsBashforthMoulton4", "abm4", 4,
               "PECE with the AB4 predictor (eq. 108) and the AM4 corrector (eq. 109); order 4.",
               predictor=adams_coefficients(*ADAMS_BASHFORTH[4], implicit=False),
               corrector=adams_coefficients(*ADAMS_MOULTON[4], implicit=True))
