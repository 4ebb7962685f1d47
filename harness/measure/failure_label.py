"""Where a failed run failed, in the scene's terms: at a near-singular position of the verified
reference, on an overconstrained loop (:mod:`mbh._harness.neutral.conditioning` says where a
scene is near-singular).

The redundant joint equations are counted at the shared start
(:func:`mbh._harness.neutral.start.initial_state`, assembled once per scene and kept; the warm
template assembles it for every case forked from it): ~1 ms, against ~5–9 ms when each failed case
assembled the start again.  The reference's conditioning (an SVD of Φ_q at every reference sample,
up to 0.5 s a scene) is kept per frozen reference (:func:`reference_conditioning`) and computed by
the warm template for the scenes with many cases (:data:`CONDITION_AHEAD_CASES`).
"""

from __future__ import annotations

import dataclasses

from mbh._harness.common.status import CaseStatus
from mbh._harness.measure.per_reference import per_reference, read_only
from mbh._harness.model.mechanism import Mechanism
from mbh._harness.model.trajectory import Trajectory
from mbh._harness.neutral.conditioning import STOPPED, Conditioning, conditioning
from mbh._harness.neutral.equations import JointEquations
from mbh._harness.neutral.mobility import independent_rows
from mbh._harness.neutral.start import initial_state


def start_redundancy(mech: Mechanism) -> tuple[int, int]:
    """(redundant, all) joint equations of ``mech`` at its shared start (full-pivot rank of the
    joint Jacobian, :func:`~mbh._harness.neutral.mobility.independent_rows`)."""
    start = initial_state(mech)
    jacobian = JointEquations(mech).jacobian(start.position, start.quaternion)
    return jacobian.shape[0] - len(independent_rows(jacobian)), jacobian.shape[0]


#: Cases of one scene in a campaign from which the warm template computes the scene's
#: conditioning before its first fork (:mod:`mbh._harness.run.warm`).  Measured 2026-11-30: on
#: every fourth case of the nightly, each of the 58 failed cases of 282 computed it again, 92 ms a
#: case, a sixth of the campaign's per-case overhead; ahead, the ten shipped scenes take 1.0 s
#: (Bricard 0.48 s, slider_crank 0.18 s), which delays a campaign's first case, and the smoke
#: campaign (5–12 cases a scene, few failed) took 5.2–5.8 s instead of 4.7–5.0 s.  Ahead pays
#: from about two failed cases of a scene; the shipped campaigns with 30 or more cases a scene
#: have several.
CONDITION_AHEAD_CASES = 20


@per_reference
def reference_conditioning(mech: Mechanism, reference: Trajectory) -> Conditioning:
    """:func:`~mbh._harness.neutral.conditioning.conditioning` of ``reference``, kept per frozen
    reference (:mod:`mbh._harness.measure.per_reference`), its arrays read-only."""
    found = conditioning(mech, reference)  # arrays of its own, none a view of the reference's
    return dataclasses.replace(found, times=read_only(found.times), ratio=read_only(found.ratio),
                               minima=read_only(found.minima))


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
        analysis = reference_conditioning(mech, reference)
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
