"""Reference routes along a declared assembly branch, for scenes that pass singular positions.

Why
---
At a singular position the constraint set is locally two (or more) branches crossing: on the
N-four-bar flattened, rank Φ_q drops from 14 to 12 and the parallelogram branch crosses the
branches where the cranks turn differently.  A route in full coordinates that satisfies Φ only to
a residual ε sees, near the crossing, the hyperbola ψ·b = ε (ψ along the branch, b across it)
instead of the crossing: it leaves the branch by ~√ε, and its velocity projection there forces
transverse rates of the order of the speed along the branch.  On ``double_fourbar`` the
rk4+direct and rkn4+direct routes of :mod:`mbh._harness.references.build` therefore disagree far beyond
the agreement limit, the more so the smaller the step (more projections near the crossing;
figures: docs/measurements.md, section "References").

A scene that stays on one branch can say so: ``[reference] equal_joint_angles`` lists pairs of
revolute or cylindrical joints that turn by equal angles on it (the parallelogram's cranks).
Those relations are not constraints of the mechanism — the engines and the measuring stick never
see them — but rows the routes add to the joint equations (:class:`BranchEquations`).  With them
the rank is the same through the passage (14 of 16 rows on the N-four-bar, everywhere), the
branch is a smooth manifold, and two independent routes are well posed:

* :func:`reduced_route` — one coordinate: the driver joint's coordinate θ (the scene must have
  mobility 1 on the branch).  q(θ) by Newton–Raphson on the joint, branch and driver rows; the
  twist per unit rate ν' = ∂ν/∂θ̇ and the acceleration at zero θ̈, a₀ θ̇², from the same rows
  (G ν' = e_θ; G a₀ = γ(ν'), Frączek & Wojtyra 2009, eq. 1.62); the equation of motion projected on ν'
  (Kane's / the virtual-power form):  θ̈ = ν'ᵀ (Q − M a₀ θ̇²) / (ν'ᵀ M ν').  Integrated by DOP853.
* :func:`full_route` — every body's pose and twist: the index-1 Newton–Euler equations of
  :mod:`mbh._harness.neutral.dynamics` with the branch rows among the constraints and Baumgarte's
  stabilisation against drift (which changes nothing on the constraints), integrated by DOP853.

Both use only the harness's neutral joint equations, never the in-house kernels.  Their
right-hand sides (and the reduced route's Newton–Raphson) run compiled
(:mod:`mbh._harness.neutral.dynamics_kernels` on :mod:`mbh._harness.neutral.equation_kernels`): the same equations as
:mod:`mbh._harness.neutral.equations` and :mod:`mbh._harness.neutral.dynamics` in another operation order,
under scipy's DOP853 (its own per-step cost is a small part of a route beside them), and must
agree with the interpreted equations' references within the agreement limit (figures:
docs/measurements.md, section "References").

A scene without singular passages may ask for the same two routes with ``[reference] routes =
"neutral"`` (``Mechanism.neutral_routes``): then there are no branch rows, only the joints (and
the driver's row in the reduced route) — for scenes where the in-house RK4/RKN4 routes at a fixed
step cannot reach the agreement limit (a crank spinning at 10³ rad/s, a stiff spring).
"""

from __future__ import annotations

import time

import numpy as np
from scipy.integrate import solve_ivp

from mbh._harness.neutral.assembly import MAX_ITERATIONS, POLISH_STEPS, POSITION_TOLERANCE, assemble
from mbh._harness.neutral.equations import JointEquations, body_twists, twist_vector
from mbh._harness.model.mechanism import Mechanism
from mbh._harness.neutral.dynamics import (DIFFERENCE_STEP, DIFFERENCE_TURN, KKT_RCOND,
                                      UNIQUENESS_RATIO, IndeterminateAccelerations, accelerations)
from mbh._harness.neutral.equation_kernels import CompiledRows, row_table
from mbh._harness.neutral.dynamics_kernels import (body_table, branch_acceleration, branch_pose,
                                                   branch_rate, full_rates, mass_spread)
from mbh._harness.model.outputs import wrap_angle
from mbh._harness.model.trajectory import BodyStates, Trajectory
from mbh._harness.common.errors import MbhError

