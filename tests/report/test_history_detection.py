"""The detection rates of benchmarks/history_detection.py on 30 seeded random histories of 30
runs at the idle machine's measured noise (the script prints them over 100 at three noise
levels; docs/history.md): the done-when of issue 30 as numbers."""

from __future__ import annotations

import runpy
from types import SimpleNamespace

from tests.helpers import ROOT


def _benchmark() -> SimpleNamespace:
    """The script's names (it is not a package module)."""
    path = ROOT / "benchmarks" / "history_detection.py"
    return SimpleNamespace(**runpy.run_path(str(path), run_name="history_detection"))


def test_steps_found_at_their_run_and_noise_not_called_a_step():
    benchmark = _benchmark()
    counts = benchmark.measure(histories=30, runs=30, seed=11, sigma=benchmark.NOISE_LEVELS[0])
    time_step, error_step = counts["time"], counts["error"]
    # Over 100 histories the script measured 99/100 time steps and 100/100 error steps at their
    # run and no false alarm; 30 histories may miss one time step.
    assert time_step.at_run >= 29 and time_step.found == 30 and time_step.false_alarms == 0
    assert error_step.at_run == 30 and error_step.false_alarms == 0
    # One slow run (×3) called a step: measured 1 in 1000 histories at this noise (an outlier
    # beside a heavy-tailed run makes a two-run excursion); this seed holds that one.
    assert counts["noise_only"] == 0 and counts["outlier"] <= 1
