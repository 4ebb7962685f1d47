"""Compiled (numba) right-hand sides of the neutral reference routes (:mod:`mbh._harness.references.routes`).

The same equations as :mod:`mbh._harness.neutral.dynamics` (mass matrix, applied wrenches, γ by the
sixth-order central difference, the uniqueness check, the equilibrated KKT least-squares solve)
and :func:`mbh._harness.neutral.assembly.newton_positions` (the reduced route's poses), for one state, on the
compiled joint equations of :mod:`mbh._harness.neutral.equation_kernels`.  Only the order of the floating-point
operations differs (the KKT system by its symmetric eigendecomposition instead of gelsd's SVD,
the same cut-off); ``tests/neutral/test_reference_speed.py`` checks them against the numpy
originals and the stored references.  Nothing here imports the in-house formulation
(docs/design.md, Layers).

Load table (:class:`BodyTable`): ``kind`` (L,) one of the ``_LOAD_*`` codes, ``bodies`` (L, 2),
``vectors`` (L, 3, 3), ``scalars`` (L, 3) (see :func:`_add_loads`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mbh._harness.neutral.equation_kernels import (combined_rows, compiled, cross, dot, jacobian,
                                                   jacobian_of, residuals, rotations, row_gradients,
                                                   row_rates, velocity_residuals, world_vector,
                                                   wrap)
from mbh._harness.model.mechanism import (BodyForce, BodyTorque, JointActuation, Mechanism,
                                          SpringDamper)

_LOAD_FORCE, _LOAD_TORQUE, _LOAD_AXIS_TORQUE, _LOAD_AXIS_FORCE, _LOAD_SPRING = 0, 1, 2, 3, 4
_TORQUE_JOINTS = ("revolute", "cylindrical")


@dataclass(frozen=True)
class BodyTable:
    """Masses (n_b,), kg, body-frame inertias (n_b, 3, 3), kg·m², gravity (3,), m/s², and the
    load table (module docstring)."""

    masses: np.ndarray
    inertia: np.ndarray
    gravity: np.ndarray
    load_kind: np.ndarray
    load_bodies: np.ndarray
    load_vectors: np.ndarray
    load_scalars: np.ndarray

    def arrays(self) -> tuple:
        """The arrays in the order the kernels take them."""
        return (self.masses, self.inertia, self.gravity, self.load_kind, self.load_bodies,
                self.load_vectors, self.load_scalars)


def body_table(mech: Mechanism) -> BodyTable:
    """Masses, inertias, gravity and the loads of ``mech`` as a :class:`BodyTable`."""
    entries = []  # (kind, body1, body2, vectors, scalars)
    zero = np.zeros(3)
    for load in mech.forces:
        if isinstance(load, BodyForce):
            entries.append((_LOAD_FORCE, mech.body_index(load.body), -1,
                            (load.force, load.point, zero), (0.0, 0.0, 0.0)))
        elif isinstance(load, BodyTorque):
            entries.append((_LOAD_TORQUE, mech.body_index(load.body), -1,
                            (load.torque, zero, zero), (0.0, 0.0, 0.0)))
        elif isinstance(load, JointActuation):
            joint = mech.joint(load.joint)
            kind = _LOAD_AXIS_TORQUE if joint.type in _TORQUE_JOINTS else _LOAD_AXIS_FORCE
            for name, point, axis, value in ((joint.body2, joint.point2, joint.axis2, load.value),
                                             (joint.body1, joint.point1, joint.axis1, -load.value)):
                entries.append((kind, mech.body_index(name), -1, (axis, point, zero),
                                (value, 0.0, 0.0)))
        elif isinstance(load, SpringDamper):
            entries.append((_LOAD_SPRING, mech.body_index(load.body1), mech.body_index(load.body2),
                            (load.point1, load.point2, zero),
                            (load.stiffness, load.damping, load.free_length)))
        else:
            raise TypeError(f"load {load!r}: unknown load type {type(load).__name__}")
    count = len(entries)
    return BodyTable(
        np.asarray(mech.masses, dtype=float),
        np.array([body.inertia for body in mech.bodies], dtype=float),
        np.asarray(mech.gravity, dtype=float),
        np.array([e[0] for e in entries], dtype=np.int64),
        np.array([(e[1], e[2]) for e in entries], dtype=np.int64).reshape(count, 2),
        np.array([np.array(e[3], dtype=float) for e in entries]).reshape(count, 3, 3),
        np.array([e[4] for e in entries], dtype=float).reshape(count, 3))


def mass_spread(mech: Mechanism) -> float:
    """Smallest over largest eigenvalue of the twist mass matrix, the same in every pose: the
    masses and principal moments (spatial) or moments about z (planar).  The eigenvalues of
    Zᵀ M Z for orthonormal Z lie between M's (Cauchy's interlacing), so a spread above
    :data:`~mbh._harness.neutral.dynamics.UNIQUENESS_RATIO` makes every null space pass
    :func:`is_unique`."""
    inertia = np.array([body.inertia for body in mech.bodies], dtype=float)
    moments = inertia[:, 2, 2] if mech.planar else np.linalg.eigvalsh(inertia).ravel()
    values = np.concatenate([np.asarray(mech.masses, dtype=float), moments])
    return float(values.min() / values.max())


# -- dynamics -----------------------------------------------------------------------------------
@compiled
def _point(position, velocity, angular_velocity, rotation, body, local):
    """World arm, position and velocity of a body point (ground: the world point at rest)."""
    if body < 0:
        return np.zeros(3), local.copy(), np.zeros(3)
    arm = rotation[body] @ local
    return arm, position[body] + arm, velocity[body] + cross(angular_velocity[body], arm)


@compiled
def _push(wrench, body, force, arm):
    if body >= 0:
        wrench[body, 0] += force
        wrench[body, 1] += cross(arm, force)


@compiled
def _add_loads(wrench, load_kind, load_bodies, load_vectors, load_scalars, position, velocity,
               angular_velocity, rotation):
    """Add every load to ``wrench`` (n_b, 2, 3): force at a point (vectors: force, point),
    torque (torque), actuation torque (value·axis) or force (value·axis at point), spring-damper
    (points 1, 2; scalars k, c, L₀), as :func:`mbh._harness.neutral.dynamics.applied_wrenches`."""
    for index in range(load_kind.shape[0]):
        kind = load_kind[index]
        one, two = load_bodies[index, 0], load_bodies[index, 1]
        if kind == _LOAD_FORCE:
            arm = _point(position, velocity, angular_velocity, rotation, one,
                         load_vectors[index, 1])[0]
            _push(wrench, one, load_vectors[index, 0].copy(), arm)
        elif kind == _LOAD_TORQUE:
            if one >= 0:
                wrench[one, 1] += load_vectors[index, 0]
        elif kind == _LOAD_AXIS_TORQUE:
            if one >= 0:
                wrench[one, 1] += load_scalars[index, 0] * (rotation[one] @ load_vectors[index, 0])
        elif kind == _LOAD_AXIS_FORCE:
            axis = world_vector(rotation, one, load_vectors[index, 0])
            arm = _point(position, velocity, angular_velocity, rotation, one,
                         load_vectors[index, 1])[0]
            _push(wrench, one, load_scalars[index, 0] * axis, arm)
        else:
            arm1, at1, velocity1 = _point(position, velocity, angular_velocity, rotation, one,
                                          load_vectors[index, 0])
            arm2, at2, velocity2 = _point(position, velocity, angular_velocity, rotation, two,
                                          load_vectors[index, 1])
            span = at2 - at1
            length = np.sqrt(dot(span, span))
            direction = span / length
            tension = (load_scalars[index, 0] * (length - load_scalars[index, 2])
                       + load_scalars[index, 1] * dot(direction, velocity2 - velocity1))
            _push(wrench, one, tension * direction, arm1)
            _push(wrench, two, -tension * direction, arm2)


@compiled
def mass_and_forces(masses, inertia, gravity, load_kind, load_bodies, load_vectors,
                    load_scalars, planar, position, quaternion, velocity, angular_velocity):
    """Mass matrix (n, n) and Q − [0; ω × J ω] (n,) in the twist coordinates, as
    :func:`mbh._harness.neutral.dynamics.twist_mass_and_forces`."""
    n_bodies = position.shape[0]
    rotation = rotations(quaternion)
    wrench = np.zeros((n_bodies, 2, 3))
    for b in range(n_bodies):
        wrench[b, 0] += masses[b] * gravity
    _add_loads(wrench, load_kind, load_bodies, load_vectors, load_scalars, position, velocity,
               angular_velocity, rotation)
    size = 3 if planar else 6
    mass = np.zeros((size * n_bodies, size * n_bodies))
    forces = np.zeros(size * n_bodies)
    for b in range(n_bodies):
        world = rotation[b] @ inertia[b] @ rotation[b].T
        omega = angular_velocity[b].copy()
        torque = wrench[b, 1] - cross(omega, world @ omega)
        start = size * b
        if planar:
            mass[start, start] = masses[b]
            mass[start + 1, start + 1] = masses[b]
            mass[start + 2, start + 2] = world[2, 2]
            forces[start:start + 2] = wrench[b, 0, :2]
            forces[start + 2] = torque[2]
        else:
            for k in range(3):
                mass[start + k, start + k] = masses[b]
            mass[start + 3:start + 6, start + 3:start + 6] = world
            forces[start:start + 3] = wrench[b, 0]
            forces[start + 3:start + 6] = torque
    return mass, forces


@compiled
def _turned(quaternion, angular_velocity, h):
    """Quaternions (n_b, 4) turned by the world rotation vector h·ω (scipy's from_rotvec,
    composed on the left)."""
    out = np.empty_like(quaternion)
    for b in range(quaternion.shape[0]):
        vector = h * angular_velocity[b]
        angle = np.sqrt(dot(vector, vector))
        if angle <= 1e-3:
            scale = 0.5 - angle ** 2 / 48.0 + angle ** 4 / 3840.0
        else:
            scale = np.sin(angle / 2.0) / angle
        w, x, y, z = np.cos(angle / 2.0), scale * vector[0], scale * vector[1], scale * vector[2]
        qw, qx, qy, qz = quaternion[b, 0], quaternion[b, 1], quaternion[b, 2], quaternion[b, 3]
        out[b, 0] = w * qw - x * qx - y * qy - z * qz
        out[b, 1] = w * qx + x * qw + y * qz - z * qy
        out[b, 2] = w * qy - x * qz + y * qw + z * qx
        out[b, 3] = w * qz + x * qy - y * qx + z * qw
    return out


@compiled
def gamma(kind, bodies, vectors, rate, combine, position, quaternion, velocity,
          angular_velocity, difference_step, difference_turn):
    """γ = −Ġ ν (m_out,): the sixth-order central difference of the velocity residuals along
    the motion, as :func:`mbh._harness.neutral.dynamics.gamma`."""
    fastest = np.abs(angular_velocity).max() if angular_velocity.size else 0.0
    step = min(difference_step, difference_turn / fastest) if fastest > 0.0 else difference_step
    total = np.zeros(combine.shape[0])
    weights = (45.0, -9.0, 1.0)
    for k in range(1, 4):
        ahead = velocity_residuals(kind, bodies, vectors, rate, combine,
                                   position + k * step * velocity,
                                   _turned(quaternion, angular_velocity, k * step),
                                   velocity, angular_velocity)
        behind = velocity_residuals(kind, bodies, vectors, rate, combine,
                                    position - k * step * velocity,
                                    _turned(quaternion, angular_velocity, -k * step),
                                    velocity, angular_velocity)
        total += weights[k - 1] * (ahead - behind)
    return -total / (60.0 * step)


@compiled
def _decomposition_rank(s, rcond):
    """How many singular values (descending) exceed rcond × the largest."""
    rank = 0
    for value in s:
        if value > rcond * s[0]:
            rank += 1
    return rank


@compiled
def _decomposition(jacobian, rcond):
    """SVD of the Jacobian (m, n): u (m, m), s, vh (n, n), and the rank counting the singular
    values above rcond × the largest."""
    m, n = jacobian.shape
    if m == 0:
        return np.zeros((0, 0)), np.zeros(0), np.eye(n), 0
    u, s, vh = np.linalg.svd(jacobian)
    return u, s, vh, _decomposition_rank(s, rcond)


@compiled
def _pseudo_solve(u, s, vh, rank, rhs):
    """The least-squares solution of least norm with the singular values beyond ``rank``
    dropped (what LAPACK's gelsd returns with the same cut-off), shape (n,)."""
    columns = np.ascontiguousarray(u.T)
    solution = np.zeros(vh.shape[1])
    for k in range(rank):
        solution += (columns[k] @ rhs / s[k]) * vh[k]
    return solution


@compiled
def is_unique(mass, jacobian, ratio):
    """Whether the mass matrix (n, n) is positive definite on the null space of the Jacobian
    (m, n) by the eigenvalue ratio ``ratio``, the null space cut at scipy.linalg.null_space's
    default (max(m, n)·ε × the largest singular value), as
    :func:`mbh._harness.neutral.dynamics._check_unique`."""
    m, n = jacobian.shape
    _, s, vh, rank = _decomposition(jacobian, max(m, n) * np.finfo(np.float64).eps)
    if rank == n:
        return True
    free = np.ascontiguousarray(vh[rank:].T)
    moments = np.linalg.eigvalsh(free.T @ mass @ free)
    return moments[0] > ratio * moments[-1]


@compiled
def kkt_solve(mass, jacobian, forces, rows, rcond):
    """Twist rates (n,) from the symmetrically equilibrated KKT system [[M, Gᵀ], [G, 0]] by
    least squares (singular values below rcond × the largest dropped), as
    :func:`mbh._harness.neutral.dynamics.accelerations`.

    The system is symmetric, so its singular values are the moduli of its eigenvalues: the
    least-norm solution V Λ⁺ Vᵀ b from the symmetric eigendecomposition is the one LAPACK's
    gelsd returns from the SVD with the same cut-off, and cheaper (figures: docs/measurements.md,
    section "Neutral dynamics").
    """
    n, m = mass.shape[0], jacobian.shape[0]
    kkt = np.zeros((n + m, n + m))
    kkt[:n, :n] = mass
    kkt[:n, n:] = jacobian.T
    kkt[n:, :n] = jacobian
    scale = np.empty(n + m)
    for i in range(n + m):
        size = np.abs(kkt[i]).max()
        scale[i] = 1.0 / np.sqrt(size if size > 0.0 else 1.0)
    scaled = kkt * scale.reshape(-1, 1) * scale.reshape(1, -1)
    moments, vectors = np.linalg.eigh(scaled)
    cutoff = rcond * np.abs(moments).max()
    coefficients = vectors.T @ (np.concatenate((forces, rows)) * scale)
    for k in range(n + m):
        coefficients[k] = coefficients[k] / moments[k] if abs(moments[k]) > cutoff else 0.0
    return (scale * (vectors @ coefficients))[:n]


@compiled
def expand_twist(twist, planar):
    """Linear and angular velocities (n_b, 3) each from a twist vector over the columns."""
    size = 3 if planar else 6
    n_bodies = twist.shape[0] // size
    linear = np.zeros((n_bodies, 3))
    angular = np.zeros((n_bodies, 3))
    for b in range(n_bodies):
        if planar:
            linear[b, 0] = twist[3 * b]
            linear[b, 1] = twist[3 * b + 1]
            angular[b, 2] = twist[3 * b + 2]
        else:
            linear[b] = twist[6 * b:6 * b + 3]
            angular[b] = twist[6 * b + 3:6 * b + 6]
    return linear, angular


@compiled
def quaternion_rates(quaternion, angular_velocity):
    """q̇ = ½ [0, ω] ⊗ q for world angular velocities, shape (n_b, 4)."""
    out = np.empty_like(quaternion)
    for b in range(quaternion.shape[0]):
        w, v, omega = quaternion[b, 0], quaternion[b, 1:], angular_velocity[b]
        out[b, 0] = -0.5 * dot(omega, v)
        out[b, 1:] = 0.5 * (w * omega + cross(omega, v))
    return out


@compiled
def full_rates(y, kind, bodies, vectors, offset, rate, wrapped, combine, shift, wrap_out,
               masses, inertia, gravity, load_kind, load_bodies, load_vectors, load_scalars,
               planar, alpha, beta, difference_step, difference_turn, rcond, ratio, spread):
    """ẏ of the full route's state y = [positions (3 n_b), quaternions (4 n_b), twist] (index-1
    Newton–Euler with Baumgarte's (α, β), 1/s), and False instead when the accelerations are
    not unique (ẏ then undefined).  ``spread`` is :func:`mass_spread`: when it exceeds
    ``ratio`` the accelerations are unique everywhere and the check's SVD is skipped."""
    n_bodies = masses.shape[0]
    position = y[:3 * n_bodies].copy().reshape(n_bodies, 3)
    quaternion = y[3 * n_bodies:7 * n_bodies].copy().reshape(n_bodies, 4)
    for b in range(n_bodies):
        quaternion[b] /= np.sqrt(dot(quaternion[b, 1:], quaternion[b, 1:])
                                 + quaternion[b, 0] ** 2)
    velocity, angular_velocity = expand_twist(y[7 * n_bodies:], planar)
    mass, forces = mass_and_forces(masses, inertia, gravity, load_kind, load_bodies,
                                   load_vectors, load_scalars, planar, position, quaternion,
                                   velocity, angular_velocity)
    rotation = rotations(quaternion)
    raw, g1, g2 = row_gradients(kind, bodies, vectors, position, rotation)
    matrix = jacobian_of(bodies, g1, g2, combine, planar, n_bodies)
    if spread <= ratio and not is_unique(mass, matrix, ratio):
        return np.zeros(y.shape[0]), False
    rows = gamma(kind, bodies, vectors, rate, combine, position, quaternion, velocity,
                 angular_velocity, difference_step, difference_turn)
    drift = row_rates(bodies, rate, g1, g2, combine, velocity, angular_velocity)
    values = raw - offset
    for r in range(values.shape[0]):
        if wrapped[r]:
            values[r] = wrap(values[r])
    rows = rows - 2.0 * alpha * drift - beta ** 2 * combined_rows(values, combine, shift, wrap_out)
    rates = np.empty(y.shape[0])
    rates[:3 * n_bodies] = velocity.ravel()
    rates[3 * n_bodies:7 * n_bodies] = quaternion_rates(quaternion, angular_velocity).ravel()
    rates[7 * n_bodies:] = kkt_solve(mass, matrix, forces, rows, rcond)
    return rates, True


@compiled
def branch_acceleration(kind, bodies, vectors, rate, combine, masses, inertia, gravity,
                        load_kind, load_bodies, load_vectors, load_scalars, planar, position,
                        quaternion, theta_rate, difference_step, difference_turn, rcond):
    """θ̈ = ν'ᵀ (Q − M a₀ θ̇²) / (ν'ᵀ M ν') of the reduced route at a pose on the branch
    (rad/s² or m/s²); ν' solves G ν' = e_θ, a₀ solves G a₀ = γ(ν') (least squares)."""
    u, s, vh, rank = _decomposition(jacobian(kind, bodies, vectors, combine, planar, position,
                                             quaternion), rcond)
    unit = np.zeros(combine.shape[0])
    unit[-1] = 1.0
    per_rate = _pseudo_solve(u, s, vh, rank, unit)
    velocity, angular_velocity = expand_twist(per_rate, planar)
    drift = _pseudo_solve(u, s, vh, rank, gamma(kind, bodies, vectors, rate, combine, position,
                                                quaternion, velocity, angular_velocity,
                                                difference_step, difference_turn))
    mass, forces = mass_and_forces(masses, inertia, gravity, load_kind, load_bodies,
                                   load_vectors, load_scalars, planar, position, quaternion,
                                   velocity * theta_rate, angular_velocity * theta_rate)
    return (per_rate @ (forces - mass @ drift * theta_rate ** 2)) / (per_rate @ mass @ per_rate)


@compiled
def branch_rate(kind, bodies, vectors, combine, planar, position, quaternion, rcond):
    """ν', the twist per unit rate of the last row (G ν' = e_θ, least squares), shape (n,)."""
    u, s, vh, rank = _decomposition(jacobian(kind, bodies, vectors, combine, planar, position,
                                             quaternion), rcond)
    unit = np.zeros(combine.shape[0])
    unit[-1] = 1.0
    return _pseudo_solve(u, s, vh, rank, unit)



@compiled
def branch_pose(kind, bodies, vectors, offset, rate, wrapped, combine, shift, wrap_out, planar,
                position, quaternion, tolerance, max_iterations, polish_steps):
    """Newton–Raphson on the body poses with least-squares steps in body twists, as
    :func:`mbh._harness.neutral.assembly.newton_positions` (same iteration, stopping rule and polishing
    steps; scipy's default cut-off ε of lstsq).

    Parameters
    ----------
    position : ndarray, shape (n_b, 3)
        First iterate, m.
    quaternion : ndarray, shape (n_b, 4)
        First iterate, scalar first.
    tolerance : float
        max |row| (m or rad) of convergence.

    Returns
    -------
    (position, quaternion, residual, converged) at the best iterate.
    """
    best_position, best_quaternion, best = position, quaternion, np.inf
    converged_at = -1
    for iteration in range(max_iterations + polish_steps + 1):
        rows = residuals(kind, bodies, vectors, offset, rate, wrapped, combine, shift, wrap_out,
                         position, quaternion, 0.0)
        size = np.abs(rows).max() if rows.size else 0.0
        if not np.isfinite(size):
            break
        if size < best:
            best_position, best_quaternion, best = position, quaternion, size
        if converged_at < 0 and size <= tolerance:
            converged_at = iteration
        polished = converged_at >= 0 and iteration >= converged_at + polish_steps
        if size == 0.0 or polished or (converged_at < 0 and iteration >= max_iterations):
            break
        u, s, vh, rank = _decomposition(jacobian(kind, bodies, vectors, combine, planar,
                                                 position, quaternion),
                                        np.finfo(np.float64).eps)
        velocity, turn = expand_twist(_pseudo_solve(u, s, vh, rank, -rows), planar)
        position = position + velocity
        quaternion = _turned(quaternion, turn, 1.0)
        for b in range(quaternion.shape[0]):
            quaternion[b] /= np.sqrt(dot(quaternion[b, 1:], quaternion[b, 1:])
                                     + quaternion[b, 0] ** 2)
    return best_position, best_quaternion, best, converged_at >= 0
