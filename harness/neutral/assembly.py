"""The neutral assembly: one consistent start for every engine (docs/design.md, rule 3).

Positions: Newton–Raphson on the body poses with the neutral joint equations and the driver row
(Frączek & Wojtyra 2009, eq. 1.21–1.30), from the reference configuration with ``initial.guess`` positions in
place of the reference positions of the bodies it names (the guess picks the branch).  A step
solves J Δ = −Φ in least squares (scipy.linalg.lstsq) for the body twists Δ = [Δr, Δθ]; positions
move by Δr, rotations by the exponential map R ← exp(Δθ) R (scipy Rotation.from_rotvec).

Velocities: body twists meeting the joint velocity rows = 0 exactly (in their null space) and the
driver rate and the prescribed velocities (``initial.velocities`` in the file, ``InitialState.prescribed`` here) conditions (joint rates, body-point velocity
components) in least squares; every condition is then checked.

Then the start is checked and refused with :class:`AssemblyError` when Newton did not converge,
when the configuration is singular (rank lost, or the condition number of [independent rows;
driver row] above :data:`mbh._harness.neutral.mobility.CONDITION_LIMIT`), when the velocity conditions cannot all
hold, or when the driver's value or rate is not the one asked.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
from scipy.spatial.transform import Rotation

from mbh._harness.neutral.equations import JointEquations, body_twists, point_velocity_jacobian
from mbh._harness.model.mechanism import (DRIVABLE, Mechanism, PrescribedJointRate,
                                          PrescribedPointVelocity)
from mbh._harness.neutral.mobility import CONDITION_LIMIT, RankReport, rank_analysis
from mbh._harness.model.trajectory import BodyStates
from mbh._harness.common.errors import MbhError

#: Newton stops, and a start is accepted, when max |residual| ≤ this × max(1, L), in m or rad, with
#: L (m) the mechanism's size (largest |coordinate| of a reference position or joint point).  The
#: residual after convergence is round-off, ~1e-16·L (figures: docs/measurements.md, section
#: "Assembly and rank analysis"), so this leaves > 1000× margin and still means "assembled to
#: machine precision" for any physical purpose.
POSITION_TOLERANCE = 1e-12
#: Newton iterations before giving up (the shipped scenes need 0–4).
MAX_ITERATIONS = 50
#: Newton steps taken after reaching the tolerance, to bring the residual down to round-off.
POLISH_STEPS = 2
#: The velocity conditions hold when max |J ν − b| ≤ this × max(1, max |b|) (m/s or rad/s).  A
#: consistent system solved in least squares leaves at most ~1e-16·κ·|b| with κ ≤ CONDITION_LIMIT
#: = 1e6 accepted, i.e. ≤ ~1e-10 in the worst accepted case (round-off on the shipped scenes); an
#: inconsistent prescription misses by the inconsistency itself, orders of magnitude more.
VELOCITY_TOLERANCE = 1e-9


class AssemblyError(MbhError, ValueError):
    """The mechanism cannot be started at the requested driver state; the message names the
    scenario file, the driver and the numbers."""


class SingularStartError(AssemblyError):
    """The start is at a singular configuration; ``report`` holds the rank analysis there."""

    def __init__(self, message: str, report: RankReport):
        super().__init__(message)
        self.report = report


@dataclass(frozen=True)
class Assembly:
    """A consistent state at t = 0.

    Attributes
    ----------
    states : BodyStates
        World body states satisfying the joint equations and the driver.
    residual : float
        max |residual| of the joint and driver rows after assembly (m or rad).
    velocity_residual : float
        max |J ν − b| of the velocity conditions (m/s or rad/s).
    iterations : int
        Newton–Raphson iterations to reach the tolerance.
    report : RankReport
        The rank analysis at the start (its ``condition`` is also :attr:`condition`).
    """

    states: BodyStates
    residual: float
    velocity_residual: float
    iterations: int
    report: RankReport

    @property
    def condition(self) -> float:
        """Condition number of [independent rows; driver row] at the start."""
        return self.report.condition


def _size(mech: Mechanism) -> float:
    """The mechanism's length scale L, m (see :data:`POSITION_TOLERANCE`)."""
    lengths = [np.abs(b.position).max() for b in mech.bodies]
    lengths += [np.abs(p).max() for j in mech.joints for p in (j.point1, j.point2)]
    return max(1.0, *lengths)


def _start_pose(mech: Mechanism) -> tuple[np.ndarray, Rotation]:
    position = np.array([mech.initial.guess.get(b.name, b.position) for b in mech.bodies],
                        dtype=float)
    return position, Rotation.from_matrix(np.array([b.rotation for b in mech.bodies]))