#: DOP853 tolerance of both routes (relative and absolute, on θ in rad and θ̇ in rad/s, or on
#: positions in m, quaternions and twists).
ROUTE_TOLERANCE = 1e-13
#: Baumgarte's (α, β), 1/s, of the full route: without them its drift off the constraints grows
#: from 1e-13 m to 3.5e-7 m over double_fourbar's 10 s (index-1 drift).
FULL_ROUTE_BAUMGARTE = (20.0, 20.0)


class BranchRouteError(MbhError, ValueError):
    """The scene cannot be followed along its branch (no relations, wrong mobility, Newton
    failed); the message says which and where."""


class BranchEquations:
    """The joint rows, then one row per branch relation, then (optionally) the driver row.

    A relation (a, b) is the coordinate of joint b minus that of joint a minus its value at the
    start, wrapped to (−π, π] (rad).  Same interface as
    :class:`~mbh._harness.neutral.equations.JointEquations` (``residuals``, ``jacobian``,
    ``velocity_residuals``, ``m``); the driver row is the driver's coordinate minus
    :attr:`drive` (rad or m, from the reference configuration) and is the last row.

    Parameters
    ----------
    mech : Mechanism
        With ``mech.neutral_routes`` (a declared branch, or ``routes = "neutral"``; ``mech.branch``
        may then be empty).
    start : BodyStates
        A configuration on the branch (the assembled start): the relations' zero.
    with_driver : bool
        Append the driver row.
    """

    def __init__(self, mech: Mechanism, start: BodyStates, with_driver: bool = False):
        if not mech.neutral_routes:
            raise BranchRouteError(f"{mech.source or mech.name}: neither [reference] "
                                   "equal_joint_angles nor routes = \"neutral\": the scene "
                                   "does not ask for the neutral routes")
        names = tuple(dict.fromkeys(name for pair in mech.branch for name in pair))
        self._base = JointEquations(mech, with_driver=with_driver, drive=(0.0, 0.0),
                                    coordinates=names)
        joints = self._base.n_joint_rows
        drivers = 1 if with_driver else 0
        column = {name: joints + drivers + k for k, name in enumerate(names)}
        self.m = joints + len(mech.branch) + drivers
        combine = np.zeros((self.m, self._base.m))
        combine[:joints, :joints] = np.eye(joints)
        for k, (first, second) in enumerate(mech.branch):
            combine[joints + k, column[second]] = 1.0
            combine[joints + k, column[first]] = -1.0
        if with_driver:
            combine[-1, joints] = 1.0
        self._combine = combine
        self._branch = slice(joints, joints + len(mech.branch))
        self.n_joint_rows = joints
        self.twist_size = self._base.twist_size
        self.labels = (self._base.labels[:joints]
                       + tuple(f"branch: {b} turns with {a}" for a, b in mech.branch)
                       + self._base.labels[joints:joints + drivers])
        self.drive = 0.0
        self._zero = np.zeros(self.m)
        self._zero[self._branch] = self.residuals(start.position, start.quaternion)[self._branch]
        self._with_driver = with_driver

    def compiled(self) -> CompiledRows:
        """The same rows, compiled (:mod:`mbh._harness.neutral.equation_kernels`), for one state at a time;
        its ``drive`` starts at 0."""
        wrapped = np.zeros(self.m, dtype=bool)
        wrapped[self._branch] = True
        wrapped[self._branch.stop:] = self._with_driver
        return CompiledRows(row_table(self._base, self._combine, self._zero, wrapped),
                            self._base.mech.planar, driver_row=self._with_driver)

    def residuals(self, position, quaternion, t=0.0) -> np.ndarray:
        """Rows, shape (..., m), m or rad."""
        rows = self._base.residuals(position, quaternion) @ self._combine.T - self._zero
        rows[..., self._branch] = wrap_angle(rows[..., self._branch])
        if self.m > self._branch.stop:
            rows[..., -1] = wrap_angle(rows[..., -1] - self.drive)
        return rows

    def jacobian(self, position, quaternion) -> np.ndarray:
        """∂(rows)/∂(body twists), shape (..., m, twist_size·n_bodies)."""
        return self._combine @ self._base.jacobian(position, quaternion)

    def velocity_residuals(self, position, quaternion, velocity, angular_velocity) -> np.ndarray:
        """Rates of the rows, shape (..., m) (the driver row: the driver's rate)."""
        return self._base.velocity_residuals(position, quaternion, velocity,
                                             angular_velocity) @ self._combine.T


