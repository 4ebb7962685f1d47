"""The neutral model's accelerations at a consistent state: Newton–Euler in body twists with the
joint equations of :mod:`mbh._harness.neutral.equations` as index-1 constraints.

Equations (Rouvinen 2003, §3: Newton–Euler equations with Lagrange multipliers; Frączek & Wojtyra 2009, eq. 1.62 for the
acceleration-level constraint)
----------------------------------------------------------------------------------------------
With every body's twist ν_b = [v_b, ω_b] (centre-of-mass velocity and angular velocity, world
axes), mass matrix M = diag(m_b I₃, J_b) with J_b = A_b J̄_b A_bᵀ the world inertia, applied
wrench Q (forces at the centres of mass and torques about them) and the joint equations'
Jacobian G = ∂Φ̇/∂ν:

    M ν̇ + Gᵀ λ = Q − [0; ω × J ω]        (Newton–Euler with constraint reactions)
    G ν̇ = γ,   γ = −Ġ ν                  (second derivative of the joint equations)

solved together as one KKT system by least squares, so redundant joint equations (a planar
revolute loop closed in space, the N-four-bar's parallelogram) are handled: ν̇ is unique whenever
M is positive definite on the null space of G, the multipliers need not be.  When it is not (a
body with a zero principal moment free to turn about that axis: a slender bar on a revolute or
spherical joint on its own axis) any rate of that turn solves the equations, and
:class:`IndeterminateAccelerations` is raised rather than one of them returned.  Ġ ν is the central
difference of :meth:`~mbh._harness.neutral.equations.JointEquations.velocity_residuals` along the motion
at fixed twists (positions advanced by v·h, orientations by the rotation ω·h), of sixth order.

Planar mechanisms use the planar twists [v_x, v_y, ω_z] of the joint equations, with the inertia
about z; their gyroscopic term vanishes (z is a principal axis of a planar body).

Loads: gravity m g on every body; :class:`~mbh._harness.model.mechanism.BodyForce` at its point;
:class:`~mbh._harness.model.mechanism.BodyTorque`; :class:`~mbh._harness.model.mechanism.JointActuation` as a torque (revolute,
cylindrical) or a force at the joint points (prismatic, translational) along each body's own world
axis, +value on ``body2`` and −value on ``body1``; :class:`~mbh._harness.model.mechanism.SpringDamper` as the
tension k (L − L₀) + c L̇ along the line between its points.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
from scipy.spatial.transform import Rotation

from mbh._harness.neutral.equations import JointEquations, body_twists
from mbh._harness.model.outputs import body_rotations
from mbh._harness.model.mechanism import (BodyForce, BodyTorque, JointActuation, Mechanism,
                                          SpringDamper)
from mbh._harness.model.trajectory import BodyStates

#: Time step h (s) of the central differences that give Ġ ν: truncation h⁶/140 times the seventh
#: derivative (≈ 1e-15 relative for rates up to 7 rad/s), round-off ≈ 2e-16 / h ≈ 2e-13 relative.
DIFFERENCE_STEP = 1e-3
#: Largest turn (rad) of any body over one difference step: faster motions shorten the step to
#: DIFFERENCE_TURN / |ω|max (truncation ≈ DIFFERENCE_TURN⁶/140 ≈ 7e-15 relative).  A fixed 1e-3 s
#: turns Andrews' crank (1.4e3 rad/s) by 1.4 rad per step: its full route then ended 0.2 rad off.
DIFFERENCE_TURN = 1e-2
_TORQUE_JOINTS = ("revolute", "cylindrical")
#: Smallest ratio of the least to the largest eigenvalue of the mass matrix on the null space of
#: G for which the accelerations count as unique: generated mechanisms
#: (:mod:`mbh._harness.testing.strategies`) stay five orders of magnitude above it, a bar free to spin
#: about its own axis falls below it (figures: docs/measurements.md, section "Neutral dynamics").
UNIQUENESS_RATIO = 1e-9
#: Relative cut-off of the singular values in the KKT least-squares solve.  Redundant joint
#: equations give singular values at round-off (≈ 1e-16 of the largest); LAPACK's default
#: cut-off sits right there, so off the constraint manifold a redundant direction flips in and out
#: of the solution and the accelerations jump (DOP853 then stalls on the N-four-bar with its
#: branch rows).  Genuine singular values of the scenes are ≥ 1e-6 of the largest (the assembly
#: refuses a start with condition > 1e6).
KKT_RCOND = 1e-12


class IndeterminateAccelerations(ValueError):
    """The accelerations are not unique: the mass matrix is singular on a motion the joints
    allow."""


@dataclass(frozen=True)
class Accelerations:
    """Body accelerations at one instant.

    Attributes
    ----------
    linear : ndarray, shape (n_bodies, 3)
        Centre-of-mass accelerations, m/s², world frame.
    angular : ndarray, shape (n_bodies, 3)
        Angular accelerations, rad/s², world axes.
    """

    linear: np.ndarray
    angular: np.ndarray


def _point_state(states: BodyStates, rotations: np.ndarray, body: int, local: np.ndarray):
    """World arm from the centre of mass (m), position (m) and velocity (m/s) of a body point;
    ground (−1) is the world frame at rest."""
    local = np.asarray(local, dtype=float)
    if body < 0:
        return np.zeros(3), local, np.zeros(3)
    arm = rotations[body] @ local
    return (arm, states.position[body] + arm,
            states.velocity[body] + np.cross(states.angular_velocity[body], arm))


def applied_wrenches(mech: Mechanism, states: BodyStates) -> np.ndarray:
    """World force and torque about the centre of mass on every body, shape (n_bodies, 2, 3).

    Gravity and every load of ``mech.forces`` (see the module docstring); N and N·m.
    """
    rotations = body_rotations(states.quaternion)
    wrench = np.zeros((len(mech.bodies) + 1, 2, 3))  # last row: ground, discarded

    def push(body: int, force: np.ndarray, arm: np.ndarray,
             torque=np.zeros(3)) -> None:  # noqa: B008 (read only)
        wrench[body, 0] += force
        wrench[body, 1] += np.cross(arm, force) + torque

    for index, body in enumerate(mech.bodies):
        wrench[index, 0] += body.mass * np.asarray(mech.gravity, dtype=float)
    for load in mech.forces:
        if isinstance(load, BodyForce):
            index = mech.body_index(load.body)
            push(index, np.asarray(load.force, dtype=float),
                 _point_state(states, rotations, index, load.point)[0])
        elif isinstance(load, BodyTorque):
            wrench[mech.body_index(load.body), 1] += load.torque
        elif isinstance(load, JointActuation):
            joint = mech.joint(load.joint)
            sides = ((joint.body2, joint.point2, joint.axis2, load.value),
                     (joint.body1, joint.point1, joint.axis1, -load.value))
            for name, point, axis, value in sides:
                index = mech.body_index(name)
                world_axis = axis if index < 0 else rotations[index] @ axis
                if joint.type in _TORQUE_JOINTS:
                    wrench[index, 1] += value * world_axis
                else:
                    push(index, value * world_axis,
                         _point_state(states, rotations, index, point)[0])
        elif isinstance(load, SpringDamper):
            one, two = mech.body_index(load.body1), mech.body_index(load.body2)
            arm1, at1, velocity1 = _point_state(states, rotations, one, load.point1)
            arm2, at2, velocity2 = _point_state(states, rotations, two, load.point2)
            length = float(np.linalg.norm(at2 - at1))
            direction = (at2 - at1) / length
            tension = (load.stiffness * (length - load.free_length)
                       + load.damping * float(direction @ (velocity2 - velocity1)))
            push(one, tension * direction, arm1)
            push(two, -tension * direction, arm2)
        else:
            raise TypeError(f"load {load!r}: unknown load type {type(load).__name__}")
    return wrench[:-1]


def _world_inertias(mech: Mechanism, rotations: np.ndarray) -> np.ndarray:
    """World inertia tensors A J̄ Aᵀ, shape (n_bodies, 3, 3), kg·m²."""
    local = np.array([body.inertia for body in mech.bodies], dtype=float)
    return np.einsum("bij,bjk,blk->bil", rotations, local, rotations)


def _moved(states: BodyStates, h: float) -> BodyStates:
    """``states`` advanced by h along the motion at fixed twists (rotation ω·h in world axes)."""
    turn = Rotation.from_rotvec(h * states.angular_velocity)
    rotation = turn * Rotation.from_quat(states.quaternion, scalar_first=True)
    return BodyStates(states.position + h * states.velocity,
                      rotation.as_quat(scalar_first=True), states.velocity,
                      states.angular_velocity)


def gamma(equations: JointEquations, states: BodyStates) -> np.ndarray:
    """γ = −Ġ ν, shape (m,): the sixth-order central difference of the velocity residuals along
    the motion, Ġ ν ≈ [45 D(h) − 9 D(2h) + D(3h)] / (60 h) with D(kh) = r(kh) − r(−kh)."""
    fastest = float(np.abs(states.angular_velocity).max(initial=0.0))
    step = min(DIFFERENCE_STEP, DIFFERENCE_TURN / fastest) if fastest > 0.0 else DIFFERENCE_STEP

    def difference(k: int) -> np.ndarray:
        ahead, behind = (_moved(states, sign * k * step) for sign in (1.0, -1.0))
        rates = [equations.velocity_residuals(s.position, s.quaternion, s.velocity,
                                              s.angular_velocity) for s in (ahead, behind)]
        return rates[0] - rates[1]

    return -(45.0 * difference(1) - 9.0 * difference(2) + difference(3)) / (60.0 * step)


def twist_mass_and_forces(mech: Mechanism, states: BodyStates) -> tuple[np.ndarray, np.ndarray]:
    """Mass matrix M, shape (n, n), and applied forces minus gyroscopic terms Q − [0; ω × J ω],
    shape (n,), in the twist coordinates of the joint equations' Jacobian (n = 6·n_bodies
    spatial [v, ω]; 3·n_bodies planar [v_x, v_y, ω_z]); kg, kg·m², N, N·m."""
    rotations = body_rotations(states.quaternion)
    inertia = _world_inertias(mech, rotations)
    wrench = applied_wrenches(mech, states)
    omega = np.asarray(states.angular_velocity, dtype=float)
    wrench[:, 1] -= np.cross(omega, np.einsum("bij,bj->bi", inertia, omega))
    masses = mech.masses
    if mech.planar:
        blocks = [np.diag([m, m, j[2, 2]]) for m, j in zip(masses, inertia)]
        rhs = wrench.reshape(-1, 6)[:, [0, 1, 5]].ravel()
    else:
        blocks = [scipy.linalg.block_diag(m * np.eye(3), j) for m, j in zip(masses, inertia)]
        rhs = wrench.reshape(-1).copy()
    return scipy.linalg.block_diag(*blocks), rhs


def _check_unique(mech: Mechanism, mass: np.ndarray, jacobian: np.ndarray) -> None:
    """Raise :class:`IndeterminateAccelerations` unless the mass matrix (n, n) is positive
    definite on the null space of the Jacobian (m, n), by :data:`UNIQUENESS_RATIO`."""
    free = scipy.linalg.null_space(jacobian)
    if free.shape[1] == 0:
        return
    moments, motions = np.linalg.eigh(free.T @ mass @ free)
    if moments[0] > UNIQUENESS_RATIO * moments[-1]:
        return
    motion = (free @ motions[:, 0]).reshape(len(mech.bodies), -1)
    body = mech.bodies[int(np.argmax(np.linalg.norm(motion, axis=1)))].name
    spread = max(moments[0], 0.0) / moments[-1] if moments[-1] > 0.0 else 0.0
    raise IndeterminateAccelerations(
        f"mechanism {mech.name!r}: accelerations are not unique: the mass matrix is singular on "
        f"a motion the joints allow (eigenvalue ratio {spread:.2g} "
        f"≤ {UNIQUENESS_RATIO:g}), mostly of body {body!r} (a zero principal moment free to "
        f"turn about its axis?)")


def accelerations(mech: Mechanism, states: BodyStates, equations=None,
                  baumgarte: tuple[float, float] | None = None) -> Accelerations:
    """Body accelerations of ``mech`` at the consistent state ``states`` (index-1 KKT solve).

    Parameters
    ----------
    mech : Mechanism
    states : BodyStates
        Positions, orientations and velocities satisfying the joint equations (their velocity
        residuals are assumed zero; the driver is free, not prescribed).
    equations : optional
        The constraint rows: default ``JointEquations(mech)``; any object with its ``jacobian``
        and ``velocity_residuals`` (e.g. with a branch's rows, :mod:`mbh._harness.references.routes`).
    baumgarte : (α, β), optional
        Baumgarte's stabilisation, 1/s: the acceleration rows become G ν̇ = γ − 2α Φ̇ − β² Φ, so
        a state slightly off the constraints is pulled back instead of drifting (needs the
        equations' ``residuals``); default none (the state is assumed consistent).

    Returns
    -------
    Accelerations
        Planar mechanisms have zero z acceleration and zero x, y angular acceleration.

    Raises
    ------
    IndeterminateAccelerations
        If the accelerations are not unique (see the module docstring); the message names the
        body that moves most in the undetermined motion.
    """
    mass, rhs = twist_mass_and_forces(mech, states)
    equations = JointEquations(mech) if equations is None else equations
    jacobian = equations.jacobian(states.position, states.quaternion)
    _check_unique(mech, mass, jacobian)
    n, m = mass.shape[0], jacobian.shape[0]
    kkt = np.block([[mass, jacobian.T], [jacobian, np.zeros((m, m))]])
    rows = gamma(equations, states)
    if baumgarte is not None:
        alpha, beta = baumgarte
        rows = rows - 2.0 * alpha * equations.velocity_residuals(
            states.position, states.quaternion, states.velocity, states.angular_velocity) \
            - beta ** 2 * equations.residuals(states.position, states.quaternion)
    # Symmetric equilibration first: moments of 1e-7 kg·m² beside Jacobian entries of 1 leave the
    # raw system with condition 1e6 and ν̇ 4.7e-11 relative off (Andrews' start; 4e-13 scaled).
    size = np.abs(kkt).max(axis=1)
    scale = 1.0 / np.sqrt(np.where(size > 0.0, size, 1.0))
    solution = scale * scipy.linalg.lstsq(kkt * scale[:, None] * scale,
                                          np.concatenate([rhs, rows]) * scale,
                                          cond=KKT_RCOND, lapack_driver="gelsd")[0]
    twist_rates = body_twists(solution[:n], mech.planar)
    return Accelerations(twist_rates[:, :3], twist_rates[:, 3:])


def start_accelerations(times: np.ndarray, velocity: np.ndarray,
                        angular_velocity: np.ndarray) -> Accelerations:
    """Accelerations at the first of k ≥ 3 equally spaced samples, from their velocities.

    The one-sided difference of order k − 1, exact for velocities polynomial in t of degree
    k − 1: k = 3 gives a(0) ≈ (−3 v(0) + 4 v(T) − v(2T)) / (2T), error T²/3 times the third
    derivative of the velocity; k = 5 gives (−25 v(0) + 48 v(T) − 36 v(2T) + 16 v(3T) − 3 v(4T))
    / (12T), error T⁴/5 times the fifth derivative.

    Parameters
    ----------
    times : ndarray, shape (k,)
        0, T, 2T, ... (s).
    velocity, angular_velocity : ndarray, shape (k, n_bodies, 3)
        Sampled centre-of-mass velocities (m/s) and angular velocities (rad/s, world axes).

    Raises
    ------
    ValueError
        If ``times`` are not at least three equally spaced increasing samples.
    """
    times = np.asarray(times, dtype=float)
    count = len(times) if times.ndim == 1 else 0
    span = times[1] - times[0] if count >= 3 else 0.0
    if not (span > 0 and np.all(np.abs(np.diff(times) - span) <= 1e-9 * span)):
        raise ValueError(f"times must be at least three equally spaced increasing samples, "
                         f"got {times}")
    # Weights w with sum_j w_j j^p = [p == 1] for p = 0 .. k − 1 (Taylor expansion at t = 0).
    orders = np.arange(count, dtype=float)
    weights = np.linalg.solve(np.vander(orders, increasing=True).T,
                              np.eye(count)[1]) / span

    def rate(samples) -> np.ndarray:
        return np.tensordot(weights, np.asarray(samples, dtype=float), axes=1)

    return Accelerations(rate(velocity), rate(angular_velocity))
