"""What the outside tests compute from an engine's body states themselves, and how they run a
case and read its verdict.

Nothing here uses the harness's reference, its outputs, its energy bookkeeping or its
constraint measures: each quantity is written out from the trajectory's world-frame body states
(positions, scalar-first quaternions rotating body vectors into the world, velocities, angular
velocities; harness/model/trajectory.py) and the mechanism's inputs (masses, centroidal inertias
in the body frames, gravity).  A case is run with :func:`mbh.run_case`, so its status is the
harness's verdict; an engine that does not run a mechanism ``ok`` is recorded as an expected
failure with its reason (:func:`engine_cases`), never skipped in silence.
"""

from __future__ import annotations

import numpy as np
import pytest

import mbh

#: The five engines, in the order the reports list them.
ENGINES = ("inhouse", "mujoco", "pinocchio", "exudyn", "pybullet")


class NotOk(AssertionError):
    """The harness did not mark the case ``ok``; the message is its status and reason."""


def engine_cases(not_ok: dict[str, str], *before) -> list:
    """:data:`ENGINES` as pytest parameters, each after the values ``before`` (other parameters
    of the same case); those in ``not_ok`` (engine → the status and reason measured) marked as
    expected to raise :class:`NotOk`: strictly, so an engine that starts to run the mechanism
    ``ok`` fails the test until its deviation is measured and bounded."""
    return [pytest.param(*before, engine, id="-".join([*before, engine]),
                         marks=[pytest.mark.xfail(raises=NotOk, strict=True,
                                                  reason=f"{engine}: {not_ok[engine]}")]
                         if engine in not_ok else [])
            for engine in ENGINES]


#: Judged runs of this session by (content hash, engine, step, end time).
_RUNS: dict[tuple, mbh.CaseResult] = {}


def ok_run(mech: mbh.Mechanism, engine: str, dt: float, t_end: float):
    """The trajectory of ``engine``'s ``best`` run of ``mech`` (step ``dt``, to ``t_end``, s),
    judged by the harness; raises :class:`NotOk` unless the verdict is ``ok``.  Runs are kept
    for the session, so tests of several invariants on one run pay for it once."""
    key = (mech.content_hash, engine, dt, t_end)
    if key not in _RUNS:
        _RUNS[key] = mbh.run_case(mech, engine, "best", dt=dt, t_end=t_end)
    result = _RUNS[key]
    if result.status != "ok":
        raise NotOk(f"{engine} on {mech.name}: {result.status}: {result.reason}")
    return result.trajectory


def rotations(quaternions: np.ndarray) -> np.ndarray:
    """Rotation matrices (body → world) of scalar-first quaternions, shape (..., 3, 3); each
    quaternion is normalised first (an engine's may have drifted off unit length)."""
    q = quaternions / np.linalg.norm(quaternions, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
    ], axis=-2)


def body_vectors(trajectory, body: int, vector) -> np.ndarray:
    """A vector fixed in body ``body`` (given in its body frame) in world axes at every sample,
    shape (n_samples, 3)."""
    return rotations(trajectory.quaternion[:, body]) @ np.asarray(vector, dtype=float)


def body_points(trajectory, body: int, point) -> np.ndarray:
    """A point fixed in body ``body`` (body frame, m) in the world at every sample, m."""
    return trajectory.position[:, body] + body_vectors(trajectory, body, point)


def signed_angle(first: np.ndarray, second: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """The turn (rad, in (−π, π]) about ``axis`` (unit) from ``first`` to ``second`` (both
    perpendicular to it), row by row."""
    return np.arctan2(np.einsum("ij,ij->i", np.cross(first, second), axis),
                      np.einsum("ij,ij->i", first, second))


def mass_properties(mech: mbh.Mechanism) -> tuple[np.ndarray, np.ndarray]:
    """Masses (kg, shape (n,)) and centroidal inertias in the body frames (kg·m², (n, 3, 3)) of
    the mechanism's moving bodies: the inputs every engine is given."""
    return (np.array([body.mass for body in mech.bodies]),
            np.stack([body.inertia for body in mech.bodies]))


def world_inertias(trajectory, inertias: np.ndarray) -> np.ndarray:
    """Each body's inertia about its centre of mass in world axes, A I Aᵀ, at every sample,
    shape (n_samples, n_bodies, 3, 3)."""
    turn = rotations(trajectory.quaternion)
    return turn @ inertias @ np.swapaxes(turn, -1, -2)


def kinetic_energy(trajectory, mech: mbh.Mechanism) -> np.ndarray:
    """T = Σ ½ m v·v + ½ ωᵀ (A I Aᵀ) ω over the moving bodies at every sample, J."""
    masses, inertias = mass_properties(mech)
    omega = trajectory.angular_velocity
    spin = np.einsum("tbi,tbij,tbj->t", omega, world_inertias(trajectory, inertias), omega)
    motion = np.einsum("b,tbi,tbi->t", masses, trajectory.velocity, trajectory.velocity)
    return 0.5 * (motion + spin)


def mechanical_energy(trajectory, mech: mbh.Mechanism) -> np.ndarray:
    """T + V at every sample, J: :func:`kinetic_energy` and gravity's potential −Σ m g·r (the
    mechanisms checked carry no springs)."""
    masses, _ = mass_properties(mech)
    height = np.einsum("b,tbi,i->t", masses, trajectory.position, np.asarray(mech.gravity))
    return kinetic_energy(trajectory, mech) - height


def angular_momentum(trajectory, mech: mbh.Mechanism, bodies=None) -> np.ndarray:
    """Angular momentum about the world origin of ``bodies`` (indices; default all), Σ m r × v +
    (A I Aᵀ) ω, at every sample, kg·m²/s, shape (n_samples, 3)."""
    masses, inertias = mass_properties(mech)
    chosen = slice(None) if bodies is None else list(bodies)
    spin = np.einsum("tbij,tbj->ti", world_inertias(trajectory, inertias)[:, chosen],
                     trajectory.angular_velocity[:, chosen])
    orbit = np.einsum("b,tbi->ti", masses[chosen],
                      np.cross(trajectory.position[:, chosen], trajectory.velocity[:, chosen]))
    return spin + orbit


def planar_angle(trajectory, body: int) -> np.ndarray:
    """A planar body's orientation: the angle (rad) of its body-frame x axis from the world's x
    axis about z, unwrapped along the samples (each sample must turn the body by less than π)."""
    axis = body_vectors(trajectory, body, [1.0, 0.0, 0.0])
    return np.unwrap(np.arctan2(axis[:, 1], axis[:, 0]))
