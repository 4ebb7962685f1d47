"""The machine-speed figure: what it times, that runs compare only under the same workload, and
how an execution carries the calibration beside its cases."""

from __future__ import annotations

import math

import numpy as np
import scipy

from mbh._harness.common.machine_speed import machine_speed_s, workload_name
from mbh._harness.run.calibration import (CALIBRATION, WithCalibration, calibration_work,
                                          store_figure)
from mbh._harness.run.spec import CaseSpec
from mbh._harness.store.compare import comparable_calibrations
from mbh._harness.store.runs import RunStore


class _Campaign:
    name, path, cases, sweep, text = "tiny", "tiny.toml", (), None, ""


def test_the_figure_is_a_positive_time_named_by_the_numpy_and_scipy_it_ran_on():
    seconds = machine_speed_s()
    assert math.isfinite(seconds) and seconds > 0
    assert f"numpy {np.__version__}" in workload_name()
    assert f"scipy {scipy.__version__}" in workload_name()


def test_the_calibration_case_reports_the_figure_and_its_workload():
    row, trajectory = calibration_work(CALIBRATION)
    assert trajectory is None and row["status"] == "ok" and row["wall_time_s"] > 0
    assert row["workload"] == workload_name()


def test_a_run_stored_without_a_workload_has_no_figure_and_compares_no_times(tmp_path):
    """A manifest written before the workload (an in-house calibration case) has
    ``calibration_s`` but no ``calibration_workload``: its figure is not used."""
    old, new = RunStore.create(_Campaign(), tmp_path), RunStore.create(_Campaign(), tmp_path)
    old.manifest["calibration_s"] = 0.026  # what the in-house case gave, without a workload
    new.set_calibration(0.2)
    assert old.calibration_s is None and new.calibration_s == 0.2
    assert new.calibration_workload == workload_name()
    assert comparable_calibrations(old, new) == (None, None)
    assert comparable_calibrations(new, new) == (0.2, 0.2)


def test_figures_of_different_workloads_are_not_compared(tmp_path):
    a, b = RunStore.create(_Campaign(), tmp_path), RunStore.create(_Campaign(), tmp_path)
    a.set_calibration(0.2, "solve_ivp+lu/1 numpy 1.0 scipy 1.0")
    b.set_calibration(0.3)
    assert (a.calibration_s, b.calibration_s) == (0.2, 0.3)
    assert comparable_calibrations(a, b) == (None, None)


def test_an_execution_with_the_calibration_routes_it_and_the_cases_apart():
    other = CaseSpec("fourbar", "inhouse", "best", 1e-2, 0.2)
    work = WithCalibration(lambda spec: ({"case_id": spec.case_id, "status": "case"}, None))
    row, _ = work(CALIBRATION)
    assert row["workload"] == workload_name() and row["wall_time_s"] > 0
    assert work(other)[0] == {"case_id": other.case_id, "status": "case"}


def test_a_calibration_that_fails_leaves_the_run_without_a_figure_and_says_so(tmp_path):
    said = []
    failed = RunStore.create(_Campaign(), tmp_path)
    store_figure(failed, {"status": "crashed", "reason": "worker process killed by SIGKILL",
                          "wall_time_s": float("nan")}, said.append)
    assert failed.calibration_s is None
    assert said == ["mbh: calibration case ended crashed (worker process killed by SIGKILL); "
                    "this run has no machine-speed figure"]
    measured = RunStore.create(_Campaign(), tmp_path)
    store_figure(measured, {"status": "ok", "wall_time_s": 0.16, "workload": workload_name()},
                 said.append)
    assert measured.calibration_s == 0.16 and len(said) == 1
