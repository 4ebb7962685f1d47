"""The evaluation grid: the sample times every case of a scenario is measured on.

Every error figure (outputs against the reference, constraint violations, energy balance) is
taken on one grid per scenario, whatever step a case uses, so maxima for different dt compare
like with like.  The grid is every :data:`EVALUATION_STEP` from 0 to the end time: 10 ms, the
seed's own step (Rouvinen 2003, ch. 7: Δt = 0.01 s) and a multiple of the reference grid step
(1 ms), so every sample lands on a reference sample.  Sampling every 10 ms resolves the seed's
motions (fastest body 69 rad/s: 0.69 rad per sample, below the π that unwrapping angles needs).
A faster scene declares a finer ``sample_step`` (``Mechanism.sample_step``, a multiple of 1 ms):
Andrews' squeezer turns its crank by up to 7.6 rad in 10 ms, which unwrapping would read 4π short
(and its energy balance 2π·0.033 J short), so it samples every 1 ms (≤ 1.4 rad).

A case's step dt must divide the evaluation step: an integer number of steps per sample, to a
relative 1e-9.
"""

from __future__ import annotations

import numpy as np

from mbh._harness.model.trajectory import Trajectory

#: Spacing of the reference grid, s: every reference is stored on this grid, and every sample
#: time of a case lands on it.
GRID_STEP = 1e-3
#: Spacing of the evaluation grid, s (a multiple of the reference grid step).
EVALUATION_STEP = 0.01
#: Relative tolerance on "integer number of steps per sample".
STEP_MATCH = 1e-9


def steps_per_sample(dt: float, step: float = EVALUATION_STEP) -> int:
    """Number of steps of size ``dt`` (s) between two evaluation samples ``step`` (s) apart.

    Raises
    ------
    ValueError
        When ``dt`` does not divide ``step``; the message names dt, the grid step and the valid
        choices.
    """
    ratio = step / dt if dt > 0 else 0.0
    count = round(ratio) if np.isfinite(ratio) else 0  # a subnormal dt overflows the ratio
    if count < 1 or abs(ratio - count) > STEP_MATCH * ratio:
        choices = ", ".join(f"{step / k:g}" for k in (1, 2, 4, 5, 10, 20, 100))
        raise ValueError(f"step dt = {dt:g} s does not divide the evaluation grid step "
                         f"{step:g} s: dt must be {step:g} s / k for an integer k ≥ 1 "
                         f"(e.g. {choices} s)")
    return count


def sample_times(dt: float, t_end: float, step: float = EVALUATION_STEP) -> np.ndarray:
    """Evaluation sample times from 0 to t_end (s), every ``step`` (s), shape (k,).

    ``dt`` (s) is checked by :func:`steps_per_sample`; the last sample is the last grid time not
    after ``t_end``.  The times are multiples of the reference grid step, rounded to it.
    """
    steps_per_sample(dt, step)
    count = int(np.floor(t_end / step + 1e-9))
    return np.arange(count + 1) * round(step / GRID_STEP) * GRID_STEP


#: Sample times within this of a reference grid point match it, s.
TIME_MATCH = 1e-9


def reference_indices(reference: Trajectory, times: np.ndarray) -> np.ndarray:
    """Indices of ``times`` (s, shape (k,)) in the reference grid, shape (k,).

    Raises
    ------
    ValueError
        When a time is not on the reference grid (within :data:`TIME_MATCH`).
    """
    index = np.clip(np.searchsorted(reference.times, times - TIME_MATCH), 0,
                    reference.n_samples - 1)
    off = np.abs(reference.times[index] - times) > TIME_MATCH
    if np.any(off):
        raise ValueError(f"sample time {times[off][0]:.9g} s is not on the reference grid "
                         f"(step {reference.times[1] - reference.times[0]:g} s)")
    return index
