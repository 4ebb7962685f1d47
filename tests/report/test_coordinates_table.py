"""The in-house formulation in both coordinates side by side (harness/report/coordinates.py, in
the report and in ``mbh bench``'s front): its reading of given case rows."""

from __future__ import annotations

import pandas as pd
import pytest

from mbh._harness.report.coordinates import coordinates_table, model_of, without_coords

ABSOLUTE = "absolute coordinates: 12 q, 11 Φ rows of rank 11"
JOINT = "joint coordinates: 3 θ (…), 2 closure equation(s) at cut joint(s) D of rank 2, 0 redundant"


def _case(adapter, method, dt, error, per_step, status="ok", notes="", size=(3, 2)):
    return {"scenario": "fourbar", "adapter": adapter, "method": method, "dt": dt,
            "main_output_error": error, "wall_time_per_step_s": per_step, "status": status,
            "case_id": f"{adapter}-{method}-{dt}", "model_notes": notes,
            "n_coordinates": size[0], "n_constraint_equations": size[1]}


def _absolute(method, dt, error, per_step, status="ok"):
    return _case("inhouse", method, dt, error, per_step, status, ABSOLUTE, (12, 11))


def _joint(method, dt, error, per_step, status="ok"):
    return _case("inhouse", method, dt, error, per_step, status, JOINT, (3, 2))


def test_options_and_notes_are_read():
    assert without_coords("ab5+baumgarte:coords=joint") == "ab5+baumgarte"
    assert without_coords("rk4+direct:proj_tol=1e-12,coords=auto,loop=python") == \
        "rk4+direct:proj_tol=1e-12,loop=python"
    assert without_coords("best") == "best"
    assert (model_of(ABSOLUTE), model_of(JOINT), model_of("MuJoCo nq = 4"), model_of(None)) == \
        ("absolute", "joint", None, None)


def test_each_model_of_a_paired_method_gets_its_cost_error_and_largest_ok_step():
    cases = pd.DataFrame([
        _absolute("ab5+baumgarte", 1e-2, None, 3e-6, status="diverged"),
        _absolute("ab5+baumgarte", 5e-3, 2e-6, 4e-6),
        _absolute("ab5+baumgarte", 1e-3, 3e-9, 6e-6),
        _absolute("ab5+baumgarte", 1e-4, 1e-12, 5e-6),
        _joint("ab5+baumgarte:coords=joint", 1e-2, 4e-5, 20e-6),
        _joint("ab5+baumgarte:coords=joint", 1e-3, 5e-9, 30e-6),
        # coords=auto lands on the side its notes name; a method in one model only is left out.
        _joint("rk4+direct:coords=auto", 1e-3, 7e-10, 50e-6),
        _absolute("rk4+direct", 1e-3, 6e-10, 10e-6),
        _absolute("rk8+direct", 1e-3, 1e-12, 40e-6),
        _case("mujoco", "best", 1e-3, 5e-7, 8e-6, notes="MuJoCo nq = 4", size=(4, 2)),
        _case("mujoco", "best", 1e-2, None, None, status="failed", notes="MuJoCo nq = 4",
              size=(4, 2)),
    ])
    table = coordinates_table(cases, "fourbar")
    assert table.columns[-2:] == ("status at 0.001 s", "error at 0.001 s")
    rows = {(row[0], row[1]): row[2:] for row in table.rows}
    assert list(rows) == [("inhouse absolute", "ab5+baumgarte"),
                          ("inhouse joint", "ab5+baumgarte:coords=joint"),
                          ("inhouse absolute", "rk4+direct"),
                          ("inhouse joint", "rk4+direct:coords=auto"),
                          ("mujoco", "best")]
    # coordinates, equations, median µs per ok step, largest ok step, status and error at 1e-3.
    assert rows["inhouse absolute", "ab5+baumgarte"] == pytest.approx((12, 11, 5.0, 5e-3, "ok",
                                                                       3e-9))
    assert rows["inhouse joint", "ab5+baumgarte:coords=joint"] == pytest.approx(
        (3, 2, 25.0, 1e-2, "ok", 5e-9))
    assert rows["mujoco", "best"] == pytest.approx((4, 2, 8.0, 1e-3, "ok", 5e-7))


def test_the_equal_step_is_the_smallest_every_in_house_row_ran():
    cases = pd.DataFrame([
        _absolute("rk4+direct", 1e-2, 1e-5, 5e-6),
        _absolute("rk4+direct", 1e-4, 1e-13, 5e-6),
        _joint("rk4+direct:coords=joint", 1e-2, None, None, status="diverged"),
        _joint("rk4+direct:coords=joint", 1e-3, 2e-9, 9e-6),
        _case("mujoco", "best", 1e-3, 5e-7, 8e-6, notes="MuJoCo nq = 4"),
    ])
    rows = {row[0]: row for row in coordinates_table(cases, "fourbar").rows}
    assert rows["inhouse joint"][-2:] == ("diverged", None)
    assert rows["inhouse joint"][5] == 1e-3  # its largest ok step
    assert rows["mujoco"][-2:] == ("not run", None)


def test_no_table_without_a_method_in_both_coordinates():
    cases = pd.DataFrame([_absolute("rk4+direct", 1e-3, 1e-9, 5e-6),
                          _joint("ab5+baumgarte:coords=joint", 1e-3, 1e-9, 9e-6)])
    assert coordinates_table(cases, "fourbar") is None
