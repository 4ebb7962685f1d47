"""Scenario loading and validation: every problem reported at once, with file and field."""

from __future__ import annotations

import numpy as np
import pytest

from harness import cli, scenario
from harness.scenario import ScenarioError

BAD = """
kind = "spatial"
duration = "four seconds"
gravity = [0.0, -9.81]
[[bodies]]
name = "crank"
mass = -1.0
inertia = [1.0, 1.0, 5.0]
position = [0.0, 0.0, 0.0]
[[bodies]]
name = "crank"
mass = 1.0
inertia = [1.0, -2.0, 1.0]
position = [1.0, 0.0, 0.0]
[[joints]]
name = "O"
type = "hinge"
body1 = "ground"
body2 = "crank"
location = [0.0, 0.0, 0.0]
[[joints]]
name = "A"
type = "revolute"
body1 = "crank"
body2 = "nobody"
location = [0.0, 0.0, 0.0]
axis = [0.0, 0.0, 0.0]
"""

EXPECTED = [
    ("duration", "expected a finite number"),
    ("gravity", "expected a list of 3 numbers"),
    ("bodies[0].mass", "must be > 0"),
    ("bodies[0].inertia", "triangle inequality"),
    ("bodies[1].name", "duplicate name 'crank'"),
    ("bodies[1].inertia", "not positive definite"),
    ("joints[0].type", "unknown spatial joint type 'hinge'"),
    ("joints[1].body2", "unknown body 'nobody'"),
    ("joints[1].axis", "zero-length vector"),
    ("initial", "missing required section"),
]


def test_every_problem_is_reported_at_once_with_file_and_field(write_scenario):
    path = write_scenario("broken", BAD)
    with pytest.raises(ScenarioError) as error:
        scenario.load(path)
    problems = error.value.problems
    assert all(p.file == str(path) for p in problems)
    found = {(p.field, p.message) for p in problems}
    for field, fragment in EXPECTED:
        assert any(f == field and fragment in m for f, m in found), (field, fragment, found)


def test_missing_driver_and_wrong_driver_type(load_variant):
    with pytest.raises(ScenarioError) as error:
        load_variant("fourbar_spatial", [('driver = "O"', 'driver = "B"')])
    assert any(p.field == "initial.driver" and "spherical" in p.message for p in error.value.problems)
    with pytest.raises(ScenarioError) as error:
        load_variant("fourbar", [('driver = "O"\n', '')])
    assert any(p.field == "initial.driver" and "missing" in p.message for p in error.value.problems)


def test_not_toml_and_unknown_file(write_scenario, tmp_path):
    with pytest.raises(ScenarioError, match="not valid TOML"):
        scenario.load(write_scenario("garbage", "kind = = ="))
    with pytest.raises(ScenarioError, match="no such scenario file"):
        scenario.load("no_such_scenario")


def test_cli_reports_bad_file_without_traceback(write_scenario, capsys):
    path = write_scenario("broken", BAD)
    status = cli.main(["check", str(path)])
    out = capsys.readouterr()
    assert status != 0
    assert "Traceback" not in out.out + out.err
    assert f"{path}: bodies[0].mass: must be > 0" in out.out + out.err


@pytest.mark.parametrize("name", scenario.scenario_names())
def test_shipped_scenarios_declare_the_required_outputs(name):
    mech = scenario.load(name)
    names = {o.name for o in mech.outputs}
    assert {"crank_angle", "crank_rate"} <= names
    if "slider" in name:
        assert "slider_x" in names


def test_fourbar_parameters_follow_seeds():
    mech = scenario.load("fourbar")
    crank = mech.bodies[mech.body_index("crank")]
    assert crank.mass == 78.1 and crank.inertia[2, 2] == 26.0496
    coupler = mech.bodies[mech.body_index("coupler")]
    b, c = mech.joint("B").point2, mech.joint("C").point1
    assert abs(np.linalg.norm(b - c) - 4.0) < 1e-14 and coupler.mass == 156.2
    assert "16.0" in mech.notes  # the table-5 typo is recorded


def test_content_hash_changes_with_content(load_variant):
    original = scenario.load("fourbar")
    changed = load_variant("fourbar", [("value = -1200.0", "value = -1100.0")], stem="fourbar")
    assert original.content_hash != changed.content_hash
