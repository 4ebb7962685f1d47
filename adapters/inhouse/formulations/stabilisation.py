"""Formulations and constraint stabilisations as interchangeable strategies (Rouvinen 2003, ch. 3 and 5).

Each strategy is a second-order problem for :mod:`mbh._adapters.integrators`: it provides
``acceleration(t, q, v)`` (an index-1 form of the equations of motion) and ``project(t, q, v)``
(a post-step correction, the identity unless the method corrects the state).

==============  =========================================================================
name            method
==============  =========================================================================
``none``        augmented form Φ_q q̈ = γ, no stabilisation (Rouvinen 2003, eq. 77)
``baumgarte``   γ* = γ − 2αΦ̇ − β²Φ (eq. 110); ``auto`` uses α = 1/Δt, β = √2/Δt (eq. 111)
``penalty``     (M + Φ_qᵀαΦ_q) q̈ = Q − Φ_qᵀα(−γ + 2ΩμΦ̇ + Ω²Φ) (eq. 115–116)
``auglag``      augmented Lagrangian, iterated to a tolerance (eq. 117–120)
``geometric``   position projection with the Moore–Penrose inverse (eq. 127), then the
                energy-based velocity correction (eq. 128–136)
``direct``      direct violation correction: position (eq. 127) and velocity (eq. 137) projection
==============  =========================================================================

Coordinate partitioning (eq. 78–89) lives in :mod:`mbh._adapters.inhouse.formulations.partition`.

A mechanism with redundant constraints keeps only the independent equations found by the rank
analysis at the initial configuration (Frączek & Wojtyra 2009, §1.3.2); its reaction split is then not unique.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from mbh._adapters.inhouse.bodies.constraints import ConstraintSystem
from mbh._adapters.inhouse.formulations.dynamics import acceleration_jacobian, index1_acceleration
from mbh._adapters.inhouse.formulations.mass_and_forces import Dynamics
from mbh._adapters.integrators.base import SecondOrderSystem
from mbh._adapters.inhouse.numerics.banded import (conditioning_indicator,
                                                   min_norm_correction_and_indicator,
                                                   pattern_matvec)
from mbh._adapters.inhouse.formulations.fold import SAFE_INDICATOR
from mbh._adapters.inhouse.numerics.rank import RANK_TOLERANCE, full_pivot_elimination
from mbh._adapters.inhouse.bodies.states import body_states
from mbh._harness.model.mechanism import Mechanism


class Formulation(SecondOrderSystem):
    """Index-1 equations of motion over absolute coordinates; subclasses change γ, the solve or
    the post-step correction.

    Parameters
    ----------
    mech : Mechanism
    q0 : ndarray, shape (n,)
        Assembled initial configuration (the rank analysis that picks independent rows runs here).
    dt : float
        Step size, s (for the Δt-based parameter rules).
    **params
        The strategy's parameters (:attr:`defaults`).

    Attributes
    ----------
    counters : dict
        ``jacobian_evals``, ``factorizations``, ``newton_iterations`` spent by the strategy.
    notes : list of str
    """

    name = ""
    description = ""
    defaults: dict = {}
    #: Whether every constraint row enters the solves (rank-revealing, so redundant rows are
    #: harmless and no start-time choice of rows can turn ill-conditioned later: on Bricard's
    #: loop the rows kept at the start lost rank at mid-swing, σ_min 1.4e-5); coordinate
    #: partitioning needs a square dependent block and keeps the independent rows only.
    keeps_redundant_rows = True

    @classmethod
    def unsupported_reason(cls, mech: Mechanism, integrator_class) -> str | None:
        """Why this strategy cannot run ``mech`` with that integrator, or None."""
        return None

    def __init__(self, mech: Mechanism, q0: np.ndarray, dt: float, **params):
        self.mech = mech
        self.dynamics = Dynamics(mech)
        self.constraints = ConstraintSystem(mech)
        self.n = self.constraints.layout.n
        self.dt = dt
        self.params = {**self.defaults, **params}
        rank, rows = full_pivot_elimination(self.constraints.jacobian(q0))
        self.notes = []
        if self.keeps_redundant_rows:
            self.rows = np.arange(self.constraints.m)
        else:
            self.rows = np.sort(rows)
        if rank < self.constraints.m:
            dropped = sorted(set(range(self.constraints.m)) - set(np.sort(rows).tolist()))
            labels = ", ".join(self.constraints.labels[i] for i in dropped)
            what = ("kept: the solves are rank-revealing (a certified pivoted Cholesky "
                    "factorisation, else the truncated SVD), the reactions the minimum-norm split"
                    if self.keeps_redundant_rows else
                    "dropped; the reaction split among the redundant joints is not unique")
            self.notes.append(f"{len(dropped)} redundant equation(s) ({labels}) {what}")
        self.counters = {"jacobian_evals": 0, "factorizations": 0, "newton_iterations": 0}
        self.indicators = None
        every_row = self.rows.size == self.constraints.m
        if self.places_passages and self.params["passage"] and every_row:
            start = conditioning_indicator(
                np.ascontiguousarray(self.constraints.jacobian(q0, 0.0)[self.rows]),
                self.constraints.sparsity.arrays)
            self.indicators = np.array([start, start])

    #: Whether :meth:`project` changes the state (dense output between steps is then projected
    #: before it is read, :class:`~mbh._adapters.inhouse.stepping.driver.InhouseStepper`).
    corrects = False
    #: Whether the strategy measures the conditioning indicator ρ̂ at every step end for the
    #: placed passages of singular positions (:mod:`mbh._adapters.inhouse.formulations.fold`; its parameter
    #: ``passage``: 1 places them, 0 steps the plain grid): ``indicators`` then holds ρ̂ at the
    #: last two step ends (both ρ̂ at the start before the first), else it is None (also set so
    #: by :meth:`Passages.of <mbh._adapters.inhouse.formulations.fold.Passages.of>` for an integrator that cannot
    #: place passages, and kept only when every constraint row enters the solves: ρ̂ of a subset
    #: of Φ_q's rows says nothing about the whole).
    places_passages = False
    #: The ρ̂-distance from a crossing that a placed passage keeps its stages at
    #: (:data:`~mbh._adapters.inhouse.formulations.fold.SAFE_INDICATOR` for the index-1 strategies).
    passage_clearance = SAFE_INDICATOR

    def _record_indicator(self, jac):
        """Shift ``indicators`` and put ρ̂ of ``jac`` (Φ_q on the kept rows, C-contiguous) last;
        nothing when no indicator is kept."""
        if self.indicators is not None:
            self._push_indicator(conditioning_indicator(jac, self.constraints.sparsity.arrays))

    def _push_indicator(self, indicator: float):
        """Shift ``indicators`` and put ``indicator`` last; nothing when none is kept."""
        if self.indicators is not None:
            self.indicators[0], self.indicators[1] = self.indicators[1], indicator

    # -- constraint pieces on the independent rows ------------------------------------------
    def jacobian(self, t, q):
        self.counters["jacobian_evals"] += 1
        return self.constraints.jacobian(q, t)[self.rows]

    def phi(self, t, q):
        return self.constraints.phi(q, t)[self.rows]

    def gamma(self, t, q, v):
        return self.constraints.gamma(q, v, t)[self.rows]

    # -- the index-1 right-hand side ---------------------------------------------------------
    #: Baumgarte gains (α, β) of the right-hand side γ − 2αΦ̇ − β²Φ; zero: plain γ.
    gains = (0.0, 0.0)

    def acceleration(self, t, q, v):
        """q̈ from the augmented system (Rouvinen 2003, eq. 77), one compiled call (:func:`index1_acceleration`)."""
        self.counters["jacobian_evals"] += 1
        self.counters["factorizations"] += 1
        return index1_acceleration(np.ascontiguousarray(q), np.ascontiguousarray(v), float(t),
                                   *self.gains, self.rows, self.constraints.kernel_args,
                                   self.dynamics.kernel_args, self.constraints.sparsity.arrays)

    @property
    def acceleration_jacobian(self):
        """:meth:`_compiled_jacobian` for the index-1 acceleration of this class; None when a
        subclass computes the acceleration another way (the integrators then difference it)."""
        if type(self).acceleration is not Formulation.acceleration:
            return None
        return self._compiled_jacobian

    def _compiled_jacobian(self, t, q, v, a0):
        """[∂q̈/∂q, ∂q̈/∂q̇] at (t, q, q̇), shape (n, 2n), by forward differences of the fused
        right-hand side in one compiled call (:func:`~mbh._adapters.inhouse.formulations.dynamics.
        acceleration_jacobian`); ``a0`` = :meth:`acceleration` there.  The implicit integrators
        use it instead of differencing from Python (2n evaluations either way)."""
        self.counters["jacobian_evals"] += 2 * self.n
        self.counters["factorizations"] += 2 * self.n
        return acceleration_jacobian(np.ascontiguousarray(q), np.ascontiguousarray(v), float(t),
                                     *self.gains, self.rows, self.constraints.kernel_args,
                                     self.dynamics.kernel_args, self.constraints.sparsity.arrays,
                                     np.ascontiguousarray(a0))

    def start(self, q, v):
        """Called once with the initial state before the first step (no-op here)."""

    def warm_up(self, q, v):
        """Evaluate every compiled kernel once, so that compilation stays out of timed stepping
        (the Jacobian kernel directly: its evaluations are not the method's)."""
        q, v = self.reduce(q, v)
        a0 = self.acceleration(0.0, q, v)
        if self.acceleration_jacobian is not None:
            acceleration_jacobian(q, v, 0.0, *self.gains, self.rows, self.constraints.kernel_args,
                                  self.dynamics.kernel_args, self.constraints.sparsity.arrays, a0)

    # -- the integrated state (identity here; reduced by coordinate partitioning) -----------
    def reduce(self, q, v):
        """Integrated state from a full state (q, q̇)."""
        return q, v

    def expand(self, t, q, v):
        """Full state (q, q̇) from the integrated state."""
        return q, v

    def needs_repartition(self, q_full) -> bool:
        """True when the integrated coordinates must be chosen again (partitioning only)."""
        return False

    def choose_partition(self, q_full) -> None:
        """Choose the integrated coordinates again at q_full (partitioning only)."""


class _Unprojected(Formulation):
    """A strategy that leaves the state as the step made it; with placed passages on it
    evaluates Φ_q at each step end for ρ̂ (:attr:`Formulation.places_passages`)."""

    places_passages = True
    defaults = {"passage": 1}

    def project(self, t, q, v):
        if self.indicators is not None:
            self._record_indicator(np.ascontiguousarray(self.jacobian(t, q)))
        return q, v


class NoStabilisation(_Unprojected):
    name = "none"
    description = "augmented Lagrange-multiplier form, no stabilisation (Rouvinen 2003, eq. 77)"


class Baumgarte(_Unprojected):
    name = "baumgarte"
    description = ("Baumgarte: γ − 2αΦ̇ − β²Φ (Rouvinen 2003, eq. 110); auto=true uses α = 1/Δt, "
                   "β = √2/Δt (eq. 111)")
    defaults = {**_Unprojected.defaults, "alpha": 5.0, "beta": 5.0, "auto": False}

    def __init__(self, mech, q0, dt, **params):
        super().__init__(mech, q0, dt, **params)
        if self.params["auto"]:
            self.params["alpha"], self.params["beta"] = 1.0 / dt, np.sqrt(2.0) / dt
        self.gains = (float(self.params["alpha"]), float(self.params["beta"]))


class Penalty(Formulation):
    name = "penalty"
    description = ("penalty formulation (Rouvinen 2003, eq. 115–116); penalty=0 means 1e7 × the largest "
                   "mass-matrix entry")
    defaults = {"penalty": 0.0, "omega": 10.0, "mu": 1.0}

    def __init__(self, mech, q0, dt, **params):
        super().__init__(mech, q0, dt, **params)
        if self.params["penalty"] <= 0:
            mass, _ = self.dynamics.mass_and_forces(0.0, q0, np.zeros_like(q0))
            self.params["penalty"] = 1e7 * float(np.abs(mass).max())

    def _penalty_terms(self, t, q, v):
        """Pieces of eq. 116: Q, Φ_q, the factorised M + Φ_qᵀαΦ_q, and the constraint target
        c = γ − 2ΩμΦ̇ − Ω²Φ so that Φ̈ + 2ΩμΦ̇ + Ω²Φ = Φ_q q̈ − c."""
        alpha, omega, mu = self.params["penalty"], self.params["omega"], self.params["mu"]
        q, v = np.ascontiguousarray(q), np.ascontiguousarray(v)
        mass, force = self.dynamics.mass_and_forces(t, q, v)
        jac = self.jacobian(t, q)
        target = self.gamma(t, q, v) - 2.0 * omega * mu * (jac @ v) - omega ** 2 * self.phi(t, q)
        self.counters["factorizations"] += 1
        lu = scipy.linalg.lu_factor(mass + alpha * jac.T @ jac, check_finite=False)
        return force, jac, lu, target

    def acceleration(self, t, q, v):
        force, jac, lu, target = self._penalty_terms(t, q, v)
        return scipy.linalg.lu_solve(lu, force + self.params["penalty"] * jac.T @ target,
                                     check_finite=False)


class AugmentedLagrangian(Penalty):
    name = "auglag"
    description = ("augmented Lagrangian (Rouvinen 2003, eq. 117–120): multipliers updated until the "
                   "accelerations change less than tol (relative)")
    defaults = {**Penalty.defaults, "al_tol": 1e-10, "al_max_iter": 50}

    def acceleration(self, t, q, v):
        # λ*₀ = 0 makes the first iterate the penalty solution (eq. 120 starts from M q̈₀ = Q,
        # which is singular for Euler parameters, M θ = 0); then eq. 119 updates λ*.
        alpha = self.params["penalty"]
        force, jac, lu, target = self._penalty_terms(t, q, v)
        multipliers = np.zeros(jac.shape[0])
        acc = None
        for _ in range(int(self.params["al_max_iter"])):
            self.counters["newton_iterations"] += 1
            rhs = force - jac.T @ multipliers + alpha * jac.T @ target
            new = scipy.linalg.lu_solve(lu, rhs, check_finite=False)
            multipliers = multipliers + alpha * (jac @ new - target)
            converged = acc is not None and (
                np.max(np.abs(new - acc)) <= self.params["al_tol"] * max(1.0, np.max(np.abs(new))))
            acc = new
            if converged:
                break
        return acc


class _Projection(Formulation):
    """Position projection with the Moore–Penrose inverse, iterated (Rouvinen 2003, eq. 121–127).

    The pseudo-inverse is truncated (:func:`truncated_solve`): singular values of Φ_q below
    ``singular_cut`` × its conditioning at the start (σ_r/σ_1, r the rank there) × its largest
    are left out.  Near a singular position the constraint set is two branches crossing; a
    configuration that meets Φ only to a residual ε sits on the hyperbola ψ·b = ε, and a full
    projection of the velocity there turns it towards the other branch (a rate error ≈ εV/ψ²
    at a distance ψ from the crossing, which small steps come close to).  Truncated, the
    projection leaves the lost direction to the integrator while σ is small; the default
    ``singular_cut`` 5e-2 is the most accurate of those tried on double_fourbar (figures:
    docs/measurements.md, section "In-house formulation").  A tight proj_tol matters as much:
    Newton stopped at |Φ| = ε leaves the state on the hyperbola ψ·b = ε.
    """

    defaults = {"proj_tol": 1e-12, "proj_max_iter": 10, "singular_cut": 5e-2}
    corrects = True

    def __init__(self, mech, q0, dt, **params):
        super().__init__(mech, q0, dt, **params)
        self.cut = projection_cut(self.jacobian(0.0, q0), self.params["singular_cut"])

    def _min_norm(self, jac, residual):
        """Φ_q⁺ r (eq. 126), truncated (see the class docstring), and ρ̂ of ``jac`` from the
        same factorisation (:func:`~mbh._adapters.inhouse.numerics.banded.min_norm_correction_and_indicator`).
        """
        self.counters["factorizations"] += 1
        return min_norm_correction_and_indicator(
            np.ascontiguousarray(jac), np.ascontiguousarray(residual), self.cut,
            self.constraints.sparsity.arrays)

    def warm_up(self, q, v):
        super().warm_up(q, v)
        self._min_norm(self.jacobian(0.0, q), self.phi(0.0, q))

    def project_position(self, t, q):
        """Newton on Φ(q) = 0 with Φ_q⁺ (eq. 127): :func:`newton_onto`."""
        return newton_onto(lambda x: self.phi(t, x),
                           lambda x, residual: self._min_norm(self.jacobian(t, x), residual)[0],
                           q, self.params, self.counters)


def projection_cut(jac: np.ndarray, singular_cut: float) -> float:
    """The truncation of the direct projection's pseudo-inverse (:class:`DirectCorrection`):
    ``singular_cut`` × σ_r/σ_1 of ``jac`` (m, n) at the start, r its numerical rank (at least 1);
    singular values below that × the largest are left out."""
    values = np.linalg.svd(jac, compute_uv=False)
    rank = max(int(np.count_nonzero(values > RANK_TOLERANCE * max(values[0], 1.0))), 1)
    return float(singular_cut) * float(values[rank - 1] / values[0])


def newton_onto(residual_at, correction, x, params: dict, counters: dict):
    """Newton onto residual_at(x) = 0 with x ← x − correction(x, residual), until
    max |residual| < ``params["proj_tol"]``, or until an iteration no longer reduces it (the
    round-off floor of a large mechanism can lie above a tight tolerance: on n_fourbar@16
    proj_tol 1e-15 ran all 10 iterations in most steps), at most ``params["proj_max_iter"]``
    iterations, each counted in ``counters["newton_iterations"]`` (Rouvinen 2003, eq. 127)."""
    previous = np.inf
    for _ in range(int(params["proj_max_iter"])):
        residual = residual_at(x)
        size = np.max(np.abs(residual))
        if size < params["proj_tol"] or not size < previous:
            break
        previous = size
        counters["newton_iterations"] += 1
        x = x - correction(x, residual)
    return x


class DirectCorrection(_Projection):
    """Position (Rouvinen 2003, eq. 127) and velocity (eq. 137) projection after every step; ρ̂ for the
    placed passages comes from the velocity projection's Φ_q (no evaluation of its own)."""

    name = "direct"
    description = "direct violation correction: position (Rouvinen 2003, eq. 127) and velocity (eq. 137) projection"
    #: Newton to round-off (``proj_tol`` 1e-15; it stops earlier where an iteration no longer
    #: reduces max |Φ|): 1e-12 left rk8 1.6e-3 m off on double_fourbar (10 s, dt 1e-3, with
    #: placed passages; 7.8e-9 m at 1e-15) and rk5 5.3e-2 m (plain grid), at no measurable cost
    #: on fourbar and slider_crank (rk5 and rk8 at dt 1e-2 and 1e-3, bare loop, within ±3 %).
    defaults = {**_Projection.defaults, "proj_tol": 1e-15, "passage": 1}
    places_passages = True

    def project(self, t, q, v):
        q = self.project_position(t, q)
        jac = np.ascontiguousarray(self.jacobian(t, q))
        correction, indicator = self._min_norm(
            jac, pattern_matvec(jac, self.constraints.sparsity.row_columns, v))
        self._push_indicator(indicator)
        return q, v - correction


class GeometricElimination(_Projection):
    """Geometric elimination (Rouvinen 2003, eq. 127–136): position projection, then the velocity moved
    along ∂Ψ/∂q̇ = M q̇ until the energy balance Ψ = T + V − W − E₀ vanishes (eq. 128, 136).

    Every term comes from this formulation's own model: T = ½ q̇ᵀ M(q) q̇ with the mass matrix of
    :class:`~mbh._adapters.inhouse.formulations.mass_and_forces.Dynamics`, V = −Σ m g·R, and W the work of the applied loads
    (springs, dampers, torques, forces; gravity is in V), the integral of the generalised power
    P = Q_eᵀ q̇ over each step's actual length by the two-point Hermite rule

        ∫ P dt ≈ h/2 (P₀ + P₁) + h²/12 (Ṗ₀ − Ṗ₁)      (local error O(h⁵), fourth order),

    with Ṗ a central difference of P along (q̇, q̈) (q̈ from :meth:`acceleration`; the difference's
    own error, ~1e-10 |P| s⁻¹, enters multiplied by h²).  The power at a step's end is taken before
    the velocity correction, which changes q̇ by the method's local error only.
    """

    name = "geometric"
    description = ("geometric elimination: position projection (Rouvinen 2003, eq. 127), then the energy-based "
                   "velocity correction (eq. 128–136) with the work of applied loads integrated "
                   "over each step by the Hermite rule")

    #: Time step (s) of the central difference that gives the power's rate Ṗ.
    RATE_STEP = 1e-7

    def __init__(self, mech, q0, dt, **params):
        super().__init__(mech, q0, dt, **params)
        self._layout = self.constraints.layout
        self._loaded = bool(mech.forces)
        self._last = None  # (t, P, Ṗ) at the end of the previous step
        self._work = 0.0
        self._energy0 = 0.0

    def energy(self, q, v) -> float:
        """T + V of the formulation's state (q, q̇), J."""
        mass, _ = self.dynamics.mass_and_forces(0.0, q, v)
        positions = body_states(self._layout, q, v).position
        return float(0.5 * v @ mass @ v - self.mech.masses @ positions @ self.mech.gravity)

    def _power(self, q, v) -> float:
        return float(self.dynamics.applied_forces(q, v) @ v)

    def _power_and_rate(self, t, q, v) -> tuple[float, float]:
        """P and Ṗ = d/dt P along the motion at (t, q, q̇), W and W/s."""
        acc = self.acceleration(t, q, v)
        h = self.RATE_STEP
        rate = (self._power(q + h * v, v + h * acc) - self._power(q - h * v, v - h * acc)) / (2 * h)
        return self._power(q, v), rate

    def start(self, q, v):
        """Record E₀ = T + V and the power at the initial state."""
        self._energy0 = self.energy(q, v)
        self._work = 0.0
        self._last = (0.0, *self._power_and_rate(0.0, q, v)) if self._loaded else None

    def project(self, t, q, v):
        q = self.project_position(t, q)
        if self._loaded:
            t0, p0, rate0 = self._last
            p1, rate1 = self._power_and_rate(t, q, v)
            h = t - t0
            self._work += 0.5 * h * (p0 + p1) + h * h / 12.0 * (rate0 - rate1)
            self._last = (t, p1, rate1)
        psi = self.energy(q, v) - self._work - self._energy0  # eq. 128
        mass, _ = self.dynamics.mass_and_forces(t, q, v)
        gradient = mass @ v  # ∂Ψ/∂q̇ (eq. 130)
        norm = gradient @ gradient
        if norm > 0:
            v = v - psi * gradient / norm  # eq. 136
        return q, v


STRATEGIES = {cls.name: cls for cls in (NoStabilisation, Baumgarte, Penalty, AugmentedLagrangian,
                                        DirectCorrection, GeometricElimination)}
