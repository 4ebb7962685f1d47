"""`mbh bench`'s reading of measurements (harness/jobs/bench.py, the front table of the report): the
arithmetic on given rows, and the parts that run cheaply.  No wall time is asserted."""

from __future__ import annotations

import math

import pandas as pd
import pytest

from mbh._harness.jobs import bench
from mbh._harness.cli import main
from mbh._harness.report.summary import front_ratio_table


def _case(adapter, method, dt, error, wall, status="ok"):
    return {"scenario": "fourbar", "adapter": adapter, "method": method, "dt": dt,
            "main_output_error": error, "wall_time_s": wall, "status": status,
            "case_id": f"{adapter}-{method}-{dt}"}


def test_front_ratio_reads_each_side_fastest_case_reaching_the_level():
    cases = pd.DataFrame([
        _case("inhouse", "rk4+direct", 1e-2, 3e-5, 0.02),
        _case("inhouse", "rk4+direct", 1e-3, 4e-10, 0.20),
        _case("mujoco", "best", 1e-3, 5e-5, 0.05),
        _case("mujoco", "best", 1e-4, 6e-8, 0.50),
        _case("pinocchio", "best", 1e-3, 1e-9, 0.90),
        _case("pinocchio", "best", 1e-4, 1e-11, 9.0, status="failed"),
    ])
    table = front_ratio_table(cases, "fourbar", levels=(1e-4, 1e-7, 1e-9, 1e-11))
    rows = {row[0]: row for row in table.rows}
    assert rows[1e-4][1:4] == ("rk4+direct", 0.01, 0.02) and rows[1e-4][4] == "mujoco"
    assert rows[1e-4][-1] == pytest.approx(0.02 / 0.05)
    assert rows[1e-7][-1] == pytest.approx(0.20 / 0.50)
    assert rows[1e-9][4:8] == ("pinocchio", "best", 0.001, 0.9)
    assert rows[1e-9][-1] == pytest.approx(0.20 / 0.90)
    # A failed case reaches nothing; neither side reaches 1e-11.
    assert rows[1e-11][1:] == (None,) * 8


def test_scaling_exponent_is_the_log_log_slope_from_n_4():
    rows = [{"N": n, "s_per_sim_s": 0.1 * n ** 1.5 if n >= 4 else 99.0} for n in (1, 2, 4, 8, 16)]
    assert bench._exponent(rows) == pytest.approx(1.5, abs=1e-12)
    assert bench._exponent(rows[:3]) is None  # one point from N = 4 on


def test_overhead_rows_of_the_compiled_inhouse_loop():
    """Both sides measured; the ratio is their quotient (not a bound on it: a timing)."""
    (row,) = bench.overhead_rows(adapters=["inhouse"], scenarios=["fourbar"], methods=["best"],
                                 dt=1e-3, t_end=0.05, repeats=1)
    assert row["note"] == "" and row["adapter_us_per_step"] > 0 and row["bare_us_per_step"] > 0
    assert row["ratio"] == pytest.approx(row["adapter_us_per_step"] / row["bare_us_per_step"])
    assert row["read_back_us_per_sample"] > 0


def test_a_python_path_method_has_no_bare_loop_and_says_so():
    (row,) = bench.overhead_rows(adapters=["inhouse"], scenarios=["fourbar"],
                                 methods=["abm4+direct"], dt=1e-3, t_end=0.02, repeats=1)
    assert row["ratio"] is None and "runs on the Python path" in row["note"]
    assert math.isfinite(row["adapter_us_per_step"])


def test_unknown_bench_part_is_refused_by_name(capsys):
    assert main(["bench", "--parts", "front,speedometer"]) == 2
    assert "--parts: unknown part(s) speedometer" in capsys.readouterr().err


def test_fallback_rows_count_the_calls_the_kernels_served():
    """fourbar's generated right-hand side serves every call (measured: no guard fails there)."""
    (row,) = bench.fallback_rows(scenarios=["fourbar"], dt=1e-3, t_end=0.05)
    assert (row["scenario"], row["status"], row["kernel_calls"], row["rhs_evals"]) == \
        ("fourbar", "ok", 0, 200)
    assert row["fraction"] == 0.0 and row["note"] == ""