def _velocities(mech: Mechanism, twist: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Linear and angular velocities, (n_bodies, 3) each, from a twist vector over the joint
    equations' columns."""
    spatial = body_twists(twist, mech.planar)
    return spatial[:, :3], spatial[:, 3:]


class _BranchKinematics:
    """q(θ), ν'(θ) and a₀(θ) along the branch, warm-started from the last configuration (the
    rows compiled, :mod:`mbh._harness.neutral.dynamics_kernels`)."""

    def __init__(self, mech: Mechanism, start: BodyStates):
        self.mech = mech
        equations = BranchEquations(mech, start, with_driver=True)
        self.equations = equations.compiled()
        self.bodies = body_table(mech).arrays()
        self.tolerance = POSITION_TOLERANCE * max(1.0, float(np.abs(start.position).max()))
        self.restart(start)
        jacobian = equations.jacobian(start.position, start.quaternion)
        rank = np.linalg.matrix_rank(jacobian[:-1])
        if jacobian.shape[1] - rank != 1:
            raise BranchRouteError(
                f"{mech.source or mech.name}: the reduced route needs mobility 1 on the "
                f"branch; the joint and branch rows leave {jacobian.shape[1] - rank}")

    def restart(self, states: BodyStates) -> None:
        """Warm-start the next Newton solve from ``states``' configuration.  Samples are
        rebuilt in time order from the start: a warm start from the end of the run can land on
        another assembly branch at the first samples' θ."""
        self._last = (states.position.copy(), states.quaternion.copy())

    def pose(self, theta: float) -> tuple[np.ndarray, np.ndarray]:
        """Positions (n_bodies, 3) and quaternions (n_bodies, 4) at driver coordinate θ, by
        :func:`~mbh._harness.neutral.dynamics_kernels.branch_pose` (mbh._harness.neutral.assembly's Newton–Raphson)."""
        self.equations.drive = theta
        position, quaternion, residual, converged = branch_pose(
            *self.equations.arrays(), self.mech.planar, *self._last, self.tolerance,
            MAX_ITERATIONS, POLISH_STEPS)
        if not converged:
            raise BranchRouteError(f"{self.mech.source or self.mech.name}: Newton–Raphson on "
                                   f"the branch failed at θ = {theta:.12g} (residual "
                                   f"{residual:.3g})")
        self._last = (position, quaternion)
        return position, quaternion

    def states(self, theta: float, theta_rate: float) -> BodyStates:
        """Body states at θ and θ̇ on the branch."""
        position, quaternion = self.pose(theta)
        rows = self.equations.table
        rate = branch_rate(rows.kind, rows.bodies, rows.vectors, rows.combine, self.mech.planar,
                           position, quaternion, KKT_RCOND)
        return BodyStates(position, quaternion, *_velocities(self.mech, rate * theta_rate))

    def acceleration(self, theta: float, theta_rate: float) -> float:
        """θ̈ = ν'ᵀ (Q − M a₀ θ̇²) / (ν'ᵀ M ν'), rad/s² (or m/s²); a₀ solves G a₀ = γ(ν')."""
        position, quaternion = self.pose(theta)
        rows = self.equations.table
        return float(branch_acceleration(rows.kind, rows.bodies, rows.vectors, rows.rate,
                                         rows.combine, *self.bodies, self.mech.planar, position,
                                         quaternion, theta_rate, DIFFERENCE_STEP,
                                         DIFFERENCE_TURN, KKT_RCOND))


def _start(mech: Mechanism) -> BodyStates:
    return assemble(mech).states


def _driver_state(mech: Mechanism, start: BodyStates) -> tuple[float, float]:
    """The driver coordinate (from the reference configuration) and its rate at the start."""
    equations = JointEquations(mech, with_driver=True, drive=(0.0, 0.0))
    row = equations.n_joint_rows
    value = equations.residuals(start.position, start.quaternion)[row]
    rate = equations.velocity_residuals(start.position, start.quaternion, start.velocity,
                                        start.angular_velocity)[row]
    return float(value), float(rate)


def _trajectory(grid: np.ndarray, states: list[BodyStates], solution,
                stepping: float) -> Trajectory:
    stack = {key: np.array([getattr(s, key) for s in states])
             for key in ("position", "quaternion", "velocity", "angular_velocity")}
    return Trajectory(times=np.asarray(grid, dtype=float), **stack, wall_time_s=stepping,
                      counters={"rhs_evals": int(solution.nfev)})


def _timed(function, *args):
    """``function(*args)`` and its wall time, s: a route's stepping time (``wall_time_s``), as
    the in-house routes report theirs, so that a reference build's estimate of a stage scales
    the stepping alone and counts set-up and compilation once."""
    began = time.perf_counter()
    result = function(*args)
    return result, time.perf_counter() - began


def _solve(rhs, t_end: float, y0, grid: np.ndarray, name: str, mech: Mechanism):
    solution = solve_ivp(rhs, (0.0, t_end), y0, method="DOP853", t_eval=grid,
                         rtol=ROUTE_TOLERANCE, atol=ROUTE_TOLERANCE)
    if solution.status != 0:
        raise BranchRouteError(f"{mech.source or mech.name}: the {name} route's DOP853 "
                               f"stopped: {solution.message}")
    return solution


def reduced_route(mech: Mechanism, grid: np.ndarray) -> Trajectory:
    """The branch followed in the driver coordinate alone (see the module docstring).

    Parameters
    ----------
    mech : Mechanism
        With ``mech.neutral_routes`` and mobility 1 (on the branch, if one is declared).
    grid : ndarray, shape (n,)
        Sample times from 0 to the end, s.
    """
    start = _start(mech)
    kinematics = _BranchKinematics(mech, start)

    def rhs(_t, y):
        return [y[1], kinematics.acceleration(y[0], y[1])]

    solution, stepping = _timed(_solve, rhs, float(grid[-1]), list(_driver_state(mech, start)),
                                grid, "reduced", mech)
    kinematics.restart(start)
    states = [kinematics.states(theta, rate) for theta, rate in solution.y.T]
    return _trajectory(grid, states, solution, stepping)


def _unpack(mech: Mechanism, y: np.ndarray) -> BodyStates:
    """Body states from the full route's vector [positions (3 n_b), quaternions (4 n_b), twist];
    quaternions normalised."""
    n = len(mech.bodies)
    position = y[:3 * n].reshape(n, 3)
    quaternion = y[3 * n:7 * n].reshape(n, 4)
    quaternion = quaternion / np.linalg.norm(quaternion, axis=1, keepdims=True)
    return BodyStates(position, quaternion, *_velocities(mech, y[7 * n:]))


def full_route(mech: Mechanism, grid: np.ndarray) -> Trajectory:
    """Every body's pose and twist, index-1 Newton–Euler with the branch rows (module docstring).

    Parameters
    ----------
    mech : Mechanism
        With ``mech.neutral_routes``.
    grid : ndarray, shape (n,)
        Sample times from 0 to the end, s.
    """
    start = _start(mech)
    equations = BranchEquations(mech, start)
    tables = (*equations.compiled().table.arrays(), *body_table(mech).arrays())
    spread = mass_spread(mech)

    def rhs(t, y):
        rates, unique = full_rates(y, *tables, mech.planar, *FULL_ROUTE_BAUMGARTE,
                                   DIFFERENCE_STEP, DIFFERENCE_TURN, KKT_RCOND, UNIQUENESS_RATIO,
                                   spread)
        if not unique:  # the numpy path's message names the body that moves most
            accelerations(mech, _unpack(mech, y), equations, baumgarte=FULL_ROUTE_BAUMGARTE)
            raise IndeterminateAccelerations(f"{mech.source or mech.name}: the accelerations "
                                             f"are not unique at t = {t:.12g} s")
        return rates

    y0 = np.concatenate([start.position.ravel(), start.quaternion.ravel(),
                         twist_vector(start.velocity, start.angular_velocity, mech.planar)])
    rhs(0.0, y0)  # the compiled rates' first call compiles or loads them: set-up, not stepping
    solution, stepping = _timed(_solve, rhs, float(grid[-1]), y0, grid, "full", mech)
    states = [_unpack(mech, y) for y in solution.y.T]
    return _trajectory(grid, states, solution, stepping)
