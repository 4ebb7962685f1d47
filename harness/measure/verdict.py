"""The measuring stick's verdict on a run (docs/design.md, rule 5: ``ok`` is a promise).

An adapter's own status says only that its integrator did not give up.  After every run the
harness judges the returned :class:`~mbh._harness.model.trajectory.Trajectory` the same way for every adapter
and withdraws ``ok`` at the first sample where

1. a position, orientation or velocity is not finite (→ ``diverged``);
2. a joint gap exceeds ``gap`` × the mechanism's size :func:`characteristic_length` (m), or a joint
   orientation violation exceeds ``orientation`` (rad);
3. the energy-balance error |e(t)| (:func:`mbh._harness.measure.energy.energy_balance`) exceeds ``energy`` ×
   the energy scale :func:`mbh._harness.measure.energy.energy_scale` (J: the most energy that moves through
   the reference — its largest kinetic energy, potential-energy range or applied work; M·|g|·ℓ
   for a scene at rest or without a reference; not judged, with a note, when neither exists);
4. the configuration left the assembly branch of the start: it is farther than ``branch`` × the
   mechanism's size from the reference's configuration at the same value of the driver
   coordinate (see :mod:`mbh._harness.measure.branch`);
5. the configuration left the reference's motion: it is farther than ``trajectory`` × the
   mechanism's size from the reference's configuration at the same time (the largest distance
   over the bodies' centres of mass and joint points, :func:`mbh._harness.measure.branch.markers`), or a body
   is turned by more than ``trajectory`` rad from the reference's orientation at the same time
   (the distance's angular counterpart, as ``orientation`` is the gap's: a turn of 0.1 rad moves
   a point at the mechanism's size from the axis by 0.1 of the size; without it a small body can
   be far off in angle while its points stay close in metres).  A run can stay on its branch
   and still be a wrong answer: early or late by a large part of a cycle, or with the wrong
   amplitude.  Check 4 names a branch switch as such; this one catches what it lets through on
   purpose (it compares at the same driver value so as not to take a phase error for a branch
   switch).

Breaches 2–5 give ``failed`` (the run finished, the answer is wrong), or ``diverged`` when the
quantity exceeds its bound :data:`DIVERGED_FACTOR`-fold (at the default bounds: a joint gap the
size of the mechanism, an energy error 50 times its energy scale).  The reason names the first
sample's time and every quantity breached there; ``failure_time`` is the last sample before it
(the first sample's time if the breach is there); all samples are kept.  A run an adapter already
reported as not ``ok`` keeps its own status and reason, and the stick's finding becomes a note.

The default bounds (:class:`Bounds`) are physical, not tuned to any engine: a joint that has
opened by half a percent of the mechanism's size, or an energy balance off by 5 % of the energy
that moves it, is no longer the mechanism described (its link lengths, or its motion's energy,
are wrong by that much).  A branch switch moves bodies by a sizeable fraction of the mechanism
(metres on the four-bar), while an on-branch run stays within about its joint gaps of the
reference's branch, so 10 % separates the two with margin on either side.  A run whose bodies are
10 % of the mechanism's size from where the reference has them at the same time is wrong by as
much as a branch switch; below that, how far it is off is a question of accuracy, reported as its
error against the reference.  The accurate runs (every ``best`` at dt 1e-3 s) stay well over an
order of magnitude below every bound, while the known-inaccurate defaults at dt 1e-2 s fail it
(figures: docs/measurements.md, section "Verdict bounds").
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from mbh._harness.measure.branch import BranchCheck, branch_distance, markers, reference_side
from mbh._harness.measure.energy import energy_balance, energy_scale, has_quadrature_loads, \
    reference_quadrature_work
from mbh._harness.measure.metrics import reference_outputs, violation_series
from mbh._harness.model.mechanism import Mechanism, characteristic_length
from mbh._harness.model.outputs import rotation_between
from mbh._harness.common.status import CaseStatus
from mbh._harness.model.timegrid import TIME_MATCH, reference_indices
from mbh._harness.model.trajectory import Trajectory

#: Largest joint gap, as a fraction of :func:`characteristic_length` (2.9 cm on the 5.7 m
#: four-bar, 9 mm on the 1.9 m spatial slider-crank).
GAP_FRACTION = 5e-3
#: Largest joint orientation violation (angle between axes that should coincide), rad.  The
#: angular counterpart of GAP_FRACTION: that gap at the end of a link of the mechanism's size.
ORIENTATION_BOUND = 5e-3
#: Largest |energy-balance error|, as a fraction of :func:`energy_scale`.
ENERGY_FRACTION = 5e-2
#: Largest distance from the reference's configuration at the same driver value, as a fraction of
#: :func:`characteristic_length`.
BRANCH_FRACTION = 1e-1
#: Largest distance from the reference's configuration at the same time, as a fraction of
#: :func:`characteristic_length`: an error the size of a branch switch (:data:`BRANCH_FRACTION`);
#: also the largest turn of a body from the reference's orientation at the same time, rad.
TRAJECTORY_FRACTION = 1e-1
#: A breach this many times past its bound is reported as ``diverged`` rather than ``failed``.
DIVERGED_FACTOR = 1e3


@dataclass(frozen=True)
class Bounds:
    """The verdict's bounds (module constants by default); see the module docstring.

    Attributes
    ----------
    gap : float
        Joint gap / characteristic length.
    orientation : float
        Joint orientation violation, rad.
    energy : float
        |Energy-balance error| / energy scale.
    branch : float
        Distance from the reference's branch / characteristic length.
    trajectory : float
        Distance from the reference's configuration at the same time / characteristic length,
        and a body's turn from the reference's orientation at the same time, rad.
    """

    gap: float = GAP_FRACTION
    orientation: float = ORIENTATION_BOUND
    energy: float = ENERGY_FRACTION
    branch: float = BRANCH_FRACTION
    trajectory: float = TRAJECTORY_FRACTION

    @classmethod
    def parse(cls, text: str) -> "Bounds":
        """Bounds from ``"gap=1e-2,energy=0.1"`` (unnamed ones keep their defaults).

        Raises ValueError naming the bad item, the valid names, or the bad value.
        """
        names = [f.name for f in dataclasses.fields(cls)]
        values = {}
        for item in filter(None, (part.strip() for part in text.split(","))):
            key, sep, value = (s.strip() for s in item.partition("="))
            if not sep or key not in names:
                raise ValueError(f"bounds: expected NAME=VALUE with NAME one of {', '.join(names)},"
                                 f" got {item!r}")
            try:
                number = float(value)
            except ValueError:
                number = float("nan")
            if not (np.isfinite(number) and number > 0):
                raise ValueError(f"bounds: {key} must be a positive finite number, got {value!r}")
            values[key] = number
        return cls(**values)


DEFAULT_BOUNDS = Bounds()
#: The main-output error (rad or m) below which a case counts as accurate when a campaign does not
#: set its own ``accuracy``.
DEFAULT_ACCURACY = 1e-6


def joint_violations(mech: Mechanism, trajectory: Trajectory) -> tuple[np.ndarray, np.ndarray]:
    """Largest joint gap (m) and orientation violation (rad) at every sample, each (n,), from the
    neutral joint equations (:func:`mbh._harness.measure.metrics.violation_series`); for a planar mechanism a
    body's departure from the plane counts as a gap and its tilt out of it as an orientation
    violation."""
    series = violation_series(mech, trajectory)
    gaps, angles = series["joint_gap_m"], series["orientation_rad"]
    if mech.planar:
        gaps = np.maximum(gaps, series["out_of_plane_m"])
        angles = np.maximum(angles, series["tilt_rad"])
    return gaps, angles


@dataclass(frozen=True)
class Check:
    """One quantity judged at every sample.

    ``ratio`` (n,) is the quantity over its bound (> 1: breached; inf: not finite);
    ``describe(k)`` says what was found at sample k.
    """

    ratio: np.ndarray
    describe: object


def _finite_check(trajectory: Trajectory) -> Check:
    arrays = (trajectory.position, trajectory.quaternion, trajectory.velocity,
              trajectory.angular_velocity)
    bad = ~np.all([np.isfinite(a).all(axis=(1, 2)) for a in arrays], axis=0)
    names = ("position", "orientation", "velocity", "angular velocity")

    def describe(k):
        which = [n for n, a in zip(names, arrays) if not np.isfinite(a[k]).all()]
        return f"non-finite {', '.join(which)}"
    return Check(np.where(bad, np.inf, 0.0), describe)


def _constraint_checks(mech: Mechanism, trajectory: Trajectory, bounds: Bounds) -> list[Check]:
    length = characteristic_length(mech)
    gap_bound = bounds.gap * length
    gaps, angles = joint_violations(mech, trajectory)
    return [
        Check(gaps / gap_bound, lambda k: f"joint gap {gaps[k]:.3g} m exceeds {gap_bound:.3g} m "
              f"({bounds.gap:g} of the mechanism's size {length:.3g} m)"),
        Check(angles / bounds.orientation, lambda k: f"joint orientation violation "
              f"{angles[k]:.3g} rad exceeds {bounds.orientation:g} rad"),
    ]


def _energy_check(mech: Mechanism, trajectory: Trajectory, reference, bounds: Bounds,
                  notes: list) -> Check | None:
    scale = energy_scale(mech, Trajectory.empty(len(mech.bodies)) if reference is None else reference)
    if scale is None:
        notes.append("energy balance not judged: the scene has no energy scale (no motion in the "
                     "reference and no gravity)")
        return None
    error = np.abs(energy_balance(mech, trajectory, reference))
    limit = bounds.energy * scale
    return Check(error / limit, lambda k: f"energy-balance error {error[k]:.3g} J exceeds "
                 f"{limit:.3g} J ({bounds.energy:g} of the energy scale {scale:.3g} J)")


def _branch_check(mech: Mechanism, trajectory: Trajectory, reference: Trajectory,
                  bounds: Bounds, notes: list) -> Check | None:
    length = characteristic_length(mech)
    limit = bounds.branch * length
    result: BranchCheck = branch_distance(mech, trajectory, reference, limit)
    if result.skipped:
        notes.append(f"assembly branch not checked: {result.skipped}")
        return None
    unchecked = ~np.isfinite(result.distance)
    if unchecked.any():
        t = trajectory.times[unchecked]
        notes.append(f"assembly branch not checked at {unchecked.sum()} samples (t = {t[0]:.6g} "
                     f"to {t[-1]:.6g} s): the driver left the range of values the reference visits")
    distance = np.where(unchecked, 0.0, result.distance)
    return Check(distance / limit, lambda k: f"left the assembly branch (body "
                 f"{mech.bodies[result.body[k]].name} is {distance[k]:.3g} m from the reference's "
                 f"configuration at the same driver value; bound {limit:.3g} m, {bounds.branch:g} "
                 f"of the mechanism's size)")


def _trajectory_check(mech: Mechanism, trajectory: Trajectory, reference: Trajectory,
                      bounds: Bounds, notes: list) -> Check | None:
    length = characteristic_length(mech)
    limit = bounds.trajectory * length
    covered = trajectory.times <= reference.times[-1] + TIME_MATCH
    try:
        index = reference_indices(reference, trajectory.times[covered])
    except ValueError as error:
        notes.append(f"motion not compared with the reference: {error}")
        return None
    if not covered.all():
        notes.append(f"motion not compared with the reference after t = "
                     f"{reference.times[-1]:.6g} s, where the reference ends")
    run, same_time = _samples(trajectory, covered), _samples(reference, index)
    run_markers, body_of = markers(mech, run)
    apart = np.linalg.norm(run_markers - markers(mech, same_time)[0], axis=-1) / limit
    turned = rotation_between(run.quaternion, same_time.quaternion) / bounds.trajectory
    ratio = np.zeros(trajectory.n_samples)
    ratio[:covered.sum()] = np.maximum(apart.max(axis=1), turned.max(axis=1))

    def describe(k):
        marker, body = apart[k].argmax(), turned[k].argmax()
        found = []
        if not apart[k, marker] <= 1.0:
            found.append(f"body {mech.bodies[body_of[marker]].name} is "
                         f"{apart[k, marker] * limit:.3g} m from the reference's configuration at "
                         f"the same time; bound {limit:.3g} m, {bounds.trajectory:g} of the "
                         f"mechanism's size")
        if not turned[k, body] <= 1.0:
            found.append(f"body {mech.bodies[body].name} is turned "
                         f"{turned[k, body] * bounds.trajectory:.4g} rad from the reference's "
                         f"orientation at the same time; bound {bounds.trajectory:g} rad")
        return f"left the reference's motion ({'; '.join(found)})"
    return Check(ratio, describe)


def _stick_checks(mech, trajectory, reference, bounds, notes) -> list[Check]:
    """Joint, energy, branch and motion checks of a trajectory whose samples are all finite."""
    checks = [*_constraint_checks(mech, trajectory, bounds),
              _energy_check(mech, trajectory, reference, bounds, notes)]
    if reference is None:
        notes.append("assembly branch and motion not checked: no reference")
    else:
        checks += [_branch_check(mech, trajectory, reference, bounds, notes),
                   _trajectory_check(mech, trajectory, reference, bounds, notes)]
    return [check for check in checks if check is not None]


def prepare_reference(mech: Mechanism, reference: Trajectory) -> None:
    """Compute now what judging and measuring a run of ``mech`` derive from ``reference`` alone
    (the energy scale and baseline, the branch check's reference side, the outputs); kept for a
    frozen reference (:mod:`mbh._harness.measure.per_reference`), so that the warm template computes
    them once for every case forked from it."""
    energy_scale(mech, reference)
    if has_quadrature_loads(mech):
        reference_quadrature_work(mech, reference)
    reference_side(mech, reference)
    reference_outputs(mech, reference)


def judge(mech: Mechanism, trajectory: Trajectory, reference: Trajectory | None = None,
          bounds: Bounds = DEFAULT_BOUNDS) -> Trajectory:
    """The trajectory with the stick's verdict applied (see the module docstring).

    Parameters
    ----------
    mech : Mechanism
    trajectory : Trajectory
        What the adapter returned; not modified.
    reference : Trajectory or None
        The verified reference; without it the assembly branch and the motion are not checked (a
        note says so) and the energy scale is the static M·|g|·ℓ.
    bounds : Bounds

    Returns
    -------
    Trajectory
        A copy with ``status``, ``reason``, ``failure_time`` and ``notes`` updated.
    """
    if trajectory.n_samples == 0:
        return trajectory
    notes = list(trajectory.notes)
    finite = _finite_check(trajectory)
    reached = int(np.argmax(np.isinf(finite.ratio))) if np.isinf(finite.ratio).any() \
        else trajectory.n_samples
    checks = [finite]
    with np.errstate(all="ignore"):  # a run growing without bound overflows its energy
        if reached:
            checks += _stick_checks(mech, _samples(trajectory, slice(reached)), reference,
                                     bounds, notes)
    ratios = np.zeros((len(checks), trajectory.n_samples))
    for row, check in zip(ratios, checks):
        row[:check.ratio.size] = np.nan_to_num(check.ratio, nan=np.inf)
    breached = np.flatnonzero((ratios > 1.0).any(axis=0))
    if breached.size == 0:
        return dataclasses.replace(trajectory, notes=notes)
    k = int(breached[0])
    found = "; ".join(check.describe(k) for check, row in zip(checks, ratios) if row[k] > 1.0)
    time = float(trajectory.times[k])
    reason = f"at t = {time:.6g} s: {found}"
    if trajectory.status != CaseStatus.OK:
        return dataclasses.replace(trajectory, notes=[*notes, f"the measuring stick: {reason}"])
    diverged = bool(np.max(ratios[:, k]) >= DIVERGED_FACTOR)
    return dataclasses.replace(trajectory,
                               status=CaseStatus.DIVERGED if diverged else CaseStatus.FAILED,
                               reason=reason, failure_time=float(trajectory.times[max(k - 1, 0)]),
                               notes=notes)


def _samples(trajectory: Trajectory, selection) -> Trajectory:
    """The samples ``selection`` (a slice or an index array) as a trajectory."""
    return dataclasses.replace(trajectory, times=trajectory.times[selection],
                               position=trajectory.position[selection],
                               quaternion=trajectory.quaternion[selection],
                               velocity=trajectory.velocity[selection],
                               angular_velocity=trajectory.angular_velocity[selection])
