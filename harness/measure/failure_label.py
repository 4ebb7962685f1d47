"""Where a failed run failed, in the scene's terms: at a near-singular position of the verified
reference, on an overconstrained loop (:mod:`mbh._harness.neutral.conditioning` says where a
scene is near-singular).

The redundant joint equations at the assembled start are computed once per scene (by content
hash; the warm template computes them for every case forked from it,
:func:`mbh._harness.measure.verdict.prepare_reference`).  The reference's conditioning is not: an
SVD of Φ_q at every reference sample, ~0.12 s a scene, which would delay every campaign's first
case to spare the failed cases ~30 ms each.
"""

from __future__ import annotations

import dataclasses

from mbh._harness.common.status import CaseStatus
from mbh._harness.model.mechanism import Mechanism
from mbh._harness.model.trajectory import Trajectory
from mbh._harness.neutral.assembly import assemble
from mbh._harness.neutral.conditioning import STOPPED, conditioning
from mbh._harness.neutral.equations import JointEquations
from mbh._harness.neutral.mobility import independent_rows

#: Content hash → (redundant, all) joint equations at the assembled start, of the scenes seen.
_START_REDUNDANCY: dict[str, tuple[int, int]] = {}


def start_redundancy(mech: Mechanism) -> tuple[int, int]:
    """(redundant, all) joint equations of ``mech`` at its assembled start (full-pivot rank of
    the joint Jacobian, :func:`~mbh._harness.neutral.mobility.independent_rows`); kept per
    content hash."""
    kept = _START_REDUNDANCY.get(mech.content_hash) if mech.content_hash else None
    if kept is None:
        start = assemble(mech).states
        jacobian = JointEquations(mech).jacobian(start.position, start.quaternion)
        kept = (jacobian.shape[0] - len(independent_rows(jacobian)), jacobian.shape[0])
        if mech.content_hash:
            _START_REDUNDANCY[mech.content_hash] = kept
    return kept


def label_failure(mech: Mechanism, trajectory: Trajectory,
                  reference: Trajectory | None) -> Trajectory:
    """The trajectory with its reason prefixed by what the scene's geometry says about it.

    * A run that stopped (:data:`~mbh._harness.neutral.conditioning.STOPPED`) within
      :data:`~mbh._harness.neutral.conditioning.SINGULAR_WINDOW_S` of a near-singular position
      of the reference: "singular configuration (σ_r/σ_1 = … at t = … s in the reference):
      <reason>".
    * A run that did not end ``ok`` on a scene whose joint equations are redundant at the start:
      "; overconstrained loop: k of the n joint equations are redundant" appended.

    Parameters
    ----------
    trajectory : Trajectory
        The judged run (:func:`mbh._harness.measure.verdict.judge`); returned unchanged when ``ok``.
    reference : Trajectory or None
        The verified reference (without one, only the redundancy is checked, at the assembled
        start).
    """
    if trajectory.status == CaseStatus.OK:
        return trajectory
    reason = trajectory.reason or trajectory.status
    if (reference is not None and reference.n_samples and trajectory.status in STOPPED
            and trajectory.failure_time is not None):
        analysis = conditioning(mech, reference)
        passage = analysis.near(float(trajectory.failure_time))
        if passage is not None:
            reason = (f"singular configuration (the reference's σ_r/σ_1 of Φ_q dips to "
                      f"{analysis.ratio_at(passage):.2g} at t = {passage:.4g} s): {reason}")
    redundant, equations = start_redundancy(mech)
    if redundant:
        reason = (f"{reason}; overconstrained loop: {redundant} of the {equations} "
                  "joint equations are redundant")
    if reason == (trajectory.reason or trajectory.status):
        return trajectory
    return dataclasses.replace(trajectory, reason=reason)
