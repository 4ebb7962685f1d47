"""Synthetic campaign histories for the history tests: :class:`mbh._harness.report.history.History`
objects built in memory, with the noise measured on this machine.

Calibrated-time noise: ``exp(σ · t₃ / √3)`` with σ = 0.036 (natural log, per run), the spread
of two runs of the smoke campaign on the idle machine (benchmarks/history_detection.py,
docs/history.md); errors repeat to the bit between runs (measured on 289 stored cases), here with
a 1 % jitter so that nothing rests on exact equality.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from mbh._harness.report.history import History

#: Measured per-run noise of the log of calibrated time on the idle machine (see above).
IDLE_TIME_NOISE = 0.036
#: Relative jitter put on the synthetic errors.
ERROR_JITTER = 0.01


@dataclass
class CaseSeries:
    """One case over the runs: its identity and per-run values (arrays of the history's length).

    ``status`` and ``version`` default to ``ok`` and ``"1.0"`` throughout.
    """

    case_id: str
    scenario: str
    adapter: str
    method: str
    dt: float
    error: np.ndarray
    time: np.ndarray
    status: list = field(default_factory=list)
    version: list = field(default_factory=list)


def noisy_times(rng: np.random.Generator, runs: int, level: float = 0.01,
                sigma: float = IDLE_TIME_NOISE) -> np.ndarray:
    """Calibrated times with the measured noise, shape (runs,)."""
    return level * np.exp(sigma * rng.standard_t(3, runs) / np.sqrt(3.0))


def jittered_errors(rng: np.random.Generator, runs: int, level: float = 1e-6) -> np.ndarray:
    """Errors (rad) with a 1 % jitter, shape (runs,)."""
    return level * (1.0 + ERROR_JITTER * rng.standard_normal(runs))


def case(rng: np.random.Generator, runs: int, method: str = "rk4+direct", dt: float = 1e-3,
         scenario: str = "fourbar", adapter: str = "inhouse") -> CaseSeries:
    """A steady case: measured-level time noise, jittered errors, always ``ok``."""
    return CaseSeries(f"{scenario}|{adapter}|{method}|{dt:g}|1.0", scenario, adapter, method, dt,
                      jittered_errors(rng, runs), noisy_times(rng, runs))


def history(cases: list[CaseSeries], runs: int, campaign: str = "synthetic") -> History:
    """A history of ``runs`` runs holding ``cases`` (calibration 1 s, so the calibrated time is
    the wall time; commits ``c000…`` numbered by run)."""
    run_rows = [{"run_id": f"2026010{1 + i // 24}T{i % 24:02d}0000Z-{campaign}",
                 "started": f"2026-01-0{1 + i // 24}T{i % 24:02d}:00:00+00:00",
                 "status": "complete", "commit": f"c{i:011d}", "calibration_s": 1.0,
                 "packages": {}} for i in range(runs)]
    rows = []
    for series in cases:
        for run in range(runs):
            status = series.status[run] if series.status else "ok"
            rows.append({"run": run, "case_id": series.case_id, "scenario": series.scenario,
                         "adapter": series.adapter, "method": series.method, "dt": series.dt,
                         "status": status,
                         "adapter_version": series.version[run] if series.version else "1.0",
                         "main_output_error": series.error[run],
                         "max_constraint_violation": series.error[run] / 10,
                         "max_energy_error_rel": series.error[run] / 100,
                         "wall_time_s": series.time[run], "calibrated_time": series.time[run]})
    return History(campaign, None, pd.DataFrame(run_rows), pd.DataFrame(rows))
