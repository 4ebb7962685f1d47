"""The reference routes along a declared branch (``harness/references/routes.py``) and the scenario
table that declares it, on the N-four-bar ``double_fourbar``.

The outside check is the one-degree-of-freedom model of ``tests/references/test_double_fourbar.py``
(3 φ̈ = −3.5 g cos φ, tip at (cos φ, sin φ)), which knows nothing of either route.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from tests.helpers import reduced_tip
from scipy.spatial.transform import Rotation

from mbh._harness.model import scenario
from mbh._harness.neutral.assembly import assemble
from mbh._harness.references.routes import (BranchEquations, BranchRouteError, full_route,
                                            reduced_route)
from mbh._harness.neutral.equations import JointEquations
from mbh._harness.model.outputs import output_series
from mbh._harness.references.build import (AGREEMENT_LIMIT, BRANCH_ROUTE_A, reference_info,
                                           reference_trajectory, route_difference)
from mbh._harness.model.scenario import ScenarioError


@pytest.fixture(scope="module")
def mech():
    return scenario.load("double_fourbar")


def tip_error(mech, trajectory) -> float:
    """Largest distance (m) of the first crank's tip from the one-degree-of-freedom model."""
    x, y = reduced_tip(trajectory.times)
    return float(np.hypot(output_series(mech, trajectory, "tip_x") - x,
                          output_series(mech, trajectory, "tip_y") - y).max())


def flattened_pose(mech):
    """The flattened configuration (every bar on the x axis, cranks pointing along +x)."""
    centres = {"crank1": 0.5, "coupler1": 1.5, "crank2": 1.5, "coupler2": 2.5, "crank3": 2.5}
    position = np.array([[centres[b.name], 0.0, 0.0] for b in mech.bodies])
    quaternion = np.tile(Rotation.identity().as_quat(scalar_first=True), (len(mech.bodies), 1))
    return position, quaternion


def test_branch_rows_keep_the_rank_through_the_flattened_position(mech):
    start = assemble(mech).states
    position, quaternion = flattened_pose(mech)
    joints = JointEquations(mech)
    assert np.abs(joints.residuals(position, quaternion)).max() < 1e-15
    plain = np.linalg.svd(joints.jacobian(position, quaternion), compute_uv=False)
    branch_rows = BranchEquations(mech, start)
    with_branch = np.linalg.svd(branch_rows.jacobian(position, quaternion), compute_uv=False)
    at_start = np.linalg.svd(branch_rows.jacobian(start.position, start.quaternion),
                             compute_uv=False)
    # The joints alone lose two ranks there (14 → 12: the mobility jumps from 1 to 3); with the
    # branch's two rows the rank is 14 both at the start and at the flattened position, and the
    # 14th singular value stays of order one (measured 0.39 there, 0.39 at the start).
    assert np.sum(plain > 1e-9 * plain[0]) == 12
    assert np.sum(with_branch > 1e-9 * with_branch[0]) == 14
    assert np.sum(at_start > 1e-9 * at_start[0]) == 14
    assert with_branch[13] > 0.1 and at_start[13] > 0.1


def test_both_routes_pass_the_first_singular_passage_on_the_one_dof_model(mech):
    short = dataclasses.replace(mech, duration=0.8)  # the first passage is at t = 0.71 s
    grid = np.arange(81) * 0.01
    for route in (reduced_route, full_route):
        # Measured: 1.5e-12 m (reduced) and 3.4e-12 m (full) over 1 s; bound 1e-10 m.  A route
        # that leaves the branch at the passage is off by > 1e-4 m (the RK4/RKN4 routes).
        assert tip_error(short, route(short, grid)) <= 1e-10


def test_shipped_reference_is_the_branch_routes_and_matches_the_one_dof_model(mech):
    info = reference_info(mech)
    assert info["route_a"] == list(BRANCH_ROUTE_A)
    assert info["agreement"]["max"] <= AGREEMENT_LIMIT
    # Measured: route A (full) 2.6e-11 m over the 10 s and ten singular passages, route B
    # (reduced) 4.7e-10 m (the one-degree-of-freedom model's own DOP853 error at rtol 1e-13 is
    # 1.6e-11 m); routes agree to 5.0e-10 m.  Bound 2e-10 m, 7.8x the reference's error.
    assert tip_error(mech, reference_trajectory(mech)) <= 2e-10


def test_a_scene_without_a_branch_has_no_branch_route():
    plain = scenario.load("fourbar")
    with pytest.raises(BranchRouteError, match="equal_joint_angles"):
        BranchEquations(plain, assemble(plain).states)


def test_neutral_routes_without_a_branch_follow_the_plain_joints():
    """``[reference] routes = "neutral"`` on a scene without singular passages: both routes on the
    joint rows alone.  Measured on the four-bar over 1 s: full vs reduced 5.6e-11 m, full vs the
    shipped in-house reference 5.5e-11 m (before the reduced route rebuilt its samples in time
    order it was 4.0 rad off: warm-started from the run's end, Newton found the other assembly).
    Over 0.3 s here: 2.2e-13 m; bound 1e-10 m."""
    plain = scenario.load("fourbar")
    mech = dataclasses.replace(plain, neutral_routes=True, duration=0.3)
    grid = np.arange(301) * 1e-3
    full, reduced = full_route(mech, grid), reduced_route(mech, grid)
    assert route_difference(mech, full, reduced)["max"] <= 1e-10
    shipped = reference_trajectory(plain)
    assert np.abs(shipped.position[:301] - full.position).max() <= 1e-10


def test_routes_key_is_validated(tmp_path):
    text = scenario.scenario_path("double_fourbar").read_text()
    path = tmp_path / "broken.toml"
    path.write_text(text.replace("[reference]", '[reference]\nroutes = "fastest"'))
    with pytest.raises(ScenarioError, match="reference.routes: expected 'inhouse' or 'neutral'"):
        scenario.load(path)
    path.write_text(text.replace("[reference]", '[reference]\nroutes = "neutral"'))
    assert scenario.load(path).neutral_routes


@pytest.mark.parametrize("value, message", [
    ('[["O1", "nowhere"]]', "unknown joint 'nowhere'"),
    ('[["O1", "O1"]]', "paired with itself"),
    ('[["O1"]]', "expected a pair of joint names"),
    ('"O1"', "expected a list of joint-name pairs"),
])
def test_the_reference_table_is_validated(tmp_path, value, message):
    text = scenario.scenario_path("double_fourbar").read_text()
    text = text.replace('equal_joint_angles = [["O1", "O2"], ["O1", "O3"]]',
                        f"equal_joint_angles = {value}")
    path = tmp_path / "broken.toml"
    path.write_text(text)
    with pytest.raises(ScenarioError) as error:
        scenario.load(path)
    assert "reference.equal_joint_angles" in str(error.value)
    assert message in str(error.value)
    assert str(path) in str(error.value) or "broken.toml" in str(error.value)
