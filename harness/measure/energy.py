"""Energy bookkeeping from body states, as in the seed (Rouvinen 2003, ch. 7 setup): the energy-balance error
is e(t) = T + V − W − (T₀ + V₀), with T the kinetic energy, V the potential of gravity and of
springs, and W the work of the other applied loads integrated along the motion.

Work along a sampled trajectory (:func:`cumulative_work`) is exact wherever the load is constant
along a coordinate the states give: a joint torque τ does τ·Δθ and a joint force f·Δs (joint
coordinates unwrapped along the samples), a constant world force F at a body point F·Δp, and a
world torque on a body of a planar mechanism τ_z·Δφ, φ the body's unwrapped rotation about z (the
only rotation a planar body has; the x and y components do no work).  Unwrapping assumes a joint or
body turns less than π between two samples.

Two loads have no such coordinate: a world torque on a spatial body (power τ·ω) and damper
dissipation (power −c L̇²).  Their power is sampled and integrated exactly after interpolation by
a spline of degree :data:`QUADRATURE_DEGREE` with not-a-knot ends (:func:`cumulative_quadrature`),
a quadrature of order :data:`QUADRATURE_DEGREE` + 1 in the sample spacing h for a smooth power, on
any increasing sample times: at hω ≤ 0.1 the running integral is exact to round-off, far
beyond the trapezoidal rule's (hω)²/12 (figures: docs/measurements.md, section "Energy
bookkeeping").

A fast passage that the samples do not resolve still costs accuracy.  Given a reference on a
denser grid, :func:`energy_balance` therefore takes the reference's work, integrated on its own
grid, and integrates only the difference of the powers at the samples (a control variate), which
brings such a passage back to near round-off (tests/measure/test_metrics.py).

:func:`interval_work` is the two-state version for a stepper that only holds the previous and the
current state: exact for the same loads, the trapezoidal rule (second order) for the others.
All state functions take arrays with any leading sample shape.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import make_interp_spline

from mbh._harness.model.mechanism import (BodyForce, BodyTorque, JointActuation, Mechanism,
                                          SpringDamper, characteristic_length)
from mbh._harness.model.outputs import (body_frame, body_rotations, joint_angle, joint_slide,
                                        wrap_angle)
from mbh._harness.model.timegrid import reference_indices
from mbh._harness.model.trajectory import BodyStates, Trajectory
from mbh._harness.measure.per_reference import per_reference, read_only

#: Degree of the spline through sampled power (odd, so not-a-knot ends are symmetric).
QUADRATURE_DEGREE = 9


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


def _has_work_coordinate(mech: Mechanism, force) -> bool:
    """Whether the work of ``force`` is a coordinate change times a constant (exact)."""
    if isinstance(force, BodyTorque):
        return mech.planar
    return isinstance(force, (JointActuation, BodyForce))


def _work_coordinate(mech: Mechanism, force, state: dict) -> tuple[float, np.ndarray, bool]:
    """A constant load's magnitude (N, N·m or 1), the coordinate whose change times it is the
    load's work (m, rad or J), shape (...,), and whether that coordinate is an angle (wrapped)."""
    position, rotation = state["position"], state["rotation"]
    if isinstance(force, JointActuation):
        joint = mech.joint(force.joint)
        if joint.type in ("revolute", "cylindrical"):
            return force.value, joint_angle(mech, joint, position, rotation), True
        return force.value, joint_slide(mech, joint, position, rotation), False
    index = mech.body_index(force.body)
    if isinstance(force, BodyForce):
        point = position[..., index, :] + rotation[..., index, :, :] @ force.point
        return 1.0, point @ force.force, False
    # a planar body's rotation about z, from its rotation matrix (free of the quaternion's sign)
    return force.torque[2], np.arctan2(rotation[..., index, 1, 0], rotation[..., index, 0, 0]), True


