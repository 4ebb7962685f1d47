"""The equations of motion in joint coordinates by velocity transformation, on the absolute
formulation's own kernels (``coords=joint``).

The tree coordinates θ (n_θ,) of :mod:`~mbh._adapters.inhouse.bodies.tree_kinematics` give the
absolute coordinates q = g(θ) (n,) and velocities q̇ = B θ̇ with B = ∂g/∂θ (n, n_θ); the
accelerations are q̈ = B θ̈ + Ḃθ̇.  The spanning tree and its path matrix are Arczewski's (1995,
eq. 2–3: the joints cut to obtain the tree are the ``cut joints``).  Put into the absolute
equations M q̈ = Q + Φ_qᵀλ (Rouvinen 2003, eq. 77) and multiplied by Bᵀ, which removes the
reactions of the tree joints (their equations hold identically on g, Φ_q,tree B = 0, and so do the
Euler-parameter normalisations):

    M_θ θ̈ = Q_θ + C_θᵀλ,   M_θ = BᵀMB (n_θ, n_θ),   Q_θ = Bᵀ(Q − M Ḃθ̇) (n_θ,)

with M and Q (gravity, springs, dampers, applied loads and the quadratic-velocity terms) from
:class:`~mbh._adapters.inhouse.formulations.mass_and_forces.Dynamics`.  The loops closed at the cut
joints are the absolute equations of those joints alone, Φ_θ(θ) = Φ_cut(g(θ)) (m_c,), with

    C_θ = Φ_cut,q B (m_c, n_θ),   γ_θ = γ_cut − Φ_cut,q Ḃθ̇ (m_c,)

(Φ_cut,q, γ_cut from :class:`~mbh._adapters.inhouse.bodies.constraints.ConstraintSystem`).  All of
it, from θ to θ̈, is one compiled call (:mod:`.joint_rhs`).  The
pair [M_θ C_θᵀ; C_θ 0] is solved by the absolute formulation's range-space solve
(:func:`~mbh._adapters.inhouse.formulations.dynamics.augmented_mass_acceleration`): certified
Cholesky, else the truncated SVD, so redundant closure rows (Bricard, parallel revolutes) are
solved rank-revealingly, never dropped by guess.  Where rows are redundant, the pivoted Cholesky
takes them in the order it chose at the start (:attr:`JointCoordinates.pivots`) for as long as
its certificate holds, so that the solve's path, and a generated right-hand side's guards
(:mod:`~mbh._adapters.inhouse.codegen.generated`), do not change with the order of its diagonal.

Treatments (the absolute strategies' names and parameters; ``passage`` has no effect here: no
placed passages of singular positions in joint coordinates yet):

* ``none``: γ_θ as it is (Rouvinen 2003, eq. 77);
* ``baumgarte``: γ_θ − 2αΦ̇_θ − β²Φ_θ (eq. 110), ``auto`` α = 1/Δt, β = √2/Δt (eq. 111);
* ``direct``: after every step Newton on Φ_θ(θ) = 0 with the truncated pseudo-inverse of C_θ
  (eq. 127 in θ), then θ̇ − C_θ⁺C_θθ̇ (eq. 137 in θ).  The minimum norm is taken in θ, whose
  entries mix radians and metres: a different (equally valid) point of the manifold than the
  absolute projection's.

An open chain has no closure: θ̈ = M_θ⁻¹Q_θ and every treatment is the same.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from mbh._adapters.inhouse.bodies.constraints import ConstraintSystem
from mbh._adapters.inhouse.bodies.tree_kinematics import TreeKinematics
from mbh._adapters.inhouse.bodies.tree_moves import tree_moves, tree_of, unsupported_tree_joints
from mbh._adapters.inhouse.formulations.dynamics import ACCELERATION_CUT, range_space_pivots
from mbh._adapters.inhouse.formulations.joint_rhs import acceleration_kernel, reduced_kernel
from mbh._adapters.inhouse.formulations.mass_and_forces import Dynamics
from mbh._adapters.inhouse.formulations.stabilisation import (Baumgarte, DirectCorrection,
                                                              NoStabilisation, newton_onto,
                                                              projection_cut)
from mbh._adapters.inhouse.numerics.linalg import truncated_solve
from mbh._adapters.inhouse.numerics.rank import RANK_TOLERANCE, full_pivot_elimination
from mbh._adapters.integrators.base import SecondOrderSystem
from mbh._harness.common.kernel_cache import first_use
from mbh._harness.model.mechanism import Mechanism
from mbh._harness.model.topology import DisconnectedGraphError

#: The values of the method option ``coords``: ``auto`` takes the smaller model
#: (:func:`auto_coordinates`).
COORDINATES = ("absolute", "joint", "auto")
#: The loops a joint-coordinate run accepts: ``generated`` (the compiled joint-coordinate loop,
#: :mod:`~mbh._adapters.inhouse.stepping.joint_loop`, for the methods it runs, with the right-hand
#: side generated for the mechanism, :func:`~mbh._adapters.inhouse.codegen.generated.joint_function`),
#: ``compiled`` (that loop on the kernel alone), ``python`` (the Python loop, every method),
#: ``auto`` (``generated`` where the loop runs the method, except that a short run compiles no
#: new generated function, as the absolute model's ``auto``; else Python).
JOINT_LOOPS = ("auto", "generated", "compiled", "python")
#: What the announcement of :attr:`JointCoordinates.pivots`' first compilation says to expect, s:
#: the reduced kernel 21.4 s and the pivots' own 6.1 s on an empty cache (Bricard,
#: benchmarks/compile_cost.py, 2-core machine, 2026-11-29); ~6 s once the right-hand side is
#: compiled.
PIVOTS_COMPILE_S = 28.0


def joint_coordinates_unsupported(mech: Mechanism) -> str | None:
    """Why ``mech`` has no joint-coordinate model here, or None."""
    try:
        tree = tree_of(mech)
    except DisconnectedGraphError as error:
        return str(error)
    missing = unsupported_tree_joints(mech, tree)
    if missing:
        return (f"coords=joint: the spanning tree of {mech.name!r} needs tree joint(s) "
                f"{', '.join(missing)}, which have no joint coordinates yet (a spherical or free "
                "joint needs three rotation coordinates and a chart without singularities); "
                "coords=absolute runs it")
    return None


def auto_coordinates(mech: Mechanism, loop: str, joint_loop: str | None) -> tuple[str, str]:
    """``coords=auto``: the coordinates of the smaller model, and the run's note saying which and
    why.

    The joint model is taken when its coordinates plus closure equations (n_θ + m_c) are fewer
    than the absolute model's coordinates plus Φ rows (n + m, the Euler-parameter normalisations
    included), the spanning tree has joint coordinates for every tree joint, and the method's
    ``loop`` has a joint-coordinate loop for it (``joint_loop``: ``compiled``, ``python``, or
    None for none); otherwise the absolute model.

    Returns
    -------
    coords : str
        ``"joint"`` or ``"absolute"``.
    note : str
    """
    absolute = ConstraintSystem(mech)
    size_absolute = f"{absolute.layout.n} q and {absolute.m} Φ rows"
    reason = joint_coordinates_unsupported(mech)
    if reason:
        return "absolute", f"coords=auto: absolute coordinates ({size_absolute}): {reason}"
    tree = tree_of(mech)
    n_theta = tree_moves(mech, tree).n_coordinates
    m_closure = Closure(mech, tree.cut_joints).m
    sizes = (f"{n_theta} θ and {m_closure} closure equation(s) against {size_absolute}")
    if n_theta + m_closure >= absolute.layout.n + absolute.m:
        return "absolute", f"coords=auto: absolute coordinates, the model no larger ({sizes})"
    if joint_loop is None:
        return "absolute", (f"coords=auto: absolute coordinates, as loop={loop} asks: the joint "
                            f"model is smaller ({sizes}) but has no such loop for this method")
    if joint_loop == "python":
        return "joint", (f"coords=auto: joint coordinates, the smaller model ({sizes}); this "
                         "method steps them in Python, slower per step than the absolute "
                         "model's compiled loop")
    return "joint", (f"coords=auto: joint coordinates, the smaller model ({sizes}), on their "
                     "compiled loop")


class Closure:
    """The absolute equations of the cut joints, Φ_cut (m_c,), Φ_cut,q (m_c, n), γ_cut (m_c,)
    (Euler-parameter normalisations left out: g(θ) meets them identically; none for an open
    chain)."""

    def __init__(self, mech: Mechanism, cut_joints: tuple[str, ...]):
        cut = dataclasses.replace(mech, joints=tuple(mech.joint(n) for n in cut_joints),
                                  forces=())
        self.system = ConstraintSystem(cut)
        self.m = self.system.n_joint_equations
        self.labels: tuple[str, ...] = self.system.labels[:self.m]

    @property
    def kernel_args(self) -> tuple:
        """The cut joints' arguments of :mod:`~mbh._adapters.inhouse.bodies.kernels` (those of a
        system without joints for an open chain: m = 0)."""
        return self.system.kernel_args

    def phi(self, q, t):
        return self.system.phi(q, t)[:self.m]

    def jacobian(self, q, t):
        return self.system.jacobian(q, t)[:self.m]

    def gamma(self, q, v, t):
        return self.system.gamma(q, v, t)[:self.m]


class JointCoordinates(SecondOrderSystem):
    """Index-1 equations of motion in joint coordinates (see the module docstring), a
    :class:`~mbh._adapters.integrators.base.SecondOrderSystem` over (θ, θ̇) that the in-house
    stepper drives like an absolute :class:`~.stabilisation.Formulation`.

    Parameters
    ----------
    mech : Mechanism
    q0 : ndarray, shape (n,)
        The common start in absolute coordinates (its θ₀, and the rank analysis of C_θ).
    dt : float
        Step size, s (Baumgarte's ``auto`` gains).
    **params
        The treatment's parameters (:attr:`defaults`).

    Attributes
    ----------
    n : int
        n_θ, the number of joint coordinates.
    kinematics : TreeKinematics
    closure : Closure
    counters : dict
    notes : list of str
    """

    name = ""
    description = ""
    defaults: dict = {}
    corrects = False
    places_passages = False
    indicators = None
    #: Baumgarte gains (α, β); zero: plain γ_θ.
    gains = (0.0, 0.0)

    @classmethod
    def unsupported_reason(cls, mech: Mechanism, integrator_class) -> str | None:
        return joint_coordinates_unsupported(mech)

    def __init__(self, mech: Mechanism, q0: np.ndarray, dt: float, **params):
        self.mech = mech
        self.dt = dt
        self.params = {**self.defaults, **params}
        self.kinematics = TreeKinematics(mech, q0)
        self.dynamics = Dynamics(mech)
        tree = self.kinematics.moves.tree
        self.closure = Closure(mech, tree.cut_joints)
        self.n = self.kinematics.n
        self.counters = {"jacobian_evals": 0, "factorizations": 0, "newton_iterations": 0}
        self._args = self._kernel_args()
        self.rank, self.redundant = self._rank_at(self.kinematics.theta0)
        self.notes = [self._model_note(tree)]

    def _rank_at(self, theta) -> tuple[int, tuple[str, ...]]:
        """Rank of C_θ at θ and the closure rows full pivoting leaves out (Frączek & Wojtyra
        2009, eq. 1.49)."""
        if not self.closure.m:
            return 0, ()
        # At its default tolerance (RANK_TOLERANCE) left out: passed, it is typed float64 and
        # numba compiles the elimination a third time (~4 s) beside the absolute model's call.
        rank, rows = full_pivot_elimination(np.ascontiguousarray(self.closure_jacobian(0.0, theta)))
        left = sorted(set(range(self.closure.m)) - set(np.asarray(rows[:rank]).tolist()))
        return int(rank), tuple(self.closure.labels[i] for i in left)

    @functools.cached_property
    def pivots(self) -> np.ndarray:
        """The range-space solve's pivot order at θ₀ where closure rows are redundant
        (:func:`~.dynamics.range_space_pivots`), (rank,) int64; empty otherwise.  Every later
        solve takes its rows in that order while its certificate holds, so its path (and a
        generated right-hand side's guards) stays the same along the run.  Made when first
        asked for (by the first right-hand side), not at construction: for redundant closures
        it compiles the reduced kernel and the pivoted factorisation, announced."""
        if not self.redundant:
            return np.empty(0, np.int64)
        theta = self.kinematics.theta0
        with first_use("joint-start-pivots", "the joint reduced kernel and the start's pivot "
                       "order of redundant closure rows", PIVOTS_COMPILE_S):
            mass, _, c, _ = self.reduced(0.0, theta, np.zeros(theta.size))
            return range_space_pivots(mass, np.ascontiguousarray(c), ACCELERATION_CUT)

    def _model_note(self, tree) -> str:
        """The run's note on its model: coordinates, closure equations, redundant ones."""
        what = (f"joint coordinates: {self.n} θ ({', '.join(self.kinematics.moves.coordinate_labels)}"
                f"), {self.closure.m} closure equation(s)")
        if self.closure.m:
            what += f" at cut joint(s) {', '.join(tree.cut_joints)} of rank {self.rank}"
        if not self.redundant:
            what += ", 0 redundant"
        else:
            what += (f", {len(self.redundant)} redundant ({', '.join(self.redundant)}): kept, the "
                     "solves are rank-revealing (certified Cholesky, pivoted in the start's "
                     "order, else the truncated SVD)")
        if self.closure.m and self.params.get("passage"):
            what += "; no placed passages of singular positions in joint coordinates yet"
        return what

    # -- the pieces ----------------------------------------------------------------------------
    def closure_jacobian(self, t, theta):
        """C_θ = Φ_cut,q B, shape (m_c, n_θ)."""
        q, b, _ = self.kinematics.evaluate(theta)
        self.counters["jacobian_evals"] += 1
        return self.closure.jacobian(q, t) @ b

    def closure_residual(self, t, theta):
        """Φ_θ = Φ_cut(g(θ)), shape (m_c,)."""
        return self.closure.phi(self.kinematics.positions(theta), t)

    def on_closure(self, theta: np.ndarray) -> np.ndarray:
        """θ (n_θ,) moved onto Φ_θ = 0 (at t = 0) by Newton with C_θ's pseudo-inverse truncated
        at the rank tolerance (Rouvinen 2003, eq. 127 in θ), to round-off; the counters left as
        they were.  Where a generated right-hand side is traced
        (:mod:`~mbh._adapters.inhouse.codegen.generated`).  numpy's least squares, not the
        compiled :func:`~..numerics.linalg.truncated_solve`: on an empty cache that compiled for
        ~2 s before the trace, unannounced, for a point that enters no run's numbers."""
        if not self.closure.m:
            return theta
        jacobian_evals = self.counters["jacobian_evals"]
        moved = newton_onto(
            lambda x: self.closure_residual(0.0, x),
            lambda x, residual: np.linalg.lstsq(self.closure_jacobian(0.0, x), residual,
                                                rcond=RANK_TOLERANCE)[0],
            theta, {"proj_tol": 1e-15, "proj_max_iter": 20}, {"newton_iterations": 0})
        self.counters["jacobian_evals"] = jacobian_evals
        return moved

    def _kernel_args(self) -> tuple:
        """The arguments after (θ, θ̇, t) of :func:`~.joint_rhs.reduced_kernel`."""
        return (self.kinematics.table, self.dynamics.kernel_args, self.closure.kernel_args,
                self.closure.m, (float(self.gains[0]), float(self.gains[1])))

    @property
    def kernel_args(self) -> tuple:
        """The arguments after (θ, θ̇, t) of :func:`~.joint_rhs.acceleration_kernel`: the tree
        pass's table, the dynamics', the closure's, m_c, the gains (α, β) in 1/s and the
        range-space solve's cut and the start's pivots (what :meth:`acceleration` passes)."""
        return (*self._args, ACCELERATION_CUT, self.pivots)

    def reduced(self, t, theta, rate):
        """(M_θ (n_θ, n_θ), Q_θ (n_θ,), C_θ (m_c, n_θ), γ_θ (m_c,)) at (t, θ, θ̇), the
        Baumgarte terms included (kg·m², N·m or kg, N per coordinate), in one compiled call
        (:func:`~.joint_rhs.reduced_kernel`)."""
        return reduced_kernel(np.asarray(theta, dtype=float), np.asarray(rate, dtype=float),
                              float(t), *self._args)

    def acceleration(self, t, q, v):
        """θ̈ (n_θ,) of [M_θ C_θᵀ; C_θ 0] by the range-space solve, in one compiled call
        (:func:`~.joint_rhs.acceleration_kernel`)."""
        self.counters["jacobian_evals"] += 1
        self.counters["factorizations"] += 1
        return acceleration_kernel(np.asarray(q, dtype=float), np.asarray(v, dtype=float),
                                   float(t), *self.kernel_args)

    # -- the stepper's protocol (as :class:`~.stabilisation.Formulation`) -----------------------
    def start(self, q, v):
        """Nothing to record at the start."""

    def warm_up(self, q, v):
        """One right-hand side and one :meth:`project` (counters left as they were), so that the
        first compilation of the compiled solves called from here (the range-space solve, the
        truncated SVD) stays out of timed stepping."""
        counters = dict(self.counters)
        theta, rate = self.reduce(q, v)
        self.acceleration(0.0, theta, rate)
        self.project(0.0, theta, rate)
        self.counters.update(counters)

    def reduce(self, q, v):
        """(θ, θ̇) of an absolute state whose tree joints are assembled."""
        theta = self.kinematics.coordinates_of(q)
        return theta, self.kinematics.rates_of(theta, v)

    def expand(self, t, theta, rate):
        """(q, q̇) = (g(θ), B θ̇): the body states the harness measures."""
        q, b, _ = self.kinematics.evaluate(theta)
        return q, b @ rate

    def needs_repartition(self, q_full) -> bool:
        return False

    def choose_partition(self, q_full) -> None:
        """No partitions in joint coordinates."""

    def carried(self, t, theta, rate):
        """(θ, θ̇) of dense output put back on the closure (the :meth:`project` of a correcting
        treatment, its counters left as they were); the identity otherwise."""
        if not self.corrects:
            return theta, rate
        counters = dict(self.counters)
        theta, rate = self.project(t, theta, rate)
        self.counters.update(counters)
        return theta, rate


def joint_model_size(mech: Mechanism, q0: np.ndarray) -> dict:
    """The joint-coordinate model's size as :meth:`mbh._adapters.base.Adapter.model_size` gives
    it: θ (``coordinates``), the cut joints' closure equations, the redundant ones at the common
    start ``q0`` (n,), and the run's model note."""
    model = JointCoordinates(mech, q0, 1.0)
    return {"coordinates": model.n, "constraint_equations": model.closure.m,
            "redundant_equations": len(model.redundant), "notes": model.notes[0]}


class JointNone(JointCoordinates):
    name = "none"
    description = "joint coordinates, Lagrange multipliers at the cut joints, no stabilisation"
    defaults = NoStabilisation.defaults


class JointBaumgarte(JointCoordinates):
    name = "baumgarte"
    description = "joint coordinates with Baumgarte's γ − 2αΦ̇ − β²Φ at the cut joints"
    defaults = Baumgarte.defaults

    def __init__(self, mech, q0, dt, **params):
        super().__init__(mech, q0, dt, **params)
        if self.params["auto"]:
            self.params["alpha"], self.params["beta"] = 1.0 / dt, np.sqrt(2.0) / dt
        self.gains = (float(self.params["alpha"]), float(self.params["beta"]))
        self._args = self._kernel_args()


class JointDirect(JointCoordinates):
    name = "direct"
    description = "joint coordinates with position and velocity projection onto the closure"
    defaults = DirectCorrection.defaults
    corrects = True

    def __init__(self, mech, q0, dt, **params):
        super().__init__(mech, q0, dt, **params)
        self.cut = (projection_cut(self.closure_jacobian(0.0, self.kinematics.theta0),
                                   self.params["singular_cut"]) if self.closure.m else 0.0)

    def _min_norm(self, c, residual):
        """C_θ⁺ r, truncated at ``cut`` × the largest singular value (as the absolute
        projection, :class:`~.stabilisation.DirectCorrection`)."""
        self.counters["factorizations"] += 1
        return truncated_solve(np.ascontiguousarray(c), np.ascontiguousarray(residual), self.cut)

    def project_position(self, t, theta):
        """Newton on Φ_θ(θ) = 0 with C_θ⁺ (eq. 127 in θ): :func:`~.stabilisation.newton_onto`."""
        return newton_onto(lambda x: self.closure_residual(t, x),
                           lambda x, residual: self._min_norm(self.closure_jacobian(t, x), residual),
                           theta, self.params, self.counters)

    def project(self, t, q, v):
        if not self.closure.m:
            return q, v
        theta = self.project_position(t, q)
        c = self.closure_jacobian(t, theta)
        return theta, v - self._min_norm(c, c @ v)


JOINT_TREATMENTS = {cls.name: cls for cls in (JointNone, JointBaumgarte, JointDirect)}
