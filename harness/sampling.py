"""Sample grids shared by every run, so that each sample lands on the reference grid."""

from __future__ import annotations

import numpy as np

from harness.reference import GRID_STEP


def sample_interval(dt: float) -> float:
    """The smallest multiple of ``dt`` (s) that is also a multiple of the reference grid step.

    Raises ValueError when none exists below 1000 steps (a step incommensurate with the grid).
    """
    for k in range(1, 1001):
        ratio = k * dt / GRID_STEP
        if ratio >= 1 - 1e-9 and abs(ratio - round(ratio)) < 1e-6:
            return k * dt
    raise ValueError(f"step {dt:g} s is incommensurate with the reference grid ({GRID_STEP:g} s)")


def sample_times(dt: float, t_end: float) -> np.ndarray:
    """Sample times from 0 to t_end (s), every :func:`sample_interval` (dt), shape (k,)."""
    interval = sample_interval(dt)
    count = int(np.floor(t_end / interval + 1e-9))
    grid_steps = round(interval / GRID_STEP)
    return np.arange(count + 1) * grid_steps * GRID_STEP
