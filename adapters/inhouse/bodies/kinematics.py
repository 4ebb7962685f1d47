"""Kinematic analysis in absolute coordinates: Newton–Raphson assembly from the driver value,
velocity and acceleration analysis, and the rank report (Frączek & Wojtyra 2009, §1.1.2 and §1.3; Rouvinen 2003
eq. 15–23).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from mbh._adapters.inhouse.bodies.constraints import (ConstraintSystem, layout_of,
                                                      reference_coordinates)
from mbh._adapters.inhouse.numerics.rank import JacobianRank, jacobian_rank
from mbh._adapters.inhouse.bodies.states import coordinates
from mbh._harness.common.errors import MbhError
from mbh._harness.model.mechanism import Mechanism, grubler_mobility

#: Assembly stops when max |Φ| falls below this (m, rad, or dimensionless).
ASSEMBLY_TOLERANCE = 1e-13
ASSEMBLY_MAX_ITERATIONS = 50


class InhouseAssemblyError(MbhError, ValueError):
    """The in-house formulation cannot be assembled at the requested driver value, or the common
    start does not satisfy its joint equations."""


@dataclass(frozen=True)
class Assembly:
    """A consistent state at t = 0.

    Attributes
    ----------
    q, v, a : ndarray, shape (n,)
        Coordinates, velocities and accelerations satisfying Φ = 0, Φ_q v = −Φ_t, Φ_q a = γ.
    residual : float
        max |Φ| after assembly.
    iterations : int
        Newton–Raphson iterations used.
    """

    q: np.ndarray
    v: np.ndarray
    a: np.ndarray
    residual: float
    iterations: int


def _solve(matrix: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Least-squares solve (handles the consistent over-determined systems of redundant joints);
    never an explicit inverse."""
    return scipy.linalg.lstsq(matrix, rhs, lapack_driver="gelsd")[0]


def newton_raphson(system: ConstraintSystem, q0: np.ndarray, t: float = 0.0,
                   tol: float = ASSEMBLY_TOLERANCE, max_iter: int = ASSEMBLY_MAX_ITERATIONS):
    """Solve Φ(q, t) = 0 from q0 by Newton–Raphson, Φ_q Δq = −Φ (Frączek & Wojtyra 2009, eq. 1.21–1.30).

    Returns
    -------
    q : ndarray, shape (n,)
    residual : float
        max |Φ| reached (the smallest seen if it did not converge).
    iterations : int
    converged : bool
    """
    q = np.array(q0, dtype=float)
    best_q, best = q.copy(), np.inf
    for iteration in range(max_iter + 1):
        residual_vector = system.phi(q, t)
        residual = float(np.max(np.abs(residual_vector))) if residual_vector.size else 0.0
        if not np.isfinite(residual):
            break
        if residual < best:
            best_q, best = q.copy(), residual
        if residual < tol:
            return q, residual, iteration, True
        q = q + _solve(system.jacobian(q, t), -residual_vector)
    return best_q, best, max_iter, False


def assemble(mech: Mechanism, value: float | None = None, rate: float | None = None) -> Assembly:
    """Assemble the mechanism at the driver value, then solve velocities and accelerations.

    Raises
    ------
    InhouseAssemblyError
        When Newton–Raphson does not reach :data:`ASSEMBLY_TOLERANCE`; the message names the
        mechanism, the driver value and the residual reached.
    """
    value = mech.initial.value if value is None else value
    rate = mech.initial.rate if rate is None else rate
    system = ConstraintSystem(mech, with_driver=True, drive=(value, rate))
    q, residual, iterations, converged = newton_raphson(system, reference_coordinates(mech))
    if not converged:
        raise InhouseAssemblyError(
            f"{mech.source or mech.name}: the mechanism cannot be assembled with driver "
            f"{mech.initial.driver} = {value:g}: Newton–Raphson stopped after {iterations} "
            f"iterations at max |Φ| = {residual:.3g} (no configuration satisfies the constraints "
            "there: check link lengths and the driver value; Frączek & Wojtyra 2009, example 1.9)")
    jacobian = system.jacobian(q)
    v = _solve(jacobian, -system.phi_t(q))
    a = _solve(jacobian, system.gamma(q, v))
    return Assembly(q, v, a, residual, iterations)


def common_start(mech: Mechanism) -> Assembly:
    """The harness's common start (docs/design.md, rule 3) in absolute coordinates.

    Every engine starts from :func:`mbh._harness.neutral.start.initial_state`; this converts it to (q, q̇)
    (planar angles taken on the branch of :func:`reference_coordinates`, so that the prismatic
    angle rows see no 2π) and polishes it onto the in-house joint equations: Newton–Raphson on Φ
    without the driver (usually no iteration: the start already satisfies the neutral equations
    to ~1e-15) and the minimum-norm velocity correction Φ_q⁺ Φ_q q̇ (Rouvinen 2003, eq. 137).  The driver
    value and rate are the harness's; nothing here re-assembles from the driver.

    Raises
    ------
    InhouseAssemblyError
        When the polish does not converge (the two formulations' joint equations disagree).
    """
    from mbh._harness.neutral.start import initial_state

    layout = layout_of(mech)
    q, v = coordinates(layout, initial_state(mech))
    if layout.planar:
        reference = reference_coordinates(mech)[2::3]
        q[2::3] = reference + (q[2::3] - reference + np.pi) % (2.0 * np.pi) - np.pi
    system = ConstraintSystem(mech)
    q, residual, iterations, converged = newton_raphson(system, q)
    if not converged:
        raise InhouseAssemblyError(
            f"{mech.source or mech.name}: the common start does not satisfy the in-house joint "
            f"equations (max |Φ| = {residual:.3g} after {iterations} Newton–Raphson iterations)")
    jacobian = system.jacobian(q)
    v = v - _solve(jacobian, jacobian @ v)
    a = _solve(jacobian, system.gamma(q, v))
    return Assembly(q, v, a, residual, iterations)


def rank_report(mech: Mechanism, q: np.ndarray) -> JacobianRank:
    """Rank analysis of the joint equations at configuration q
    (:func:`~mbh._adapters.inhouse.numerics.rank.jacobian_rank`)."""
    joints = ConstraintSystem(mech)
    driven = ConstraintSystem(mech, with_driver=True)
    return jacobian_rank(joints.jacobian(q), joints.labels, driven.jacobian(q)[-1])


def check(mech: Mechanism) -> dict:
    """The kinematic analysis printed by ``mbh check``: one JSON-ready dict."""
    assembly = assemble(mech)
    report = rank_report(mech, assembly.q)
    return {
        "scenario": mech.name,
        "kind": mech.kind,
        "n_bodies": len(mech.bodies),
        "n_coordinates": report.n_coordinates,
        "n_equations": report.n_equations,
        "rank": report.rank,
        "mobility": report.mobility,
        "grubler_mobility": grubler_mobility(mech),
        "redundant_equations": len(report.redundant),
        "redundant_equation_labels": list(report.redundant_labels),
        "assembly_residual": assembly.residual,
        "assembly_iterations": assembly.iterations,
        "jacobian_condition": report.condition,
        "smallest_singular_value": report.smallest_singular_value,
    }
