"""A third-party adapter for the mbh harness: planar mechanisms of revolute joints, integrated in
absolute coordinates (x, y, φ per body) on the index-1 equations of motion with Baumgarte
stabilisation and fixed-step RK4.

Written against docs/adapter-contract.md only: it subclasses ``mbh._adapters.base.Adapter`` and
``mbh._adapters.base.Stepper``, reads the neutral ``Mechanism``, starts from the harness's assembled
state (``mbh._harness.neutral.start.initial_state``) and returns ``BodyStates``.  Registered by the
entry point ``toy = "mbh_toy_adapter:ToyAdapter"`` in the group ``mbh.adapters``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mbh._adapters.base import Adapter, MethodSpec, RunFailure, Stepper, UnsupportedCase
from mbh._harness.model.mechanism import (GROUND, BodyForce, BodyTorque, JointActuation, Mechanism)
from mbh._harness.model.trajectory import BodyStates
from mbh._harness.neutral.start import initial_state

__version__ = "0.1.0"

#: d R(φ) / dφ = R(φ) @ _TURN for the planar rotation R(φ).
_TURN = np.array([[0.0, -1.0], [1.0, 0.0]])


def _rotation(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s], [s, c]])


@dataclass(frozen=True)
class ToyModel:
    """The engine model: the mechanism (the contract's ``model.mechanism``), the mass matrix
    (3n × 3n, kg and kg·m²), the applied generalized forces (3n,: N and N·m) and the joint ends
    [(body index or -1 for ground, point (2,) in that body's frame, m, sign ±1)] per joint."""

    mechanism: Mechanism
    mass: np.ndarray
    applied: np.ndarray
    ends: tuple[tuple[tuple[int, np.ndarray, float], ...], ...]


class ToyAdapter(Adapter):
    """Planar revolute mechanisms: RK4 on M q̈ + Cqᵀ λ = Q, Cq q̈ = γ − 2α Ċ − α² C."""

    name = "toy"

    def version(self) -> str:
        return f"toy {__version__}"

    def methods(self) -> list[MethodSpec]:
        return [
            MethodSpec("default", "RK4, Baumgarte stabilisation at alpha = 10 1/s",
                       {"alpha": 10.0}),
            MethodSpec("best", "RK4, Baumgarte stabilisation at alpha = 50 1/s",
                       {"alpha": 50.0}),
        ]

    def build(self, mechanism: Mechanism) -> ToyModel:
        if mechanism.kind != "planar":
            raise UnsupportedCase("the toy adapter models planar mechanisms only")
        for joint in mechanism.joints:
            if joint.type != "revolute":
                raise UnsupportedCase(f"joint {joint.name}: the toy adapter has revolute joints "
                                      f"only, not {joint.type}")
        n = len(mechanism.bodies)
        inertia = [body.inertia[2, 2] for body in mechanism.bodies]
        mass = np.diag(np.ravel([[body.mass, body.mass, izz]
                                 for body, izz in zip(mechanism.bodies, inertia)]))
        applied = np.zeros(3 * n)
        for i, body in enumerate(mechanism.bodies):
            applied[3 * i:3 * i + 2] += body.mass * mechanism.gravity[:2]
        for force in mechanism.forces:
            self._add_force(mechanism, force, applied)
        ends = tuple(((mechanism.body_index(j.body1), j.point1[:2], 1.0),
                      (mechanism.body_index(j.body2), j.point2[:2], -1.0))
                     for j in mechanism.joints)
        return ToyModel(mechanism, mass, applied, ends)

    @staticmethod
    def _add_force(mechanism: Mechanism, force, applied: np.ndarray) -> None:
        """Add a constant load to the generalized forces: a joint torque, a body torque, or a
        force at the centre of mass; anything else is refused."""
        if isinstance(force, JointActuation):
            joint = mechanism.joint(force.joint)
            for body, sign in ((joint.body2, 1.0), (joint.body1, -1.0)):
                if body != GROUND:
                    applied[3 * mechanism.body_index(body) + 2] += sign * force.value
        elif isinstance(force, BodyTorque):
            applied[3 * mechanism.body_index(force.body) + 2] += force.torque[2]
        elif isinstance(force, BodyForce) and not np.any(force.point):
            index = mechanism.body_index(force.body)
            applied[3 * index:3 * index + 2] += force.force[:2]
        else:
            raise UnsupportedCase(f"the toy adapter has no {type(force).__name__} of this kind")

    def model_size(self, model: ToyModel) -> dict:
        rows = 2 * len(model.ends)
        q, _ = _start_coordinates(model.mechanism)
        rank = np.linalg.matrix_rank(_jacobian(model, q)) if rows else 0
        return {"coordinates": 3 * len(model.mechanism.bodies), "constraint_equations": rows,
                "redundant_equations": rows - int(rank),
                "notes": "absolute coordinates (x, y, phi) per body; two rows per revolute joint"}

    def _start(self, model: ToyModel, spec: MethodSpec, params: dict, grid) -> Stepper:
        return ToyStepper(model, params["alpha"], grid.dt)


def _start_coordinates(mechanism: Mechanism) -> tuple[np.ndarray, np.ndarray]:
    """(q, v) of the harness's assembled start: (x, y, φ) and their rates per body."""
    start = initial_state(mechanism)
    if np.abs(start.quaternion[:, 1:3]).max(initial=0.0) > 1e-12:
        raise UnsupportedCase("a body frame is tilted out of the x-y plane")
    angle = 2.0 * np.arctan2(start.quaternion[:, 3], start.quaternion[:, 0])
    q = np.column_stack([start.position[:, :2], angle]).ravel()
    v = np.column_stack([start.velocity[:, :2], start.angular_velocity[:, 2]]).ravel()
    return q, v


def _jacobian(model: ToyModel, q: np.ndarray) -> np.ndarray:
    """Cq, (2 m, 3 n): rows of each joint's point gap p1 − p2 (m)."""
    jac = np.zeros((2 * len(model.ends), q.size))
    for row, ends in enumerate(model.ends):
        for body, point, sign in ends:
            if body >= 0:
                jac[2 * row:2 * row + 2, 3 * body:3 * body + 2] = sign * np.eye(2)
                turned = _rotation(q[3 * body + 2]) @ _TURN @ point
                jac[2 * row:2 * row + 2, 3 * body + 2] = sign * turned
    return jac


def _gap_and_curvature(model: ToyModel, q: np.ndarray, v: np.ndarray):
    """(C, the joints' point gaps (2 m,), m; γ = −(Cq v)_q v (2 m,), m/s²)."""
    gap, curvature = np.zeros(2 * len(model.ends)), np.zeros(2 * len(model.ends))
    for row, ends in enumerate(model.ends):
        for body, point, sign in ends:
            if body < 0:
                gap[2 * row:2 * row + 2] += sign * point
                continue
            turned = _rotation(q[3 * body + 2]) @ point
            gap[2 * row:2 * row + 2] += sign * (q[3 * body:3 * body + 2] + turned)
            curvature[2 * row:2 * row + 2] += sign * v[3 * body + 2] ** 2 * turned
    return gap, curvature


class ToyStepper(Stepper):
    """Fixed-step RK4 on (q, v) from the assembled start."""

    def __init__(self, model: ToyModel, alpha: float, dt: float):
        super().__init__()
        self.model, self.alpha, self.dt = model, alpha, dt
        self.q, self.v = _start_coordinates(model.mechanism)
        self.z = initial_state(model.mechanism).position[:, 2]
        self.t = 0.0
        self.evaluations = 0

    def _acceleration(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        jac = _jacobian(self.model, q)
        gap, curvature = _gap_and_curvature(self.model, q, v)
        rhs = curvature - 2.0 * self.alpha * (jac @ v) - self.alpha ** 2 * gap
        n, m = q.size, gap.size
        kkt = np.block([[self.model.mass, jac.T], [jac, np.zeros((m, m))]])
        self.evaluations += 1
        try:
            return np.linalg.solve(kkt, np.concatenate([self.model.applied, rhs]))[:n]
        except np.linalg.LinAlgError:
            raise RunFailure("failed", f"singular constraint Jacobian at t = {self.t:g} s "
                                       f"(redundant or locked joints)") from None

    def _step_to(self, t: float) -> None:
        for _ in range(int(round((t - self.t) / self.dt))):
            q, v, h = self.q, self.v, self.dt
            a1 = self._acceleration(q, v)
            a2 = self._acceleration(q + h / 2 * v, v + h / 2 * a1)
            a3 = self._acceleration(q + h / 2 * (v + h / 2 * a1), v + h / 2 * a2)
            a4 = self._acceleration(q + h * (v + h / 2 * a2), v + h * a3)
            self.q = q + h * v + h * h / 6 * (a1 + a2 + a3)
            self.v = v + h / 6 * (a1 + 2 * a2 + 2 * a3 + a4)
            self.steps += 1
        self.t = t

    def _states(self, t: float) -> BodyStates:
        q, v = self.q.reshape(-1, 3), self.v.reshape(-1, 3)
        zero = np.zeros(len(q))
        half = q[:, 2] / 2
        return BodyStates(
            position=np.column_stack([q[:, :2], self.z]),
            quaternion=np.column_stack([np.cos(half), zero, zero, np.sin(half)]),
            velocity=np.column_stack([v[:, :2], zero]),
            angular_velocity=np.column_stack([zero, zero, v[:, 2]]))

    def counters(self) -> dict:
        return {"rhs_evals": self.evaluations}