def _power(mech, force, state: dict) -> np.ndarray:
    """Power of a load without a work coordinate (spatial world torque, damper), shape (...,), W."""
    if isinstance(force, BodyTorque):
        return state["angular_velocity"][..., mech.body_index(force.body), :] @ force.torque
    _, rate = _spring_geometry(mech, force, state["position"], state["rotation"],
                               state["velocity"], state["angular_velocity"])
    return -force.damping * rate ** 2


def _quadrature_loads(mech: Mechanism) -> list:
    return [f for f in mech.forces if not _has_work_coordinate(mech, f)
            and (isinstance(f, BodyTorque) or f.damping > 0)]


def has_quadrature_loads(mech: Mechanism) -> bool:
    """Whether ``mech`` has loads whose work is integrated by quadrature (body torques, dampers):
    then :func:`energy_balance` takes the reference's work of them
    (:func:`reference_quadrature_work`)."""
    return bool(_quadrature_loads(mech))


def interval_work(mech: Mechanism, start: dict, end: dict, dt) -> np.ndarray:
    """Work of the non-potential loads between two states, shape (...,), J.

    ``start`` and ``end`` hold arrays ``position``, ``rotation``, ``velocity``,
    ``angular_velocity`` with matching leading shapes; ``dt`` is the interval length (s).  Exact
    for loads with a work coordinate (angles change by less than π over the interval), the
    trapezoidal rule for the others.
    """
    work = 0.0
    for force in (f for f in mech.forces if _has_work_coordinate(mech, f)):
        magnitude, c0, angular = _work_coordinate(mech, force, start)
        _, c1, _ = _work_coordinate(mech, force, end)
        work = work + magnitude * (wrap_angle(c1 - c0) if angular else c1 - c0)
    for force in _quadrature_loads(mech):
        work = work + 0.5 * (_power(mech, force, start) + _power(mech, force, end)) * dt
    return work


def cumulative_quadrature(times: np.ndarray, values: np.ndarray) -> np.ndarray:
    """∫ from times[0] to each sample time of the sampled function, shape (n,).

    The interpolating spline of degree min(:data:`QUADRATURE_DEGREE`, n − 1) through the samples
    (not-a-knot ends) integrated exactly; order degree + 1 in the largest sample spacing.
    """
    times = np.asarray(times, dtype=float)
    if times.size < 2:
        return np.zeros(times.size)
    spline = make_interp_spline(times, values, k=min(QUADRATURE_DEGREE, times.size - 1))
    integral = spline.antiderivative()
    return integral(times) - integral(times[0])


def dissipative_power(mech: Mechanism, state: dict) -> np.ndarray:
    """Total power of the loads without a work coordinate (spatial world torques, dampers), shape
    (...,), W; zeros when the mechanism has none."""
    zeros = np.zeros(state["position"].shape[:-2])
    return sum((_power(mech, force, state) for force in _quadrature_loads(mech)), zeros)


def coordinate_work(mech: Mechanism, state: dict, n: int) -> np.ndarray:
    """Work of the loads with a work coordinate (constant torques and forces along a joint or a
    body angle) from the first of ``n`` samples to each, shape (n,), J."""
    work = np.zeros(n)
    if n == 0:
        return work
    for force in (f for f in mech.forces if _has_work_coordinate(mech, f)):
        magnitude, coordinate, angular = _work_coordinate(mech, force, state)
        if angular:
            coordinate = np.unwrap(coordinate)
        work += magnitude * (coordinate - coordinate[0])
    return work


