"""A run's machine-speed figure: the wall time of a fixed workload of the pinned numpy and scipy,
so that wall times of runs on different machines, or under different load, compare as ratios to
their run's figure (calibrated times: :mod:`mbh._harness.store.compare`, the history page, the reports).

It measures the machine, never this project's code: the workload calls numpy and scipy only, and
their versions (pinned in ``constraints.txt``) are part of its name (:func:`workload_name`), so two
figures compare only when their names are equal.  The calibration case it replaced was an in-house
run (the four-bar, rk4+direct at 5e-4 s), whose time followed the in-house code: it fell from
~1 s to ~26 ms as the compiled loop got faster, and every engine's calibrated time rose with each
such change although no engine had changed.

The workload mixes the two kinds of work a case does: small numpy arrays driven from Python
(:func:`scipy.integrate.solve_ivp` on a pendulum) and compiled dense algebra (LU solves of a stack
of 24 × 24 systems, the size of a planar mechanism's); its matrices are too small for BLAS to use
threads.  A campaign measures it beside one busy core: in its own process while the warm template
starts, else as the first case of its execution (:mod:`mbh._harness.run.calibration`; version 2;
version 1 ran it in a fresh interpreter before the cases, ~2 % slower on the development machine:
169.1 against 166.0 ms, medians of 6 alternating figures).
"""

from __future__ import annotations

import time

import numpy as np
import scipy

#: Timings of the workload; the figure is the fastest (the one least disturbed by other jobs).
REPEATS = 3

#: The workload's version: raised whenever :func:`_workload` or where a campaign runs it changes,
#: which makes earlier figures incomparable (:func:`workload_name`).
VERSION = 2


def workload_name() -> str:
    """What a figure measured: the workload's version and the numpy and scipy it ran on."""
    return f"solve_ivp+lu/{VERSION} numpy {np.__version__} scipy {scipy.__version__}"


def _pendulum(t: float, y: np.ndarray) -> np.ndarray:
    """(φ̇, φ̈) of a 1 m pendulum at angle φ (rad) and rate φ̇ (rad/s), g = 9.81 m/s²."""
    return np.array([y[1], -9.81 * np.sin(y[0])])


def _workload() -> None:
    from scipy.integrate import solve_ivp

    solve_ivp(_pendulum, (0.0, 50.0), [1.0, 0.0], method="RK45", rtol=1e-10, atol=1e-12)
    rng = np.random.default_rng(20261127)
    systems = rng.standard_normal((2000, 24, 24)) + 24.0 * np.eye(24)
    right_sides = rng.standard_normal((2000, 24, 1))
    for _ in range(10):
        np.linalg.solve(systems, right_sides)


def machine_speed_s() -> float:
    """The machine-speed figure, s: the fastest of :data:`REPEATS` timings of the workload
    (~0.1–0.2 s each on the 2-core development machine)."""
    times = []
    for _ in range(REPEATS):
        began = time.perf_counter()
        _workload()
        times.append(time.perf_counter() - began)
    return min(times)
