"""Has a run left the assembly branch of its start?  Measured against the verified reference.

A one-degree-of-freedom mechanism on one assembly branch has one configuration per value of its
driver coordinate.  So each sample of a run is compared with the reference's configuration at the
same driver value — not at the same time, so that a phase error (a run that is early or late) is
not taken for a branch switch:

1. the driver coordinate (the ``[initial] driver`` joint's angle, taken modulo 2π, or its slide)
   of every run sample is located among the reference's samples: the reference's driver series is
   cut into monotone pieces, and in each piece the segments whose ends bracket the value (for an
   angle, any value + 2πm) are found by bisection;
2. the reference's configuration is interpolated linearly along each bracketing segment, and the
   distance to the run's configuration is the largest over the bodies' markers (centre of mass
   and joint points, so a body's rotation counts too);
3. the run's distance is the smallest over the bracketing segments (the nearest visit of the
   reference to that driver value); a sample whose driver value the reference never reaches gets
   ``inf`` (not checked).

The premise is tested on the reference itself before it is used: the largest distance between two
of the reference's own visits to a driver value (the same search, with the largest instead of the
smallest distance) must stay below the limit, otherwise the configuration is not a function of the
driver (more degrees of freedom, or a reference that itself changes branch) and the check is
skipped with the reason.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mbh._harness.model.mechanism import GROUND, Mechanism
from mbh._harness.model.outputs import body_rotations, joint_angle, joint_slide
from mbh._harness.model.trajectory import Trajectory
from mbh._harness.measure.per_reference import per_reference, read_only

#: At most this many reference samples are used to test the premise (an even stride through it).
PREMISE_SAMPLES = 2000


@dataclass(frozen=True)
class BranchCheck:
    """Distance of every run sample from the reference's branch.

    Attributes
    ----------
    distance : ndarray, shape (n_samples,)
        m; ``inf`` where the reference never reaches the sample's driver value.
    body : ndarray of int, shape (n_samples,)
        Index of the body farthest from the reference's configuration.
    skipped : str
        Why the branch could not be checked at all ("" when it was).
    """

    distance: np.ndarray
    body: np.ndarray
    skipped: str = ""


def driver_series(mech: Mechanism, trajectory: Trajectory) -> tuple[np.ndarray, float | None]:
    """The driver coordinate at every sample, shape (n,), and its period (2π for an angle, whose
    values are wrapped to (−π, π]; None for a slide, m)."""
    joint = mech.joint(mech.initial.driver)
    rotations = body_rotations(trajectory.quaternion)
    if joint.type in ("revolute", "cylindrical"):
        return joint_angle(mech, joint, trajectory.position, rotations), 2.0 * np.pi
    return joint_slide(mech, joint, trajectory.position, rotations), None


def markers(mech: Mechanism, trajectory: Trajectory) -> tuple[np.ndarray, np.ndarray]:
    """World positions of every body's centre of mass and joint points, shape (n, k, 3), m, and
    the body index of each marker, shape (k,)."""
    local = [(b, np.zeros(3)) for b in range(len(mech.bodies))]
    for joint in mech.joints:
        local += [(mech.body_index(body), np.asarray(point, dtype=float))
                  for body, point in ((joint.body1, joint.point1), (joint.body2, joint.point2))
                  if body != GROUND]
    index = np.array([b for b, _ in local])
    points = np.array([p for _, p in local])
    rotations = body_rotations(trajectory.quaternion)[:, index]
    world = trajectory.position[:, index] + np.einsum("nkij,kj->nki", rotations, points)
    return world, index


def _brackets(u: np.ndarray, targets: np.ndarray, period: float | None):
    """Every reference segment bracketing each target (modulo ``period``).

    Yields ``(queries, i0, i1, w)``: for the target indices ``queries``, the configuration
    (1 − w)·X[i0] + w·X[i1] of the reference has the target's driver value.
    """
    step = np.diff(u)
    moving = np.flatnonzero(step)
    if moving.size == 0:
        return
    sign = np.sign(step[moving])
    turns = moving[1:][sign[1:] != sign[:-1]]
    for a, b in zip(np.concatenate([[0], turns]), np.concatenate([turns, [u.size - 1]])):
        piece = u[a:b + 1]
        flip = piece[-1] < piece[0]
        ascending = piece[::-1] if flip else piece
        lo, hi = ascending[0], ascending[-1]
        shifts = [0] if period is None else range(
            int(np.ceil((lo - targets.max()) / period)), int(np.floor((hi - targets.min()) / period)) + 1)
        for m in shifts:
            shifted = targets if period is None else targets + m * period
            queries = np.flatnonzero((shifted >= lo) & (shifted <= hi))
            if queries.size == 0:
                continue
            value = shifted[queries]
            j = np.clip(np.searchsorted(ascending, value, side="right") - 1, 0, ascending.size - 2)
            width = ascending[j + 1] - ascending[j]
            w = np.where(width > 0, (value - ascending[j]) / np.where(width > 0, width, 1.0), 0.0)
            if flip:
                yield queries, b - j, b - j - 1, w
            else:
                yield queries, a + j, a + j + 1, w


def _distances(u, reference_markers, targets, target_markers, period, nearest: bool):
    """Smallest (``nearest``) or largest distance over the bracketing reference segments, per
    target, shape (n,), and the marker index of that distance; inf/−inf where none brackets."""
    fill = np.inf if nearest else -np.inf
    distance = np.full(targets.size, fill)
    marker = np.zeros(targets.size, dtype=int)
    for queries, i0, i1, w in _brackets(u, targets, period):
        between = (reference_markers[i0] * (1.0 - w)[:, None, None]
                   + reference_markers[i1] * w[:, None, None])
        apart = np.linalg.norm(between - target_markers[queries], axis=-1)
        worst = apart.argmax(axis=1)
        value = apart[np.arange(queries.size), worst]
        better = value < distance[queries] if nearest else value > distance[queries]
        distance[queries[better]] = value[better]
        marker[queries[better]] = worst[better]
    return distance, marker


def _unwrapped(values: np.ndarray, period: float | None) -> np.ndarray:
    return values if period is None else np.unwrap(values, period=period)


def branch_distance(mech: Mechanism, trajectory: Trajectory, reference: Trajectory,
                    limit: float) -> BranchCheck:
    """Distance of each run sample from the reference's configuration at the same driver value.

    ``limit`` (m) is the branch bound; the check is skipped (``BranchCheck.skipped``) when the
    reference's own visits to one driver value differ by more (see the module docstring).
    """
    values, period = driver_series(mech, trajectory)
    side = reference_side(mech, reference)
    if side.spread.max() > limit:
        k = int(side.spread.argmax())
        n = len(trajectory.times)
        return BranchCheck(np.full(n, np.inf), np.zeros(n, dtype=int),
                           f"the reference's configuration is not a function of the driver "
                           f"{mech.initial.driver} (two of its visits to the driver value at "
                           f"t = {reference.times[k * side.stride]:.6g} s differ by "
                           f"{side.spread[k]:.3g} m at body "
                           f"{mech.bodies[side.body_of[side.where[k]]].name}: more than one "
                           "degree of freedom, or a reference that changes branch)")
    run_markers, _ = markers(mech, trajectory)
    distance, marker = _distances(side.u, side.markers, values, run_markers, period, nearest=True)
    return BranchCheck(distance, side.body_of[marker])


@dataclass(frozen=True)
class ReferenceSide:
    """What :func:`branch_distance` derives from the reference alone (arrays read-only).

    Attributes
    ----------
    u : ndarray, shape (n,)
        The reference's driver series, unwrapped (rad or m).
    markers : ndarray, shape (n, k, 3)
        Its markers (:func:`markers`), m; ``body_of`` (k,) the body of each.
    stride : int
        Every ``stride``-th sample tests the premise.
    spread, where : ndarray, shape (n // stride,)
        Largest distance between the reference's visits to each premise sample's driver value,
        m, and the marker index of it.
    """

    u: np.ndarray
    markers: np.ndarray
    body_of: np.ndarray
    stride: int
    spread: np.ndarray
    where: np.ndarray


@per_reference
def reference_side(mech: Mechanism, reference: Trajectory) -> ReferenceSide:
    """The reference's part of :func:`branch_distance`, and the test of its premise."""
    values, period = driver_series(mech, reference)
    u = _unwrapped(values, period)
    ref_markers, body_of = markers(mech, reference)
    stride = max(1, reference.n_samples // PREMISE_SAMPLES)
    spread, where = _distances(u, ref_markers, values[::stride], ref_markers[::stride], period,
                               nearest=False)
    return ReferenceSide(*(read_only(array) for array in (u, ref_markers, body_of)), stride,
                          read_only(spread), read_only(where))
