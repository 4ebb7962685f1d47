"""The Newton–Euler form for spatial mechanisms (Rouvinen 2003, §3.3, eq. 90–93).

Velocities are the centre-of-mass velocity Ṙ and the angular velocity in body axes ω̄, six per
body, so the mass matrix diag(m I, J̄) is constant and the quadratic-velocity term is the gyroscopic
−ω̄ × J̄ω̄.  Positions stay (R, θ); θ is advanced on the unit sphere by the quaternion exponential
θ ⊗ exp(Δπ̄ / 2) (:meth:`advance`), so the normalisation equation is not needed.  Rotations do not
commute, so the explicit methods step in the exponential chart around the current orientation
(:mod:`mbh._adapters.integrators.nystrom`, "Lie groups"): :meth:`increment_rate`,
:meth:`chart_velocity` and :meth:`chart_acceleration` are the chart's maps of
:mod:`mbh._adapters.integrators.so3` for the rotations and the identity for the translations.  The constraint
Jacobian with respect to (Ṙ, ω̄) is Φ_q T with θ̇ = ¼ Ḡᵀ ω̄ (Ḡ of Rouvinen 2003, eq. 28), and the
acceleration right-hand side gains −Φ_θ ¼ Ḡ(θ̇)ᵀ ω̄ from differentiating that map.  Drift is held by
Baumgarte terms (α, β; α = β = 0 gives the plain form).

Only explicit one-step integrators can advance θ on its manifold; the others are refused.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from mbh._adapters.inhouse.formulations.dynamics import solve_augmented
from mbh._adapters.inhouse.formulations.mass_and_forces import g_bar
from mbh._adapters.inhouse.formulations.stabilisation import Formulation
from mbh._adapters.integrators import so3


class NewtonEuler(Formulation):
    name = "newton-euler"
    description = ("Newton–Euler form (Rouvinen 2003, §3.3): velocities (Ṙ, ω̄) per body, constant mass matrix, "
                   "θ advanced by the quaternion exponential; Baumgarte α, β (spatial only; explicit "
                   "one-step integrators)")
    defaults = {"alpha": 5.0, "beta": 5.0}

    @classmethod
    def unsupported_reason(cls, mech, integrator_class):
        if mech.planar:
            return ("the Newton–Euler form applies to spatial mechanisms; planar absolute "
                    "coordinates already have a constant mass matrix")
        if integrator_class.euclidean_only:
            return (f"{integrator_class.name} combines positions linearly; the Newton–Euler form "
                    "needs an explicit one-step integrator (euler, symplectic-euler, heun, rk4, "
                    "rkn4) to advance θ on its manifold")
        return None

    def __init__(self, mech, q0, dt, **params):
        super().__init__(mech, q0, dt, **params)
        nb = len(mech.bodies)
        self.rows = self.rows[self.rows < self.constraints.n_joint_equations]
        self.n = 6 * nb
        self._mass = np.zeros((self.n, self.n))
        for b, body in enumerate(mech.bodies):
            self._mass[6 * b:6 * b + 3, 6 * b:6 * b + 3] = body.mass * np.eye(3)
            self._mass[6 * b + 3:6 * b + 6, 6 * b + 3:6 * b + 6] = body.inertia
        self._gravity = np.concatenate([np.concatenate([b.mass * mech.gravity, np.zeros(3)])
                                        for b in mech.bodies])

    # -- maps between (Ṙ, θ̇) and (Ṙ, ω̄) ---------------------------------------------------------
    def _blocks(self, x, width):
        return x.reshape(-1, width)

    def velocity_map(self, q):
        """T(q), shape (7 nb, 6 nb): q̇ = T v with θ̇ = ¼ Ḡᵀ ω̄."""
        nb = self.n // 6
        t = np.zeros((7 * nb, 6 * nb))
        for b, block in enumerate(self._blocks(q, 7)):
            t[7 * b:7 * b + 3, 6 * b:6 * b + 3] = np.eye(3)
            t[7 * b + 3:7 * b + 7, 6 * b + 3:6 * b + 6] = 0.25 * g_bar(block[3:]).T
        return t

    def reduce(self, q, qdot):
        v = [np.concatenate([qd[:3], g_bar(qq[3:]) @ qd[3:]])
             for qq, qd in zip(self._blocks(q, 7), self._blocks(qdot, 7))]
        return q, np.concatenate(v)

    def expand(self, t, q, v):
        return q, self.velocity_map(q) @ v

    def advance(self, q, dq):
        """R + ΔR and θ ⊗ exp(Δπ̄/2) per body (Δπ̄ a body-axes rotation vector)."""
        out = q.reshape(-1, 7).copy()
        for block, step in zip(out, self._blocks(dq, 6)):
            block[:3] += step[:3]
            rotation = Rotation.from_quat(block[3:], scalar_first=True) * Rotation.from_rotvec(step[3:])
            block[3:] = rotation.as_quat(scalar_first=True, canonical=False)
        return out.ravel()

    # -- the exponential chart of each body's rotation (Lie-group stepping) -------------------
    def _chart(self, function, dq, *rates):
        """Apply an :mod:`~mbh._adapters.integrators.so3` map to the rotation rows, identity elsewhere."""
        out = np.array(rates[-1], dtype=float).reshape(-1, 6)
        rotation = self._blocks(dq, 6)[:, 3:]
        out[:, 3:] = function(rotation, *(self._blocks(r, 6)[:, 3:] for r in rates))
        return out.ravel()

    def increment_rate(self, q, dq, v):
        """dexp⁻¹: (Ṙ, J(Δπ̄)⁻¹ ω̄) per body, shape (6 nb,)."""
        return self._chart(so3.chart_rate, dq, v)

    def chart_velocity(self, q, dq, w):
        """dexp: (Ṙ, J(Δπ̄) w) per body, shape (6 nb,)."""
        return self._chart(so3.angular_velocity, dq, w)

    def chart_acceleration(self, q, dq, w, a):
        """Second derivative of the increment: (R̈, J⁻¹(ω̄̇ − J̇ w)) per body, shape (6 nb,)."""
        return self._chart(so3.chart_acceleration, dq, w, a)

    # -- the equations of motion (eq. 90–93) -------------------------------------------------
    def acceleration(self, t, q, v):
        q, v = np.ascontiguousarray(q), np.ascontiguousarray(v)
        velocity_map = self.velocity_map(q)
        qdot = velocity_map @ v
        jac_q = self.jacobian(t, q)
        jac = jac_q @ velocity_map
        force = self._gravity + velocity_map.T @ self.dynamics.applied_forces(q, qdot)
        for b, block in enumerate(self._blocks(v, 6)):
            omega = block[3:]
            force[6 * b + 3:6 * b + 6] -= np.cross(omega, self.mech.bodies[b].inertia @ omega)
        # d/dt of the map: θ̈ = ¼ Ḡᵀ ω̄̇ + ¼ Ḡ(θ̇)ᵀ ω̄
        map_rate = np.zeros_like(qdot)
        for b, (qd, block) in enumerate(zip(self._blocks(qdot, 7), self._blocks(v, 6))):
            map_rate[7 * b + 3:7 * b + 7] = 0.25 * g_bar(qd[3:]).T @ block[3:]
        alpha, beta = self.params["alpha"], self.params["beta"]
        gamma = (self.gamma(t, q, qdot) - jac_q @ map_rate
                 - 2.0 * alpha * (jac @ v) - beta ** 2 * self.phi(t, q))
        self.counters["factorizations"] += 1
        return solve_augmented(self._mass, jac, force, gamma)[0]
