"""The equations of motion as a differential-algebraic system, solved by SUNDIALS IDA.

Method ``ida`` integrates the constrained equations of motion in absolute coordinates (Rouvinen 2003
ch. 3, eq. 76) without reducing them to an ODE: the variable-order BDF of IDA (through
scikit-sundae) solves the DAE in residual form F(t, y, ẏ) = 0.

Forms
-----
``"ggl"`` (default), the stabilised index-2 form of Gear, Gupta and Leimkuhler (1985), with
y = (q, v, λ, μ) of length 2n + 2m::

    q̇ = v − Φ_qᵀ μ          (n)
    M v̇ = Q − Φ_qᵀ λ        (n)
    0 = Φ(q, t)             (m)
    0 = Φ_q v + Φ_t         (m)    Φ_t = 0: dynamics has no driving constraints

The extra multiplier μ projects q̇ onto the position manifold; it is zero on the exact solution.
Position and velocity constraints both hold at every step, so there is no drift (the alternative
to the stabilisations of Rouvinen 2003, ch. 5).

``"index3"``, the plain form with y = (q, v, λ) of length 2n + m::

    q̇ = v,   M v̇ = Q − Φ_qᵀ λ,   0 = Φ(q, t).

Algebraic variables and the error test
--------------------------------------
λ and μ are declared algebraic (``IDASetId``).  IDA's ``IDASetSuppressAlg`` is not exposed by
scikit-sundae 1.2, so they are taken out of the local error test through their absolute
tolerance: :data:`ALGEBRAIC_ATOL` makes their error weight 1/(rtol|y| + atol) ≈ 1e-20, which IDA
accepts (it rejects a zero weight).  The same weights enter IDA's Newton convergence test, so λ
and μ converge through their coupling with q and v only.  In the index-3 form the velocities are
also taken out of the error test (:data:`INDEX3_EXCLUDES_VELOCITIES`): the BDF error estimate of
an index-3 system is not reliable for the index-2 variables either (Brenan, Campbell & Petzold
1996, §5.4); with v in the test IDA fails to start.

Jacobian
--------
``jacobian="kernels"`` (default) assembles the iteration matrix ∂F/∂y + c_j ∂F/∂ẏ block by
block: the constant and linear blocks exactly (I, M, Φ_q, Φ_qᵀ) and the derivatives of
M(q) v̇ − Q(q, v) + Φ_qᵀ λ, Φ_qᵀ μ and Φ_q v with respect to q and of Q with respect to v by
forward differences of the compiled kernels (2n kernel evaluations).  ``jacobian="ida"`` leaves
the matrix to IDA's difference quotients over all 2n + 2m columns, which costs more the larger
the system (figures: docs/measurements.md, section "Integrators").

Redundant constraint equations
------------------------------
Only the independent rows of Φ_q(q0) (Gaussian elimination with full pivoting, Frączek & Wojtyra 2009, eq. 1.49)
enter the DAE; redundant rows would make the iteration matrix singular.

Counters
--------
scikit-sundae 1.2 reports only IDA's residual and Jacobian counts, so ``steps`` are counted here
(one ``onestep`` call per internal step), ``rhs_evals`` counts every call of the residual
function (IDA's own count leaves out the difference-quotient Jacobian columns),
``jacobian_evals`` is IDA's, and ``factorizations`` equals it: IDA's direct linear solver
re-evaluates and factors the iteration matrix at every setup.  ``newton_iterations`` is not
exposed and is reported as ``None``.  ``kernel_evals`` counts the kernel evaluations of the
``"kernels"`` Jacobian (each costs about one residual evaluation).

References
----------
C. W. Gear, B. Leimkuhler, G. K. Gupta, "Automatic integration of Euler–Lagrange equations with
constraints", J. Comput. Appl. Math. 12–13 (1985) 77–90.
K. E. Brenan, S. L. Campbell, L. R. Petzold, *Numerical Solution of Initial-Value Problems in
Differential-Algebraic Equations*, SIAM 1996.
A. Rouvinen, LUT research report 44 (2003), ch. 3 (equations of motion, eq. 76–77) and ch. 5
(constraint stabilisation): Rouvinen 2003.
A. C. Hindmarsh et al., "SUNDIALS: Suite of nonlinear and differential/algebraic equation
solvers", ACM TOMS 31 (2005) 363–396.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import sksundae

from mbh._adapters.base import RunFailure, describe
from mbh._adapters.inhouse.bodies.constraints import ConstraintSystem
from mbh._adapters.inhouse.formulations.dynamics import solve_augmented
from mbh._adapters.inhouse.formulations.mass_and_forces import Dynamics
from mbh._adapters.inhouse.numerics.rank import full_pivot_elimination
from mbh._harness.common.status import CaseStatus
from mbh._harness.model.mechanism import Mechanism

FORMS = ("ggl", "index3")
JACOBIANS = ("kernels", "ida")

#: Absolute tolerance that takes a variable out of IDA's error test (weight ≈ 1e-20).
ALGEBRAIC_ATOL = 1e20
#: Whether the index-3 form also takes the velocities out of the error test (see module notes).
INDEX3_EXCLUDES_VELOCITIES = True
#: A state whose q or v 2-norm exceeds this is diverged (as in the integrator library).
DIVERGENCE_LIMIT = 1e8
#: Relative forward-difference step of the "kernels" Jacobian, √(machine ε).
_FD_STEP = float(np.sqrt(np.finfo(float).eps))

_DEFAULTS = {"rtol": 1e-10, "atol": 1e-12, "form": "ggl", "max_steps": 200_000,
             "jacobian": "kernels"}


def ida_params() -> dict:
    """Parameter defaults of method ``ida`` (rtol, atol, form, max_steps, jacobian)."""
    return dict(_DEFAULTS)


def check_ida_params(params: dict) -> None:
    """Raise a ValueError naming ``form``, ``jacobian`` or ``max_steps`` when it is invalid."""
    if params["form"] not in FORMS:
        raise ValueError(f"form must be one of {', '.join(FORMS)}, got {params['form']!r}")
    if params["jacobian"] not in JACOBIANS:
        raise ValueError(f"jacobian must be one of {', '.join(JACOBIANS)}, "
                         f"got {params['jacobian']!r}")
    if int(params["max_steps"]) < 1:
        raise ValueError(f"max_steps must be >= 1, got {params['max_steps']!r}")


@dataclass
class IdaResult:
    """Samples and cost of one IDA run.

    Attributes
    ----------
    times : ndarray, shape (k,)
        The sample times reached, s (all of ``sample_times`` when ``status == "ok"``).
    q : ndarray, shape (k, n)
        Absolute coordinates at ``times``.
    v : ndarray, shape (k, n)
        Their time derivatives.  In the GGL form this is the velocity variable v, which satisfies
        Φ_q v = 0; q̇ = v − Φ_qᵀμ differs from it by the (tolerance-sized) projection term.
    status : str
        ``"ok"``, ``"failed"`` (IDA error, ``max_steps`` reached, or an exception in the model)
        or ``"diverged"`` (non-finite state or norm above :data:`DIVERGENCE_LIMIT`).
    reason : str or None
        Why it stopped early (IDA's message and flag, or the limit hit).
    failure_time : float or None
        Time of the last good state (the last step IDA completed that passed the checks), s.
    counters : dict
        ``steps``, ``rhs_evals``, ``jacobian_evals``, ``factorizations``, ``newton_iterations``
        (``None``: not exposed), ``kernel_evals`` (see the module notes).
    """

    times: np.ndarray
    q: np.ndarray
    v: np.ndarray
    status: str
    reason: str | None = None
    failure_time: float | None = None
    counters: dict = field(default_factory=dict)


class DaeModel:
    """Residual and iteration matrix of the equations of motion in residual form.

    Parameters
    ----------
    mech : Mechanism
    q0 : ndarray, shape (n,)
        Configuration at which the independent constraint rows are chosen.
    form : {"ggl", "index3"}

    Attributes
    ----------
    n : int
        Number of coordinates.
    m : int
        Number of independent constraint equations kept.
    size : int
        Length of y: 2n + 2m (GGL) or 2n + m (index 3).
    rows : ndarray of int, shape (m,)
        Indices of the kept rows of :class:`ConstraintSystem`.
    n_residual, n_kernel : int
        Residual evaluations and Jacobian kernel evaluations so far.
    """

    def __init__(self, mech: Mechanism, q0: np.ndarray, form: str = "ggl"):
        if form not in FORMS:
            raise ValueError(f"form must be one of {', '.join(FORMS)}, got {form!r}")
        self.form = form
        self.constraints = ConstraintSystem(mech)
        self.dynamics = Dynamics(mech)
        self.n = self.constraints.layout.n
        _, independent = full_pivot_elimination(self.constraints.jacobian(q0, 0.0))
        self.rows = np.sort(independent)
        self.m = self.rows.size
        self.size = 2 * self.n + (2 if form == "ggl" else 1) * self.m
        self.n_residual = self.n_kernel = 0

    def phi(self, q: np.ndarray, t: float) -> np.ndarray:
        """Kept constraint residuals Φ(q, t), shape (m,)."""
        return self.constraints.phi(q, t)[self.rows]

    def jacobian(self, q: np.ndarray, t: float) -> np.ndarray:
        """Kept rows of Φ_q, shape (m, n)."""
        return self.constraints.jacobian(q, t)[self.rows]

    def gamma(self, q: np.ndarray, v: np.ndarray, t: float) -> np.ndarray:
        """Kept rows of γ (Φ_q q̈ = γ), shape (m,)."""
        return self.constraints.gamma(q, v, t)[self.rows]

    def split(self, y: np.ndarray):
        """Views (q, v, λ, μ) of y; μ is empty in the index-3 form."""
        n, m = self.n, self.m
        return y[:n], y[n:2 * n], y[2 * n:2 * n + m], y[2 * n + m:]

    def _split_writable(self, y: np.ndarray, yp: np.ndarray):
        """(q, v, λ, μ) of a copy of y and the copy of ẏ.  IDA hands its callbacks read-only
        arrays, and a read-only argument is a new type to numba: every kernel they reach was
        compiled a second time inside the first run's timed stepping (~100 s with a cold cache
        on double_fourbar)."""
        return (*self.split(np.array(y)), np.array(yp))

    def initial(self, q0: np.ndarray, v0: np.ndarray, t0: float = 0.0):
        """Consistent (y0, ẏ0): μ0 = 0, (v̇0, λ0) from the augmented system, q̇0 = v0.

        Returns
        -------
        y0, yp0 : ndarray, shape (size,)
        """
        mass, force = self.dynamics.mass_and_forces(t0, q0, v0)
        acceleration, multipliers = solve_augmented(
            mass, self.jacobian(q0, t0), force, self.gamma(q0, v0, t0))
        y0 = np.zeros(self.size)
        yp0 = np.zeros(self.size)
        n = self.n
        y0[:n], y0[n:2 * n], y0[2 * n:2 * n + self.m] = q0, v0, multipliers
        yp0[:n], yp0[n:2 * n] = v0, acceleration
        return y0, yp0

    def _coupled(self, t, q, v, vdot, lam, mu):
        """(M v̇ − Q + Φ_qᵀλ, Φ_qᵀμ, Φ_q v), shape (n + n + m,); index 3: the first, (n,)."""
        mass, force = self.dynamics.mass_and_forces(t, q, v)
        jac = self.jacobian(q, t)
        if self.form == "index3":
            return mass @ vdot - force + jac.T @ lam
        return np.concatenate([mass @ vdot - force + jac.T @ lam, jac.T @ mu, jac @ v])

    def residual(self, t: float, y: np.ndarray, yp: np.ndarray, res: np.ndarray) -> None:
        """F(t, y, ẏ) written into ``res``, shape (size,) (IDA's ``resfn``)."""
        self.n_residual += 1
        n, m = self.n, self.m
        q, v, lam, mu, yp = self._split_writable(y, yp)
        qdot, vdot = yp[:n], yp[n:2 * n]
        mass, force = self.dynamics.mass_and_forces(t, q, v)
        jac = self.jacobian(q, t)
        res[:n] = qdot - v
        res[n:2 * n] = mass @ vdot - force + jac.T @ lam
        res[2 * n:2 * n + m] = self.phi(q, t)
        if self.form == "ggl":
            res[:n] += jac.T @ mu
            res[2 * n + m:] = jac @ v

    def iteration_matrix(self, t: float, y: np.ndarray, yp: np.ndarray, res: np.ndarray,
                         cj: float, out: np.ndarray) -> None:
        """∂F/∂y + c_j ∂F/∂ẏ written into ``out``, shape (size, size) (IDA's ``jacfn``).

        The q- and v-derivatives of the configuration-dependent terms are forward differences of
        the kernels (step √ε·max(1, |q_j|)); every other block is exact.
        """
        n, m = self.n, self.m
        q, v, lam, mu, yp = self._split_writable(y, yp)
        vdot = yp[n:2 * n]
        mass, force = self.dynamics.mass_and_forces(t, q, v)
        jac = self.jacobian(q, t)
        base = self._coupled(t, q, v, vdot, lam, mu)
        self.n_kernel += 2
        out[:] = 0.0
        rows_v = slice(n, 2 * n)
        for j in range(n):
            step = _FD_STEP * max(1.0, abs(q[j]))
            shifted = q.copy()
            shifted[j] += step
            column = (self._coupled(t, shifted, v, vdot, lam, mu) - base) / step
            out[rows_v, j] = column[:n]
            if self.form == "ggl":
                out[:n, j] = column[n:2 * n]
                out[2 * n + m:, j] = column[2 * n:]
            step = _FD_STEP * max(1.0, abs(v[j]))
            shifted = v.copy()
            shifted[j] += step
            out[rows_v, n + j] = -(self.dynamics.mass_and_forces(t, q, shifted)[1] - force) / step
        self.n_kernel += 2 * n
        diagonal = np.arange(n)
        out[diagonal, diagonal] += cj
        out[diagonal, n + diagonal] = -1.0
        out[rows_v, n:2 * n] += cj * mass
        out[rows_v, 2 * n:2 * n + m] = jac.T
        out[2 * n:2 * n + m, :n] = jac
        if self.form == "ggl":
            out[:n, 2 * n + m:] = jac.T
            out[2 * n + m:, n:2 * n] = jac

    def warm_up(self, y: np.ndarray, yp: np.ndarray) -> None:
        """Evaluate the residual and the iteration matrix once at (y, ẏ), shape (size,) each,
        so that compiling their kernels stays out of timed stepping; the counters are left as
        they were."""
        counts = self.n_residual, self.n_kernel
        self.residual(0.0, y, yp, np.empty(self.size))
        self.iteration_matrix(0.0, y, yp, np.empty(self.size), 1.0,
                              np.empty((self.size, self.size)))
        self.n_residual, self.n_kernel = counts

    def tolerances(self, atol: float) -> tuple[np.ndarray, list[int]]:
        """Absolute tolerance per component, shape (size,), and the algebraic indices."""
        algebraic = list(range(2 * self.n, self.size))
        per_component = np.full(self.size, float(atol))
        per_component[algebraic] = ALGEBRAIC_ATOL
        if self.form == "index3" and INDEX3_EXCLUDES_VELOCITIES:
            per_component[self.n:2 * self.n] = ALGEBRAIC_ATOL
        return per_component, algebraic


def simulate_ida(mech: Mechanism, q0, v0, t_end: float, sample_times, rtol: float = 1e-10,
                 atol: float = 1e-12, form: str = "ggl", max_steps: int = 200_000,
                 jacobian: str = "kernels") -> IdaResult:
    """Integrate the DAE of motion from t = 0 to ``t_end`` with IDA and sample it.

    Parameters
    ----------
    mech : Mechanism
    q0, v0 : array_like, shape (n,)
        Consistent initial coordinates and velocities (``kinematics.assemble``), m, rad, 1.
    t_end : float
        End time, s (> 0).
    sample_times : array_like, shape (k,)
        Non-decreasing times in [0, t_end], s, at which (q, v) is interpolated by IDA.
    rtol, atol : float
        IDA's relative and absolute tolerances for q and v (λ, μ are excluded, see the module
        notes).
    form : {"ggl", "index3"}
        Stabilised index-2 (Gear–Gupta–Leimkuhler) or index-3 equations.
    max_steps : int
        Total internal steps allowed before the run ends as ``"failed"``.
    jacobian : {"kernels", "ida"}
        Iteration matrix from kernel differences or from IDA's difference quotients.

    Returns
    -------
    IdaResult
        A solver failure is reported in ``status``, ``reason`` and ``failure_time``, never
        raised.

    Raises
    ------
    ValueError
        For invalid arguments (unknown form or Jacobian, bad shapes, sample times outside
        [0, t_end] or decreasing).
    """
    check_ida_params({"jacobian": jacobian, "max_steps": max_steps, "form": form})
    t_end = float(t_end)
    if not (np.isfinite(t_end) and t_end > 0.0):
        raise ValueError(f"t_end must be finite and > 0, got {t_end!r}")
    samples = np.asarray(sample_times, dtype=float)
    if samples.ndim != 1 or np.any(np.diff(samples) < 0) or np.any(samples < 0) \
            or np.any(samples > t_end):
        raise ValueError("sample_times must be a non-decreasing 1-D array in [0, t_end]")
    q0 = np.array(q0, dtype=float)
    v0 = np.array(v0, dtype=float)
    model = DaeModel(mech, q0, form)
    if q0.shape != (model.n,) or v0.shape != (model.n,):
        raise ValueError(f"q0 and v0 must have shape ({model.n},), got {q0.shape}, {v0.shape}")

    integration = IdaIntegration(model, q0, v0, t_end, rtol=rtol, atol=atol,
                                 max_steps=max_steps, jacobian=jacobian)
    taken: list[tuple[float, np.ndarray]] = []
    status, reason, failure_time = CaseStatus.OK, None, None
    try:
        for t in (*samples, t_end):
            integration.advance_to(float(t))
            if len(taken) < samples.size:
                taken.append((float(t), integration.state_at(float(t))))
    except RunFailure as failure:
        status, reason, failure_time = failure.status, failure.reason, integration.t
    except (RuntimeError, FloatingPointError, ValueError, np.linalg.LinAlgError) as exc:
        status, reason, failure_time = CaseStatus.FAILED, describe(exc), integration.t
    n = model.n
    states = np.array([y for _, y in taken]).reshape(len(taken), -1)
    return IdaResult(np.array([t for t, _ in taken]), states[:, :n].reshape(-1, n),
                     states[:, n:2 * n].reshape(-1, n), status, reason, failure_time,
                     integration.counters())


class IdaIntegration:
    """One IDA integration of a :class:`DaeModel` from a consistent start, step by step.

    Parameters
    ----------
    model : DaeModel
    q0, v0 : ndarray, shape (n,)
        Consistent initial coordinates and velocities.
    t_end : float
        IDA never steps past it (``tstop``), s.
    rtol, atol, max_steps, jacobian
        As :func:`simulate_ida`.

    Attributes
    ----------
    t : float
        Time of the last good state (the last step IDA completed and the checks passed), s.
    steps : int
        Internal steps taken (one ``onestep`` call each).
    """

    def __init__(self, model: DaeModel, q0: np.ndarray, v0: np.ndarray, t_end: float,
                 rtol: float, atol: float, max_steps: int, jacobian: str):
        self.model = model
        self.t_end = float(t_end)
        self.max_steps = int(max_steps)
        self.y, yp0 = model.initial(q0, v0)
        model.warm_up(self.y, yp0)
        per_component_atol, algebraic = model.tolerances(atol)
        options = dict(rtol=float(rtol), atol=per_component_atol, algebraic_idx=algebraic,
                       max_num_steps=self.max_steps)
        if jacobian == "kernels":
            options["jacfn"] = model.iteration_matrix
        self.solver = sksundae.ida.IDA(model.residual, **options)
        self._yp0 = yp0
        self._started = False
        self.t = 0.0
        self.steps = 0
        self.njev = 0

    def advance_to(self, t: float) -> None:
        """One IDA step per ``onestep`` call (stopping exactly at t_end) until ``t`` is reached.

        Raises
        ------
        RunFailure
            ``failed`` (IDA's flag and message, or ``max_steps`` reached) or ``diverged``
            (non-finite state, or q or v 2-norm above :data:`DIVERGENCE_LIMIT`); :attr:`t` stays
            the last good time.
        """
        if not self._started and self.t < t:
            self.solver.init_step(0.0, self.y, self._yp0)
            self._started = True
        while self.t < t:
            if self.steps >= self.max_steps:
                raise RunFailure(CaseStatus.FAILED, f"max_steps={self.max_steps} reached before "
                                           f"t_end={self.t_end:g} s")
            out = self.solver.step(self.t_end, method="onestep", tstop=self.t_end)
            self.njev = int(out.njev)
            if not out.success:
                raise RunFailure(CaseStatus.FAILED, f"IDA flag {out.status}: {out.message}")
            self.steps += 1
            q, v, _, _ = self.model.split(out.y)
            if not (np.all(np.isfinite(q)) and np.all(np.isfinite(v))):
                raise RunFailure(CaseStatus.DIVERGED, "non-finite state")
            if max(np.linalg.norm(q), np.linalg.norm(v)) > DIVERGENCE_LIMIT:
                raise RunFailure(CaseStatus.DIVERGED,
                                 f"state norm exceeds {DIVERGENCE_LIMIT:g}")
            self.t, self.y = float(out.t), np.array(out.y)

    def state_at(self, t: float) -> np.ndarray:
        """y at ``t`` (s): the last step's state at its own time, IDA's interpolant before it,
        shape (size,)."""
        if t == self.t:
            return self.y.copy()
        out = self.solver.step(t)
        if not out.success:
            raise RuntimeError(f"interpolation at t = {t}: {out.message}")
        return np.array(out.y)

    def counters(self) -> dict:
        """``steps``, ``rhs_evals``, ``jacobian_evals``, ``factorizations``,
        ``newton_iterations`` (None: not exposed), ``kernel_evals`` (see the module notes)."""
        return {"steps": self.steps, "rhs_evals": self.model.n_residual,
                "jacobian_evals": self.njev, "factorizations": self.njev,
                "newton_iterations": None, "kernel_evals": self.model.n_kernel}
