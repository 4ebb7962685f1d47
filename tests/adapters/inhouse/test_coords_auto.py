"""``coords=auto``: the in-house run takes the smaller model, says which and why, and its row and
the report's model-size table carry the model it ran."""

from __future__ import annotations

import pandas as pd
import pytest

import mbh
from mbh._harness.report.summary import model_size_table
from tests.helpers import ball_pendulum

SIZE_COLUMNS = ("n_coordinates", "n_constraint_equations", "n_redundant_equations")


def run(scene, method: str, t_end: float = 0.1):
    return mbh.run_case(scene, adapter="inhouse", method=method, dt=1e-3, t_end=t_end)


def sizes(result) -> tuple:
    return tuple(result.row[column] for column in SIZE_COLUMNS)


@pytest.mark.parametrize("scene, joint, absolute", [
    # (θ, closure equations, redundant) against (q, Φ rows, redundant), counted by hand: the
    # four-bar's 3 revolute angles and one cut revolute (2 rows) against 3 bodies × 3 and 4
    # revolutes × 2; Bricard's 5 revolute angles and one cut revolute (5 rows, 1 redundant)
    # against 5 bodies × 7 and 6 revolutes × 5 + 5 normalisations.
    ("fourbar", (3, 2, 0), (9, 8, 0)),
    ("bricard", (5, 5, 1), (35, 35, 1)),
])
def test_auto_takes_the_smaller_model_and_says_why(scene, joint, absolute):
    chosen = run(scene, "rk4+direct:coords=auto")
    named = run(scene, "rk4+direct:coords=joint")
    assert chosen.status == named.status == "ok"
    note = chosen.trajectory.notes[0]
    assert note.startswith("coords=auto: joint coordinates, the smaller model "
                           f"({joint[0]} θ and {joint[1]} closure equation(s) against "
                           f"{absolute[0]} q and {absolute[1]} Φ rows)"), note
    assert sizes(chosen) == sizes(named) == joint
    # The same model and steps as coords=joint: the same numbers.
    assert chosen.row["main_output_error"] == named.row["main_output_error"]
    assert sizes(run(scene, "rk4+direct")) == absolute


@pytest.mark.parametrize("method", ["am2+baumgarte:coords=auto,loop=generated",
                                    "bdf2+direct:coords=auto,loop=compiled"])
def test_auto_keeps_absolute_coordinates_where_the_joint_model_has_no_such_loop(method):
    """No compiled joint-coordinate loop (with or without a generated right-hand side) for an
    implicit method."""
    result = run("fourbar", method)
    assert result.status == "ok"
    loop = method.rpartition("loop=")[2]
    assert result.trajectory.notes[0] == (
        f"coords=auto: absolute coordinates, as loop={loop} asks: the joint model is smaller "
        "(3 θ and 2 closure equation(s) against 9 q and 8 Φ rows) but has no such loop for this "
        "method")
    assert sizes(result) == (9, 8, 0)


@pytest.mark.parametrize("method,loop_note", [
    ("rk4+direct:coords=auto", ", on their compiled loop"),
    ("rk4+direct:coords=auto,loop=python", "; this method steps them in Python, slower per step "
                                           "than the absolute model's compiled loop"),
    ("bdf2+direct:coords=auto", "; this method steps them in Python, slower per step than the "
                                "absolute model's compiled loop")])
def test_auto_says_which_loop_steps_the_joint_model(method, loop_note):
    result = run("fourbar", method, t_end=0.01)
    assert result.status == "ok"
    assert result.trajectory.notes[0] == (
        "coords=auto: joint coordinates, the smaller model (3 θ and 2 closure equation(s) against "
        f"9 q and 8 Φ rows){loop_note}")


def test_auto_keeps_absolute_coordinates_where_the_tree_needs_a_ball_joint():
    """The ball pendulum's tree holds the ball joint, which has no joint coordinates here;
    coords=joint is unsupported there, auto runs the absolute model (2 bodies ×
    7 q; the revolute's 5 rows, the ball's 3 and 2 normalisations).  It declares no output: the
    run has no main-output error, and its other metrics stand."""
    mech = ball_pendulum()
    result = run(mech, "rk4+direct:coords=auto", t_end=0.01)
    assert result.status == "ok"
    note = result.trajectory.notes[0]
    assert note.startswith("coords=auto: absolute coordinates (14 q and 10 Φ rows): "), note
    assert "ball (spherical)" in note
    assert result.row["main_output"] is None and pd.isna(result.row["main_output_error"])
    assert result.row["max_constraint_violation"] < 1e-12  # measured 3.0e-16 (direct projects)
    assert run(mech, "rk4+direct:coords=joint", t_end=0.01).status == "unsupported"


def test_the_model_size_table_shows_both_in_house_models_with_their_own_cost():
    rows = [run("fourbar", method).row
            for method in ("rk4+direct", "rk4+direct:coords=joint", "rk4+baumgarte:coords=joint")]
    table = model_size_table(pd.DataFrame(rows), accuracy=1e-3)
    inhouse = [row for row in table.rows if row[1] == "inhouse"]
    assert [row[2:5] for row in inhouse] == [(3, 2, 0), (9, 8, 0)]
    joint, absolute = inhouse
    assert joint[7].startswith("joint coordinates: 3 θ")
    assert absolute[7].startswith("absolute coordinates: 9 q")
    per_step = {row["method"]: row["wall_time_per_step_s"] for row in rows}
    assert absolute[5] == per_step["rk4+direct"]
    assert joint[5] == pd.Series([per_step["rk4+direct:coords=joint"],
                                  per_step["rk4+baumgarte:coords=joint"]]).median()