def _where(equations: JointEquations, residual: np.ndarray) -> tuple[float, str]:
    worst = int(np.nanargmax(np.abs(residual))) if residual.size else 0
    value = float(np.abs(residual[worst])) if residual.size else 0.0
    return value, (f"{equations.labels[worst]} ({equations.units[worst]})" if residual.size else "")


def newton_positions(mech: Mechanism, equations, tolerance: float,
                     start: tuple[np.ndarray, Rotation] | None = None):
    """Newton–Raphson on the body poses, least-squares steps in body twists (so consistent
    redundant rows are fine).

    Parameters
    ----------
    mech : Mechanism
    equations
        :class:`~mbh._harness.neutral.equations.JointEquations` or an object with its ``residuals`` and
        ``jacobian``.
    tolerance : float
        max |residual| (m or rad) at which the iteration has converged; two polishing steps
        follow.
    start : (position (n_bodies, 3), Rotation of n_bodies), optional
        First iterate; default the reference configuration with ``initial.guess`` positions.

    Returns
    -------
    (position, rotation, residual, iterations, converged) at the best iterate.
    """
    position, rotation = _start_pose(mech) if start is None else start
    best = (position, rotation, np.inf)
    converged_at = None
    for iteration in range(MAX_ITERATIONS + POLISH_STEPS + 1):
        residual = equations.residuals(position, rotation.as_quat(scalar_first=True))
        size = float(np.max(np.abs(residual))) if residual.size else 0.0
        if not np.isfinite(size):
            break
        if size < best[2]:
            best = (position, rotation, size)
        if converged_at is None and size <= tolerance:
            converged_at = iteration
        polished = converged_at is not None and iteration >= converged_at + POLISH_STEPS
        if size == 0.0 or polished or (converged_at is None and iteration >= MAX_ITERATIONS):
            break
        jacobian = equations.jacobian(position, rotation.as_quat(scalar_first=True))
        step = body_twists(scipy.linalg.lstsq(jacobian, -residual, lapack_driver="gelsd")[0],
                           mech.planar)
        position = position + step[:, :3]
        rotation = Rotation.from_rotvec(step[:, 3:]) * rotation
    iterations = MAX_ITERATIONS if converged_at is None else converged_at
    return best[0], best[1], best[2], iterations, converged_at is not None


def _check_prescribed(mech: Mechanism) -> None:
    """Refuse prescribed conditions that name no drivable joint or no body."""
    source = mech.source or mech.name
    joints = {joint.name: joint.type for joint in mech.joints}
    bodies = {body.name for body in mech.bodies}
    for index, condition in enumerate(mech.initial.prescribed):
        field = f"{source}: initial.velocities[{index}]"
        if isinstance(condition, PrescribedJointRate) and joints.get(condition.joint) not in DRIVABLE:
            problem = ("unknown joint" if condition.joint not in joints
                       else f"{joints[condition.joint]} joint")
            raise AssemblyError(f"{field}: {problem} {condition.joint!r} has no single coordinate "
                                "to prescribe a rate for (joints with one: "
                                f"{', '.join(n for n, t in joints.items() if t in DRIVABLE)})")
        if isinstance(condition, PrescribedPointVelocity) and condition.body not in bodies:
            raise AssemblyError(f"{field}: unknown body {condition.body!r} "
                                f"(known: {', '.join(bodies)})")


def _velocity_system(mech: Mechanism, position, quaternion, value, rate):
    """Rows, right-hand side and labels of the velocity conditions at t = 0."""
    prescribed = mech.initial.prescribed
    joints = tuple(p.joint for p in prescribed if isinstance(p, PrescribedJointRate))
    equations = JointEquations(mech, with_driver=True, drive=(value, rate), coordinates=joints)
    jacobian = equations.jacobian(position, quaternion)
    fixed = equations.n_joint_rows + 1  # the joint rows and the driver row
    blocks, rhs = [jacobian[:fixed]], [np.zeros(equations.n_joint_rows), [rate]]
    labels = list(equations.labels[:fixed])
    joint_rate_rows = iter(jacobian[fixed:])
    for index, condition in enumerate(prescribed):
        field = f"initial.velocities[{index}]"
        if isinstance(condition, PrescribedJointRate):
            blocks.append(next(joint_rate_rows)[None, :])
            rhs.append([condition.rate])
            labels.append(f"{field}: rate of joint {condition.joint}")
        elif isinstance(condition, PrescribedPointVelocity):
            rows = point_velocity_jacobian(mech, condition.body, condition.point, position,
                                           quaternion)
            components = list(condition.components)
            blocks.append(rows[components])
            rhs.append(np.asarray(condition.velocity, dtype=float)[components])
            labels += [f"{field}: velocity {'xyz'[c]} of body {condition.body}'s point "
                       f"{np.asarray(condition.point).tolist()}" for c in components]
    return np.vstack(blocks), np.concatenate([np.asarray(r, dtype=float) for r in rhs]), labels


