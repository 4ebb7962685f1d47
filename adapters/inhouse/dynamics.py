"""Equations of motion in absolute coordinates (seed 002 ch. 3).

Planar: M = diag(m, m, I_zz) per body, no quadratic-velocity terms.
Spatial with Euler parameters: per body M = diag(m I₃, Ḡᵀ J̄ Ḡ) (002 eq. 55–61, Ḡ = 2Ē of eq. 28)
and Q_v = (0, −Ḡᵀ(ω̄ × J̄ ω̄)) with ω̄ = Ḡ θ̇ (eq. 62–63, using Ḡ̇ θ̇ = 0).  The rotational block is
singular along θ; the normalisation constraint θᵀθ = 1 completes the augmented system.

Generalised forces (002 eq. 64–71): a world force F at body point ū gives Q_R = F,
Q_θ = Ḡᵀ(ū × AᵀF); a world torque n gives Q_θ = Ḡᵀ Aᵀ n.  Planar: Q_φ = (Aū × F)_z, n_z.

The augmented system (002 eq. 76–77)

    [M   Φ_qᵀ] [q̈]   [Q_e + Q_v]
    [Φ_q  0  ] [λ] = [    γ    ]

is solved by LU factorisation, never by explicit inverses.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
from numba import njit

from adapters.inhouse.bodykin import PLANAR_NC, point, point_rate, rotate
from adapters.inhouse.constraints import layout_of
from harness.model import BodyForce, BodyTorque, JointActuation, Mechanism, SpringDamper


@njit(cache=True)
def g_bar(theta):
    """Ḡ = 2Ē of 002 eq. 28, shape (3, 4)."""
    t0, t1, t2, t3 = theta[0], theta[1], theta[2], theta[3]
    return 2.0 * np.array([[-t1, t0, t3, -t2],
                           [-t2, -t3, t0, t1],
                           [-t3, t2, -t1, t0]])


@njit(cache=True)
def _mass_and_inertial_forces(q, v, nc, masses, inertias, gravity):
    """M(q) (n, n) and Q_v + gravity (n,)."""
    n = q.shape[0]
    mass = np.zeros((n, n))
    force = np.zeros(n)
    for b in range(masses.shape[0]):
        k = b * nc
        m = masses[b]
        for a in range(3 if nc != PLANAR_NC else 2):
            mass[k + a, k + a] = m
            force[k + a] = m * gravity[a]
        if nc == PLANAR_NC:
            mass[k + 2, k + 2] = inertias[b, 2, 2]
            continue
        g = g_bar(q[k + 3:k + 7])
        mass[k + 3:k + 7, k + 3:k + 7] = g.T @ inertias[b] @ g
        omega = g @ v[k + 3:k + 7]
        force[k + 3:k + 7] = -(g.T @ np.cross(omega, inertias[b] @ omega))
    return mass, force


@njit(cache=True)
def _add_point_force(out, q, nc, body, u, f):
    """Add the generalised force of world force f at body point ū."""
    if body < 0:
        return
    k = body * nc
    arm = rotate(q, nc, body, u)
    if nc == PLANAR_NC:
        out[k] += f[0]
        out[k + 1] += f[1]
        out[k + 2] += arm[0] * f[1] - arm[1] * f[0]
        return
    out[k:k + 3] += f
    _add_torque(out, q, nc, body, np.cross(arm, f))


@njit(cache=True)
def _add_torque(out, q, nc, body, n):
    """Add the generalised force of world torque n on a body."""
    if body < 0:
        return
    k = body * nc
    if nc == PLANAR_NC:
        out[k + 2] += n[2]
        return
    # Ḡᵀ Aᵀ n: Aᵀ n is the torque in body axes.
    theta = q[k + 3:k + 7]
    local = np.zeros(3)
    for col in range(3):
        e = np.zeros(3)
        e[col] = 1.0
        local[col] = rotate(q, nc, body, e) @ n
    out[k + 3:k + 7] += g_bar(theta).T @ local


class Dynamics:
    """Mass matrix and applied forces of a mechanism in absolute coordinates.

    Parameters
    ----------
    mech : Mechanism
    """

    def __init__(self, mech: Mechanism):
        self.mech = mech
        self.layout = layout_of(mech)
        self.masses = mech.masses
        self.inertias = np.ascontiguousarray([b.inertia for b in mech.bodies])
        self.gravity = np.asarray(mech.gravity, dtype=float)
        self._forces = [self._compile_force(f) for f in mech.forces]

    def _compile_force(self, force):
        index = self.mech.body_index
        if isinstance(force, JointActuation):
            joint = self.mech.joint(force.joint)
            return ("actuation", index(joint.body1), index(joint.body2), joint, force.value)
        if isinstance(force, BodyForce):
            return ("point", index(force.body), force.point, np.asarray(force.force, float))
        if isinstance(force, BodyTorque):
            return ("torque", index(force.body), np.asarray(force.torque, float))
        if isinstance(force, SpringDamper):
            return ("spring", index(force.body1), index(force.body2), force)
        raise TypeError(f"unknown force {force!r}")

    def mass_and_forces(self, t: float, q: np.ndarray, v: np.ndarray):
        """M(q), shape (n, n), and Q_e + Q_v, shape (n,)  (t in s, unused by constant loads)."""
        nc = self.layout.nc
        mass, force = _mass_and_inertial_forces(q, v, nc, self.masses, self.inertias, self.gravity)
        for spec in self._forces:
            kind = spec[0]
            if kind == "actuation":
                self._add_actuation(force, q, spec)
            elif kind == "point":
                _add_point_force(force, q, nc, spec[1], spec[2], spec[3])
            elif kind == "torque":
                _add_torque(force, q, nc, spec[1], spec[2])
            else:
                self._add_spring(force, q, v, spec)
        return mass, force

    def _add_actuation(self, force, q, spec):
        _, i, j, joint, value = spec
        nc = self.layout.nc
        axis = rotate(q, nc, i, joint.axis1)
        if joint.type in ("revolute", "cylindrical"):
            _add_torque(force, q, nc, j, value * axis)
            _add_torque(force, q, nc, i, -value * axis)
        else:
            _add_point_force(force, q, nc, j, joint.point2, value * axis)
            _add_point_force(force, q, nc, i, joint.point1, -value * axis)

    def _add_spring(self, force, q, v, spec):
        _, i, j, spring = spec
        nc = self.layout.nc
        d = point(q, nc, j, spring.point2) - point(q, nc, i, spring.point1)
        length = np.linalg.norm(d)
        direction = d / length
        rate = direction @ (point_rate(q, v, nc, j, spring.point2) - point_rate(q, v, nc, i, spring.point1))
        tension = spring.stiffness * (length - spring.free_length) + spring.damping * rate
        _add_point_force(force, q, nc, i, spring.point1, tension * direction)
        _add_point_force(force, q, nc, j, spring.point2, -tension * direction)


def solve_augmented(mass: np.ndarray, jacobian: np.ndarray, force: np.ndarray, gamma: np.ndarray):
    """Solve the augmented system (002 eq. 77) by LU factorisation.

    Returns
    -------
    acceleration : ndarray, shape (n,)
    multipliers : ndarray, shape (m,)
    """
    n, m = mass.shape[0], jacobian.shape[0]
    matrix = np.zeros((n + m, n + m))
    matrix[:n, :n] = mass
    matrix[:n, n:] = jacobian.T
    matrix[n:, :n] = jacobian
    solution = scipy.linalg.solve(matrix, np.concatenate([force, gamma]), check_finite=False)
    return solution[:n], solution[n:]
