"""Where a scene is near-singular, and which failures happened there.

The conditioning of a configuration is σ_r/σ_1 of the joint Jacobian Φ_q (joint rows only, with
respect to the body twists, :meth:`mbh._harness.neutral.equations.JointEquations.jacobian`), r the rank
at the first sample: rows that are redundant everywhere (an overconstrained loop such as Bricard's)
do not make every instant singular, and a rank lost later shows as σ_r/σ_1 → 0.

A *near-singular position* is a local minimum of σ_r/σ_1 at or below :data:`SINGULAR_DROP` times
its median over the run (relative, so that a Jacobian whose rows mix very different scales, as in
Andrews' squeezer, is not singular everywhere).  A failure *at* it is one whose failure time lies
within :data:`SINGULAR_WINDOW_S` of such a minimum of the verified reference;
:func:`mbh._harness.measure.failure_label.label_failure` then says so in the run's reason
("singular configuration ..."), and for a scene whose joint equations are redundant it names the
overconstrained loop.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.signal import find_peaks

from mbh._harness.neutral.equations import JointEquations
from mbh._harness.model.mechanism import Mechanism
from mbh._harness.neutral.mobility import independent_rows
from mbh._harness.common.status import CaseStatus
from mbh._harness.model.trajectory import Trajectory

#: Fraction of its median at or below which a local minimum of σ_r/σ_1 counts as a near-singular
#: position.  On the shipped references the factor lies 4.7× above the shallowest passage and
#: 85× below the deepest dip of a scene without one (figures: docs/measurements.md, section
#: "Neutral dynamics").
SINGULAR_DROP = 1e-2
#: A failure within this many seconds of a near-singular position happened *at* it: five of the
#: largest steps a campaign uses (1e-2 s), so that an integrator that gives up a few steps before
#: or after the passage (IDA on double_fourbar: 0.7096 s, passage at 0.714 s) is placed there.
SINGULAR_WINDOW_S = 0.05
#: Statuses of a run that started and stopped (its failure time is known).
STOPPED = (CaseStatus.FAILED, CaseStatus.DIVERGED, CaseStatus.CRASHED, CaseStatus.TIMEOUT)


@dataclass(frozen=True)
class Conditioning:
    """σ_r/σ_1 of Φ_q along a trajectory.

    Attributes
    ----------
    times : ndarray, shape (n,)
        s.
    ratio : ndarray, shape (n,)
        σ_r/σ_1 of Φ_q (joint rows, no driver row) at each sample; 0 where σ_1 = 0.
    rank : int
        r: the rank of Φ_q at the first sample (:func:`mbh._harness.neutral.mobility.independent_rows`).
    n_rows : int
        Joint rows of Φ_q (n_rows − rank of them are redundant at the start).
    minima : ndarray of int
        Sample indices of the near-singular positions: local minima of ``ratio`` at or below
        ``threshold``, in time order.
    threshold : float
        :data:`SINGULAR_DROP` × the median of ``ratio``.
    """

    times: np.ndarray
    ratio: np.ndarray
    rank: int
    n_rows: int
    minima: np.ndarray
    threshold: float

    @property
    def minimum_times(self) -> np.ndarray:
        """Times of the near-singular positions, s."""
        return self.times[self.minima]

    def near(self, time: float) -> float | None:
        """The near-singular time within :data:`SINGULAR_WINDOW_S` of ``time`` (s), or None."""
        return nearest_passage(time, self.minimum_times)

    def ratio_at(self, time: float) -> float:
        """σ_r/σ_1 at the sample nearest ``time`` (s)."""
        return float(self.ratio[np.argmin(np.abs(self.times - time))])


def nearest_passage(time: float, minimum_times: np.ndarray) -> float | None:
    """The time in ``minimum_times`` (s) within :data:`SINGULAR_WINDOW_S` of ``time`` (s), or
    None."""
    if not len(minimum_times):
        return None
    nearest = float(minimum_times[np.argmin(np.abs(minimum_times - time))])
    return nearest if abs(nearest - time) <= SINGULAR_WINDOW_S else None


def conditioning(mech: Mechanism, trajectory: Trajectory, t_end: float | None = None
                 ) -> Conditioning:
    """σ_r/σ_1 of the joint Jacobian Φ_q along ``trajectory`` (up to ``t_end``, s); see the
    module docstring."""
    keep = trajectory.times <= (math.inf if t_end is None else t_end + 1e-9)
    times = trajectory.times[keep]
    jacobian = JointEquations(mech).jacobian(trajectory.position[keep],
                                             trajectory.quaternion[keep])
    if not len(times) or jacobian.shape[1] == 0:
        return Conditioning(times, np.ones(len(times)), 0, jacobian.shape[1],
                            np.zeros(0, dtype=int), SINGULAR_DROP)
    rank = len(independent_rows(jacobian[0]))
    singular_values = np.linalg.svd(jacobian, compute_uv=False)
    largest = singular_values[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(largest > 0, singular_values[:, max(rank, 1) - 1] / largest, 0.0)
    threshold = SINGULAR_DROP * float(np.median(ratio))
    dips, _ = find_peaks(-ratio, height=-threshold)
    return Conditioning(times, ratio, rank, jacobian.shape[1], dips, threshold)
