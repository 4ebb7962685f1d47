"""Steps in one series of positive values over runs (errors, calibrated times): a penalised
piecewise-constant fit (``ruptures``' PELT) on the log of the values, scaled by the series' own
noise, then each step kept only if it is both large enough and certain enough.

A series is a 1-D array of positive values in run order (one value per run in which the case
ended ``ok``).  The fit runs on ``log10(max(value, floor))``:

1. **noise**: a robust standard deviation of one value around its level,
   ``1.4826 · MAD(diff(y)) / √2`` (successive differences are free of the level, and the median
   ignores the few differences a step or an outlier makes; :func:`noise_level`), never below the
   rule's ``noise_floor``;
2. **fit**: PELT (Killick et al. 2012, ``ruptures.Pelt``) on ``y / noise`` with the rule's cost
   (``l1``, the median's cost, for noisy series: a one-run outlier does not pay for a segment of
   its own; ``l2`` for series that repeat to the bit, where a one-run change is a change) and a
   penalty per breakpoint of :data:`PENALTY` ``· log(n)``;
3. **keep**: each breakpoint is judged between its neighbouring segments: the size is the ratio of
   the segment medians (after / before), the confidence ``erf(z / √2)`` with
   ``z = |Δ median| / (noise · √(π/2) · √(1/n_before + 1/n_after))`` (the median's standard error
   under Gaussian noise).  The weakest breakpoint that is smaller than the rule's ``min_factor`` or
   less certain than :data:`CONFIDENCE` is dropped and its neighbours are judged again, until every
   step left passes both.

The rules' figures are measured: see :data:`TIME` and :data:`ERROR`, and docs/history.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import ruptures

__all__ = ["SeriesRule", "Step", "TIME", "ERROR", "PENALTY", "CONFIDENCE", "noise_level",
           "detect_steps"]

#: PELT's penalty per breakpoint, times log(n), on data in units of its noise.  With the
#: confidence filter it sets how eagerly candidates are proposed: benchmarks/history_detection.py
#: gives 0 false alarms in 100 noise-only histories of 30 runs at 2.5, and a 20 % step found at
#: its run in 100 of 100 at the idle machine's noise.
PENALTY = 2.5
#: Least confidence of a step that is reported (1 − the chance that noise alone makes it).
CONFIDENCE = 0.999


@dataclass(frozen=True)
class SeriesRule:
    """How one kind of series is fitted.

    Attributes
    ----------
    cost : str
        ``"l1"`` (robust to single-run outliers) or ``"l2"``.
    min_run : int
        Fewest runs of a segment: 2 makes a one-run excursion an outlier, not a step (a step on the
        last run is then seen one run later); 1 takes every sustained or one-run change.
    min_factor : float
        Least size of a step (ratio of levels, > 1 either way).
    noise_floor : float
        Least noise, decades of the value (log10).
    floor : float
        Values below it count as it (same unit as the values), so round-off-sized values do not
        make steps.
    """

    cost: str
    min_run: int
    min_factor: float
    noise_floor: float
    floor: float


#: Calibrated wall times.  Noise measured on this 2-core machine from stored smoke and hard runs
#: (log of calibrated time, per case, per run): σ = 0.036 (0.016 decades) between two runs on an
#: idle machine, 0.22-0.38 with other jobs on the cores, tails up to ×7-17 on single cases of a
#: few ms; hence the robust cost, two runs per segment, the idle figure as floor, and steps of at
#: least 10 %.
TIME = SeriesRule(cost="l1", min_run=2, min_factor=1.1, noise_floor=0.015, floor=1e-12)
#: Errors (main output, constraint violation, energy): equal to the bit between runs of the same
#: code (245 hard and 44 smoke cases over three runs and two commits: every ratio 1.0), so a
#: change from one run on is real; a factor of 2 is the least that counts, and errors below
#: 1e-13 (rad, m or relative) count as 1e-13.
ERROR = SeriesRule(cost="l2", min_run=1, min_factor=2.0, noise_floor=0.01, floor=1e-13)


@dataclass(frozen=True)
class Step:
    """One step of a series.

    Attributes
    ----------
    index : int
        Position in the series of the first value at the new level.
    factor : float
        Level after / level before (ratio of the segments' medians, in the values' unit).
    confidence : float
        1 − the chance that noise of the measured level makes a step this large, in [0, 1].
    before, after : float
        The segments' levels: ``10 ** median(log10 values)`` (the values' unit; below the rule's
        floor the floor).
    n_before, n_after : int
        Values in the segments.
    """

    index: int
    factor: float
    confidence: float
    before: float
    after: float
    n_before: int
    n_after: int


def noise_level(logs: np.ndarray, floor: float = 0.0) -> float:
    """Robust standard deviation of one value around its level: ``1.4826 · MAD(diff) / √2``.

    Parameters
    ----------
    logs : ndarray, shape (n,)
        The series (log10 of the values).
    floor : float
        Least value returned.

    Returns
    -------
    float
        Noise, in the unit of ``logs``; ``floor`` for fewer than three values.

    Notes
    -----
    Both medians are the lower median (of an even count, the smaller middle value), so that in a
    short history the one difference a step makes cannot be taken for the noise: of three runs
    ``[a, a, 100 a]`` the noise is 0 (then the floor), not half the step.
    """
    differences = np.diff(np.asarray(logs, float))
    if len(differences) < 2:
        return float(floor)
    centre = np.percentile(differences, 50, method="lower")
    spread = np.percentile(np.abs(differences - centre), 50, method="lower")
    return max(float(floor), 1.4826 * float(spread) / math.sqrt(2.0))


def _judge(logs: np.ndarray, start: int, index: int, end: int, noise: float) -> tuple:
    """(log size, confidence) of the step at ``index`` between segments [start, index) and
    [index, end)."""
    before, after = np.median(logs[start:index]), np.median(logs[index:end])
    spread = noise * math.sqrt(math.pi / 2.0) * math.sqrt(1.0 / (index - start)
                                                          + 1.0 / (end - index))
    return float(after - before), math.erf(abs(after - before) / spread / math.sqrt(2.0))


def _prune(logs: np.ndarray, breaks: list[int], noise: float, rule: SeriesRule) -> list[int]:
    """``breaks`` without the steps too small or too uncertain (weakest dropped first)."""
    least = math.log10(rule.min_factor)
    breaks = list(breaks)
    while breaks:
        edges = [0, *breaks, len(logs)]
        judged = [(*_judge(logs, edges[i], edges[i + 1], edges[i + 2], noise), i)
                  for i in range(len(breaks))]
        failing = [(confidence, abs(size), i) for size, confidence, i in judged
                   if abs(size) < least or confidence < CONFIDENCE]
        if not failing:
            return breaks
        breaks.pop(min(failing)[2])
    return breaks


def detect_steps(values, rule: SeriesRule) -> list[Step]:
    """The steps of a series of positive values (see the module docstring).

    Parameters
    ----------
    values : array_like, shape (n,)
        Positive finite values in run order (errors in rad, m or relative; calibrated times).
    rule : SeriesRule
        :data:`TIME` or :data:`ERROR` (or one of your own).

    Returns
    -------
    list of Step
        In series order; empty for fewer than ``2 · rule.min_run`` values.

    Raises
    ------
    ValueError
        For a value that is not finite or not positive (the caller leaves those out).
    """
    values = np.asarray(values, float)
    if values.ndim != 1 or not np.all(np.isfinite(values)) or np.any(values < 0):
        raise ValueError("a series for detect_steps must be 1-D, finite and not negative")
    if len(values) < 2 * rule.min_run:
        return []
    logs = np.log10(np.maximum(values, rule.floor))
    noise = noise_level(logs, rule.noise_floor)
    algorithm = ruptures.Pelt(model=rule.cost, min_size=rule.min_run, jump=1)
    fitted = algorithm.fit((logs / noise).reshape(-1, 1))
    breaks = _prune(logs, fitted.predict(pen=PENALTY * math.log(len(logs)))[:-1], noise, rule)
    edges = [0, *breaks, len(logs)]
    steps = []
    for i, index in enumerate(breaks):
        start, end = edges[i], edges[i + 2]
        size, confidence = _judge(logs, start, index, end, noise)
        steps.append(Step(index=index, factor=10.0 ** size, confidence=confidence,
                          before=10.0 ** float(np.median(logs[start:index])),
                          after=10.0 ** float(np.median(logs[index:end])),
                          n_before=index - start, n_after=end - index))
    return steps
