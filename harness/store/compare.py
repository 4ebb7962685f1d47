"""How every case changed between two stored runs: accuracy as error ratios, speed as
calibrated time ratios (each run's wall times divided by its own calibration case, so runs on
different machines or under different load compare), and status changes from or to ``ok``."""

from __future__ import annotations

import numpy as np
import pandas as pd

from mbh._harness.common.status import CaseStatus

#: Change classes of :func:`compare_runs`, in the order they are decided.
CHANGES = ("newly failing", "newly passing", "less accurate", "more accurate", "slower",
           "faster", "unchanged")


def _ratio(numerator: np.ndarray, denominator: np.ndarray) -> np.ndarray:
    """numerator / denominator with 0/0 = 1 and x/0 = inf (NaN stays NaN)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = numerator / denominator
    ratio[(numerator == 0) & (denominator == 0)] = 1.0
    return ratio


def _calibration(value, name: str) -> float:
    if value is None:
        return float("nan")
    value = float(value)
    if not value > 0:
        raise ValueError(f"{name} must be a positive time in s (or None), got {value!r}")
    return value


def comparable_calibrations(a, b) -> tuple[float | None, float | None]:
    """The machine-speed figures (:attr:`~mbh._harness.store.runs.RunStore.calibration_s`) of runs ``a``
    and ``b`` when the same workload measured both, else (None, None): their times are then not
    compared (a changed numpy or scipy, or a run calibrated before the workload)."""
    if a.calibration_workload is None or a.calibration_workload != b.calibration_workload:
        return None, None
    return a.calibration_s, b.calibration_s


def compare_runs(a: pd.DataFrame, b: pd.DataFrame, calibration_a: float | None,
                 calibration_b: float | None, error_factor: float = 10.0,
                 time_factor: float = 1.5, error_floor: float = 0.0) -> pd.DataFrame:
    """Classify how every case present in both runs changed from run ``a`` to run ``b``.

    Parameters
    ----------
    a, b : DataFrame
        Case rows (:meth:`mbh._harness.store.runs.RunStore.cases`): ``case_id``, ``scenario``, ``adapter``, ``method``,
        ``dt``, ``status``, ``main_output_error`` (rad or m), ``wall_time_s`` (s).
    calibration_a, calibration_b : float or None
        Each run's calibration time, s; None leaves the time ratio NaN.
    error_factor : float
        Error ratios above it are "less accurate", below its inverse "more accurate".
    time_factor : float
        Calibrated time ratios above it are "slower", below its inverse "faster".
    error_floor : float
        Errors below it count as equal to it (rad or m), so round-off-sized errors do not
        change class; 0 compares errors as they are.

    Returns
    -------
    DataFrame
        One row per common ``case_id`` (in ``a``'s order): ``case_id``, ``scenario``,
        ``adapter``, ``method``, ``dt``, ``status_a``, ``status_b``, ``main_output_error_a``,
        ``main_output_error_b``, ``error_ratio`` (b / a), ``wall_time_s_a``,
        ``wall_time_s_b``, ``time_ratio`` = (time_b / calibration_b) / (time_a /
        calibration_a), and ``change``, the first of :data:`CHANGES` that applies: a status
        change from/to ``ok``; for cases ``ok`` in both, the accuracy classes, then the speed
        classes; else "unchanged".
    """
    calib_a = _calibration(calibration_a, "calibration_a")
    calib_b = _calibration(calibration_b, "calibration_b")
    keep = ["case_id", "status", "main_output_error", "wall_time_s"]
    merged = a[["scenario", "adapter", "method", "dt", *keep]].merge(
        b[keep], on="case_id", how="inner", suffixes=("_a", "_b"))
    floor = float(error_floor)
    error_a = np.maximum(merged["main_output_error_a"].to_numpy(float, na_value=np.nan), floor)
    error_b = np.maximum(merged["main_output_error_b"].to_numpy(float, na_value=np.nan), floor)
    time_a = merged["wall_time_s_a"].to_numpy(float, na_value=np.nan) / calib_a
    time_b = merged["wall_time_s_b"].to_numpy(float, na_value=np.nan) / calib_b
    error_ratio = _ratio(error_b, error_a)
    time_ratio = _ratio(time_b, time_a)
    ok_a = (merged["status_a"] == CaseStatus.OK).to_numpy(bool)
    ok_b = (merged["status_b"] == CaseStatus.OK).to_numpy(bool)
    both = ok_a & ok_b
    change = np.select(
        [ok_a & ~ok_b, ~ok_a & ok_b,
         both & (error_ratio > error_factor), both & (error_ratio < 1.0 / error_factor),
         both & (time_ratio > time_factor), both & (time_ratio < 1.0 / time_factor)],
        CHANGES[:-1], default=CHANGES[-1])
    columns = ["case_id", "scenario", "adapter", "method", "dt", "status_a", "status_b",
               "main_output_error_a", "main_output_error_b", "wall_time_s_a", "wall_time_s_b"]
    result = merged[columns].copy()
    result.insert(9, "error_ratio", error_ratio)
    result["time_ratio"] = time_ratio
    result["change"] = change
    return result
