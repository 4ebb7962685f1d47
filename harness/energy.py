"""Energy bookkeeping from body states, as in the seed (002 ch. 7 setup): the energy-balance error
is e(t) = T + V − W − (T₀ + V₀), with T the kinetic energy, V the potential of gravity and of
springs, and W the work of the other applied forces integrated along the motion.

Work over a sample interval is exact where the load is constant: a joint torque τ does τ·Δθ, a
joint force f·Δs, a constant world force F at a body point F·Δp.  A world torque on a spatial body
and damper dissipation use the trapezoidal rule on the power.  All functions take arrays with any
leading sample shape.
"""

from __future__ import annotations

import numpy as np

from harness.model import BodyForce, BodyTorque, JointActuation, Mechanism, SpringDamper
from harness.outputs import body_frame, body_rotations, joint_angle, joint_slide
from harness.trajectory import BodyStates, Trajectory


def kinetic_energy(mech: Mechanism, velocity, angular_velocity, rotations) -> np.ndarray:
    """T = Σ ½ m |v|² + ½ ωᵀ (A J̄ Aᵀ) ω, shape (...,), J."""
    total = 0.0
    for b, body in enumerate(mech.bodies):
        v, w, rot = velocity[..., b, :], angular_velocity[..., b, :], rotations[..., b, :, :]
        local = np.einsum("...ji,...j->...i", rot, w)
        total = total + 0.5 * body.mass * np.einsum("...i,...i", v, v) \
            + 0.5 * np.einsum("...i,ij,...j", local, body.inertia, local)
    return total


def _spring_geometry(mech, spring: SpringDamper, positions, rotations, velocity, angular_velocity):
    """Length (...,) and its rate (...,) of a spring-damper."""
    p1, r1 = body_frame(mech, spring.body1, positions, rotations)
    p2, r2 = body_frame(mech, spring.body2, positions, rotations)
    arm1, arm2 = r1 @ spring.point1, r2 @ spring.point2
    d = p2 + arm2 - p1 - arm1

    def point_velocity(body, arm):
        if body == "ground":
            return np.zeros_like(arm)
        index = mech.body_index(body)
        return velocity[..., index, :] + np.cross(angular_velocity[..., index, :], arm)

    length = np.linalg.norm(d, axis=-1)
    rel = point_velocity(spring.body2, arm2) - point_velocity(spring.body1, arm1)
    return length, np.einsum("...i,...i", d, rel) / length


def potential_energy(mech: Mechanism, positions, rotations, velocity, angular_velocity) -> np.ndarray:
    """V = −Σ m g·R + Σ ½ k (L − L₀)², shape (...,), J."""
    total = -np.einsum("...bi,b,i->...", positions, mech.masses, mech.gravity)
    for spring in (f for f in mech.forces if isinstance(f, SpringDamper)):
        length, _ = _spring_geometry(mech, spring, positions, rotations, velocity, angular_velocity)
        total = total + 0.5 * spring.stiffness * (length - spring.free_length) ** 2
    return total


def _wrap(angle):
    return (angle + np.pi) % (2.0 * np.pi) - np.pi


def _power(mech, force, positions, rotations, velocity, angular_velocity):
    """Power of a load evaluated by quadrature (world torques, dampers), shape (...,), W."""
    if isinstance(force, BodyTorque):
        return angular_velocity[..., mech.body_index(force.body), :] @ force.torque
    _, rate = _spring_geometry(mech, force, positions, rotations, velocity, angular_velocity)
    return -force.damping * rate ** 2


def interval_work(mech: Mechanism, start: dict, end: dict, dt) -> np.ndarray:
    """Work of the non-potential loads between two states, shape (...,), J.

    ``start`` and ``end`` hold arrays ``position``, ``rotation``, ``velocity``,
    ``angular_velocity`` with matching leading shapes; ``dt`` is the interval length (s).
    """
    work = 0.0
    for force in mech.forces:
        if isinstance(force, JointActuation):
            joint = mech.joint(force.joint)
            if joint.type in ("revolute", "cylindrical"):
                delta = _wrap(joint_angle(mech, joint, end["position"], end["rotation"])
                              - joint_angle(mech, joint, start["position"], start["rotation"]))
            else:
                delta = (joint_slide(mech, joint, end["position"], end["rotation"])
                         - joint_slide(mech, joint, start["position"], start["rotation"]))
            work = work + force.value * delta
        elif isinstance(force, BodyForce):
            index = mech.body_index(force.body)
            def point(state):
                return state["position"][..., index, :] + state["rotation"][..., index, :, :] @ force.point
            work = work + (point(end) - point(start)) @ force.force
        elif isinstance(force, BodyTorque) or force.damping > 0:
            p0 = _power(mech, force, start["position"], start["rotation"], start["velocity"],
                        start["angular_velocity"])
            p1 = _power(mech, force, end["position"], end["rotation"], end["velocity"],
                        end["angular_velocity"])
            work = work + 0.5 * (p0 + p1) * dt
    return work


def state_arrays(states: Trajectory | BodyStates) -> dict:
    """The arrays :func:`interval_work` and the energy functions take, for a trajectory or for
    the body states of one instant (both carry the same four arrays)."""
    return {"position": states.position, "rotation": body_rotations(states.quaternion),
            "velocity": states.velocity, "angular_velocity": states.angular_velocity}


def mechanical_energy(mech: Mechanism, state: dict) -> np.ndarray:
    """T + V, shape (...,), J."""
    return (kinetic_energy(mech, state["velocity"], state["angular_velocity"], state["rotation"])
            + potential_energy(mech, state["position"], state["rotation"], state["velocity"],
                               state["angular_velocity"]))


def energy_balance(mech: Mechanism, trajectory: Trajectory) -> np.ndarray:
    """e(t) = T + V − W − (T₀ + V₀) at every sample, shape (n_samples,), J."""
    if trajectory.n_samples == 0:
        return np.zeros(0)
    state = state_arrays(trajectory)
    energy = mechanical_energy(mech, state)
    start = {k: v[:-1] for k, v in state.items()}
    end = {k: v[1:] for k, v in state.items()}
    work = np.concatenate([[0.0], np.cumsum(interval_work(mech, start, end, np.diff(trajectory.times))
                                            * np.ones(trajectory.n_samples - 1))])
    return energy - work - energy[0]