def cumulative_work(mech: Mechanism, times: np.ndarray, state: dict,
                    baseline: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Work of the non-potential loads from the first sample to each sample, shape (n,), J.

    ``state`` holds the arrays of :func:`state_arrays` for samples at ``times`` (s, increasing).
    ``baseline`` = (W_b, P_b), shapes (n,): the work from the first sample (J) and the power (W)
    of the quadrature loads along a neighbouring trajectory at the same times, W_b integrated
    more accurately than these samples allow; the quadrature then integrates only P − P_b.
    """
    work = coordinate_work(mech, state, np.size(times))
    if work.size == 0:
        return work
    power = dissipative_power(mech, state)
    if baseline is not None:
        work += baseline[0]
        power = power - baseline[1]
    if np.any(power):
        work += cumulative_quadrature(times, power)
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


def energy_balance(mech: Mechanism, trajectory: Trajectory,
                   reference: Trajectory | None = None) -> np.ndarray:
    """e(t) = T + V − W − (T₀ + V₀) at every sample, shape (n_samples,), J.

    With a ``reference`` whose grid holds every sample time, the work of the quadrature loads is
    the reference's plus the quadrature of the power difference at the samples (a control
    variate): the quadrature error then scales with the departure from the reference, not with
    the power, so a sample grid that does not resolve the power (a fast passage, a stiff damper)
    does not enter the figure.  The reference's own work of those loads is read off its energy
    balance, W_b = T + V − (T₀ + V₀) − (work of the loads with a work coordinate), which a
    verified reference meets to its accuracy: integrating the damper's power on the 1 ms grid
    instead left 7.2e-4 J on stiff_fourbar (a 1.9 ms transient), 370 times its energy scale.
    """
    if trajectory.n_samples == 0:
        return np.zeros(0)
    state = state_arrays(trajectory)
    energy = mechanical_energy(mech, state)
    baseline = None
    if reference is not None and has_quadrature_loads(mech):
        index = reference_indices(reference, trajectory.times)
        reference_work, reference_power = reference_quadrature_work(mech, reference)
        baseline = (reference_work[index] - reference_work[index[0]], reference_power[index])
    return energy - cumulative_work(mech, trajectory.times, state, baseline) - energy[0]


@per_reference
def reference_quadrature_work(mech: Mechanism, reference: Trajectory
                               ) -> tuple[np.ndarray, np.ndarray]:
    """The reference's work of the quadrature loads at every sample, W_b = T + V − (T₀ + V₀) −
    (work of the loads with a work coordinate), J, and their power, W, each shape (n_samples,):
    :func:`energy_balance`'s baseline."""
    state = state_arrays(reference)
    energy = mechanical_energy(mech, state)
    work = energy - energy[0] - coordinate_work(mech, state, reference.n_samples)
    return read_only(work), read_only(dissipative_power(mech, state))


@per_reference
def energy_scale(mech: Mechanism, reference: Trajectory) -> float | None:
    """The energy that relative energy errors are divided by, J.

    The most energy that moves through the mechanism along ``reference``: the largest of its
    kinetic energy, the range of its potential energy (gravity and springs) and the largest
    |work| of the loads with a work coordinate (driving torques and forces).  On the seed's scenes
    and every shipped scene that moves freely the kinetic energy is the largest of the three; a
    mechanism held by a stiff spring (stiff_fourbar) barely moves, its kinetic energy peaks at
    1.9e-6 J while the driving torque stores 5.0e-4 J in the spring, and a scale of kinetic
    energy alone would fail runs whose crank angle is right to 1e-10 rad.  For a reference that
    never moves (a scene at rest), the static scale M·|g|·ℓ, M the total mass and ℓ the
    mechanism's extent (largest distance between two body centres or joint points in the
    reference configuration); None when both are zero (no motion and no gravity: no energy scale
    exists).
    """
    exchanged = 0.0
    if reference.n_samples:
        state = state_arrays(reference)
        potential = potential_energy(mech, state["position"], state["rotation"],
                                     state["velocity"], state["angular_velocity"])
        exchanged = max(
            float(kinetic_energy(mech, state["velocity"], state["angular_velocity"],
                                 state["rotation"]).max()),
            float(potential.max() - potential.min()),
            float(np.abs(coordinate_work(mech, state, reference.n_samples)).max()))
    if exchanged > 0.0:
        return exchanged
    static = float(mech.masses.sum() * np.linalg.norm(mech.gravity) * characteristic_length(mech))
    return static if static > 0.0 else None