def _velocities(matrix: np.ndarray, rhs: np.ndarray, report: RankReport) -> np.ndarray:
    """Twists meeting the joint rows exactly and the driver and prescribed rows in least squares.

    ν = N z with N a basis of the joint rows' null space (the motions the joints allow), z the
    least-squares solution of the remaining rows; a contradiction thus shows in the driver and
    prescribed rows, whichever of them it is, and never in the joints.
    """
    joints = matrix[:report.n_equations]
    basis = scipy.linalg.null_space(joints) if joints.size else np.eye(matrix.shape[1])
    rest = matrix[report.n_equations:] @ basis
    return basis @ scipy.linalg.lstsq(rest, rhs[report.n_equations:], lapack_driver="gelsd")[0]


def assemble(mech: Mechanism, value: float | None = None, rate: float | None = None) -> Assembly:
    """Assemble the mechanism at the driver value and rate (default ``mech.initial``'s), solve
    the velocities, and check the start.

    Raises
    ------
    AssemblyError
        No convergence, an inconsistent set of velocity conditions, or the driver state missed;
        :class:`SingularStartError` at a singular configuration.  Each message names the scenario
        file, the driver and the numbers.
    """
    _check_prescribed(mech)
    value = mech.initial.value if value is None else value
    rate = mech.initial.rate if rate is None else rate
    source = mech.source or mech.name
    driver = mech.initial.driver
    equations = JointEquations(mech, with_driver=True, drive=(value, rate))
    tolerance = POSITION_TOLERANCE * _size(mech)
    position, rotation, residual, iterations, converged = newton_positions(mech, equations,
                                                                         tolerance)
    quaternion = rotation.as_quat(scalar_first=True)
    if not converged:
        worst, label = _where(equations, equations.residuals(position, quaternion))
        raise AssemblyError(
            f"{source}: the mechanism cannot be assembled with driver {driver} = {value:g}: "
            f"Newton–Raphson stopped after {iterations} iterations at max |residual| = "
            f"{worst:.3g} in row '{label}' (tolerance {tolerance:.1e}; no configuration satisfies "
            "the constraints there: check link lengths and the driver value; Frączek & Wojtyra 2009, example 1.9)")

    report = rank_analysis(mech, position, quaternion, drive=(value, rate))
    if report.singular:
        raise SingularStartError(
            f"{source}: singular configuration at driver {driver} = {value:g}: the constraint "
            f"Jacobian has condition {report.condition:.3g} (limit {CONDITION_LIMIT:.0e}) and rank "
            f"mobility {report.mobility} where the joints allow {max(report.grubler_mobility, 1)}; "
            "the assembly branch is ambiguous; move the driver value or give initial.guess "
            "positions that pick a branch", report)

    matrix, rhs, labels = _velocity_system(mech, position, quaternion, value, rate)
    twist = _velocities(matrix, rhs, report)
    miss = matrix @ twist - rhs
    velocity_residual = float(np.max(np.abs(miss))) if miss.size else 0.0
    velocity_tolerance = VELOCITY_TOLERANCE * max(1.0, float(np.max(np.abs(rhs), initial=0.0)))
    if not velocity_residual <= velocity_tolerance:
        missed = "; ".join(f"'{labels[i]}' asked {rhs[i]:g}, missed by {miss[i]:.3g}"
                           for i in np.flatnonzero(~(np.abs(miss) <= velocity_tolerance)))
        raise AssemblyError(
            f"{source}: inconsistent initial velocities at driver {driver} = {value:g}, rate "
            f"{rate:g}: {missed} (tolerance {velocity_tolerance:.1e}): the driver rate and the "
            "prescribed velocities contradict the joints or each other; remove or correct one")

    twists = body_twists(twist, mech.planar)
    states = BodyStates(position, quaternion, twists[:, :3].copy(), twists[:, 3:].copy())
    _check_driver(mech, equations, states, value, rate, tolerance, velocity_tolerance)
    return Assembly(states, residual, velocity_residual, iterations, report)


def _check_driver(mech, equations, states, value, rate, tolerance, velocity_tolerance) -> None:
    """Refuse a start whose driver coordinate or rate is not the one asked."""
    row = equations.n_joint_rows
    missed = float(equations.residuals(states.position, states.quaternion)[row])
    missed_rate = float(equations.velocity_residuals(states.position, states.quaternion,
                                                     states.velocity,
                                                     states.angular_velocity)[row])
    if abs(missed) > tolerance or abs(missed_rate) > velocity_tolerance:
        raise AssemblyError(
            f"{mech.source or mech.name}: driver {mech.initial.driver} is at {value + missed:.12g} "
            f"with rate {rate + missed_rate:.12g} after assembly, asked {value:g} and {rate:g}")
