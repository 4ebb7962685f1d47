"""One case from Python (mbh._harness.run.single.run_one, mbh.run_case): arguments checked up front
with every problem named, a built mechanism runs like a file, the row is a stored run's row."""

import pytest

from mbh._harness.model import scenario
from mbh._harness.model.builder import MechanismBuilder
from mbh._harness.run.single import CaseInputError, run_one
from mbh._harness.store.schema import CASE_COLUMNS


def test_every_bad_argument_is_named_at_once():
    with pytest.raises(CaseInputError) as raised:
        run_one("fourbar", "mujoco", "no_such_method", dt=3e-3, t_end=9.0, repetitions=0)
    named = [problem.split(":")[0] for problem in raised.value.problems]
    assert named == ["method", "t_end", "repetitions"]
    with pytest.raises(CaseInputError, match="adapter: unknown adapter 'nobody'"):
        run_one("fourbar", "nobody")
    with pytest.raises(CaseInputError, match="dt: step 0.002 s does not divide the duration 0.005 s"):
        run_one("fourbar", "mujoco", dt=2e-3, t_end=0.005)


def test_a_step_beyond_the_step_limit_is_refused_before_it_runs():
    # 4 s at 1e-300 s: a step that divides the grid, but 4e+300 steps (the limit is 1e+08)
    with pytest.raises(CaseInputError) as raised:
        run_one("fourbar", "mujoco", dt=1e-300)
    assert raised.value.problems == [
        "dt: step 1e-300 s would take 4e+300 steps to 4 s (at most 1e+08); give a larger step"]


def test_an_unknown_scene_is_the_loaders_error():
    with pytest.raises(scenario.ScenarioError, match="no such scenario file"):
        run_one("no_such_scene", "mujoco")


def test_a_result_carries_status_metrics_trajectory_and_a_stored_row():
    result = run_one("fourbar", "mujoco", "best", dt=1e-3, t_end=0.2)
    assert result.status == "ok" and result.reason == ""
    assert result.trajectory.position.shape == (21, 3, 3)  # 0.2 s every 10 ms, 3 bodies
    frame = result.to_frame()
    assert len(frame) == 1 and frame.loc[0, "case_id"] == "fourbar|mujoco|best|0.001|0.2"
    stored_only = {"run_id", "trajectory_file", "reused_from"}  # set when a run stores the row
    assert set(CASE_COLUMNS) - stored_only <= set(frame.columns)
    assert frame.loc[0, "reference"] == "verified"
    assert frame.loc[0, "main_output_error"] == result.metrics["output_errors"]["crank_angle"]


def test_a_built_mechanism_runs_under_its_own_name(tmp_path, monkeypatch):
    monkeypatch.setenv("MBH_CACHE_DIR", str(tmp_path))  # its reference is built there (~2 s)
    pendulum = (MechanismBuilder("bar_pendulum", kind="planar", plane="xy", duration=0.2,
                                 gravity=[0.0, -9.81, 0.0])
                .body("bar", mass=1.0, inertia=[0.0, 0.0833, 0.0833], position=[0.5, 0.0, 0.0])
                .joint("pivot", "revolute", body1="ground", body2="bar", location=[0.0, 0.0, 0.0])
                .initial(driver="pivot", value=0.0, rate=0.0)
                .output("angle", "joint_angle", joint="pivot")
                .build())
    result = run_one(pendulum, "pinocchio", "best", dt=1e-3)
    assert result.status == "ok", result.reason
    assert result.row["scenario"] == "bar_pendulum"
    assert result.row["scenario_hash"] == pendulum.content_hash
    assert list(tmp_path.glob("bar_pendulum-*.json"))
