"""One campaign case → one flat row: columns, statuses, the reference column, and the model size
every adapter reports."""

from __future__ import annotations

import json
import math

import pytest

import mbh
from mbh._adapters import get_adapter
from mbh._harness.run import row as case_row
from mbh._harness.model import scenario
from mbh._harness.run.spec import CaseSpec
from mbh._harness.run.row import error_row, run_spec
from mbh._harness.references.build import ReferenceBuildError
from mbh._harness.measure.verdict import DEFAULT_BOUNDS
from tests.outside.mechanisms import floating_pair

#: Columns every row carries (the interface of issue 10), besides error_/final_<output>.
REQUIRED = {
    "case_id", "scenario", "scenario_hash", "adapter", "adapter_version", "method", "dt", "t_end",
    "repetitions", "status", "reason", "failure_time", "accurate", "main_output",
    "main_output_error", "wall_time_s", "wall_time_per_sim_s", "wall_time_per_step_s",
    "wall_times_s", "steps", "rhs_evals", "counters", "notes", "n_coordinates",
    "n_constraint_equations", "n_redundant_equations", "model_notes", "max_constraint_violation",
    "max_velocity_violation", "max_energy_error_J", "max_energy_error_rel", "reference", "packages",
}
SCALAR = (str, float, int, bool, type(None))
#: A cheap verified case: MuJoCo best on the four-bar, 0.2 s at dt 1e-2 s (20 steps).
CHEAP = CaseSpec("fourbar", "mujoco", "best", 1e-2, 0.2, repetitions=2)


@pytest.fixture(scope="module")
def cheap_row():
    return run_spec(CHEAP, DEFAULT_BOUNDS, accuracy=1e-3)


def test_row_has_every_column_as_a_scalar(cheap_row):
    row = cheap_row.row
    outputs = [o.name for o in scenario.load("fourbar").outputs]
    assert REQUIRED | {f"error_{n}" for n in outputs} | {f"final_{n}" for n in outputs} <= set(row)
    assert {key: value for key, value in row.items() if not isinstance(value, SCALAR)} == {}


def test_row_values(cheap_row):
    row, trajectory = cheap_row.row, cheap_row.trajectory
    assert (row["case_id"], row["status"], row["reference"]) == \
        (CHEAP.case_id, "ok", "verified")
    assert row["main_output"] == "crank_angle"
    assert row["main_output_error"] == row["error_crank_angle"]
    # measured: 1.25e-7 rad after 0.2 s at dt 1e-2 s, 8000 times below the 1e-3 rad threshold
    assert 0 < row["main_output_error"] < 1e-3 and row["accurate"] is True
    assert run_spec(CHEAP, DEFAULT_BOUNDS, accuracy=1e-9).row["accurate"] is False
    assert row["steps"] == 20 and trajectory.n_samples == 21
    walls = json.loads(row["wall_times_s"])
    assert len(walls) == 2 and row["wall_time_s"] == pytest.approx(sum(walls) / 2)  # median
    assert row["wall_time_per_step_s"] == pytest.approx(row["wall_time_s"] / 20)
    assert json.loads(row["counters"]) == {"rhs_evals": 80}
    assert set(json.loads(row["packages"])) == {"numpy", "scipy", "engine"}
    assert row["adapter_version"] == json.loads(row["packages"])["engine"]
    assert (row["n_coordinates"], row["n_constraint_equations"], row["n_redundant_equations"]) \
        == (3, 3, 1)


def test_a_refused_reference_runs_without_one(monkeypatch):
    # The refusal is simulated: the shipped double_fourbar's real refusal depends on the state of
    # the reference cache, and a stale record would start a build of several minutes.
    def refuse(mech):
        raise ReferenceBuildError(f"{mech.name}: routes disagree")

    monkeypatch.setattr(case_row, "reference_trajectory", refuse)
    row = run_spec(CaseSpec("fourbar", "inhouse", "best", 1e-2, 0.1), DEFAULT_BOUNDS, 1e-3).row
    assert row["reference"] == "none: fourbar: routes disagree"
    assert row["status"] == "ok"
    assert row["accurate"] is None and math.isnan(row["main_output_error"])
    assert math.isfinite(row["max_constraint_violation"])


def test_an_unsupported_case_is_a_row():
    row = run_spec(CaseSpec("fourbar", "inhouse", "rk4+newton-euler", 1e-2, 0.1),
                   DEFAULT_BOUNDS, 1e-3).row
    assert row["status"] == "unsupported" and "spatial" in row["reason"]
    assert row["accurate"] is False and row["samples"] == 0
    assert math.isnan(row["max_constraint_violation"])


def test_error_row_has_the_same_columns(cheap_row):
    row = error_row(CHEAP, "timeout", "ran past 120 s")
    assert set(row) == set(cheap_row.row)
    assert (row["status"], row["reason"], row["accurate"]) == ("timeout", "ran past 120 s", False)
    assert math.isnan(row["main_output_error"]) and math.isnan(row["error_crank_angle"])
    assert {key: value for key, value in row.items() if not isinstance(value, SCALAR)} == {}


#: (coordinates, constraint rows, redundant rows) each engine reports for each shipped scene,
#: read off the engines' own models (MuJoCo nq and equality efc rows, Pinocchio nq and constraint
#: residual sizes, Bullet joint coordinates and point-to-point rows, Exudyn ODE2/AE sizes with the
#: rank of its own ∂AE/∂q, the in-house q and Φ rows with rank from full-pivot elimination).  The
#: closure redundancy of the tree engines is the topology's count (a planar revolute closed by a
#: 3-row point constraint: one row too many per loop).  Exudyn's ∂AE/∂q separates clearly: its
#: smallest nonzero singular value is ≈ 2.0 on every scene, the zero ones ≤ 1e-35.
MODEL_SIZES = {
    "inhouse": {"fourbar": (9, 8, 0), "fourbar_spatial": (21, 20, 0), "slider_crank": (21, 20, 0),
                "slider_crank_planar": (9, 8, 0), "double_fourbar": (15, 14, 0)},
    "mujoco": {"fourbar": (3, 3, 1), "fourbar_spatial": (4, 3, 0), "slider_crank": (4, 3, 0),
               "slider_crank_planar": (3, 3, 1), "double_fourbar": (5, 6, 2)},
    "pinocchio": {"fourbar": (3, 3, 1), "fourbar_spatial": (4, 3, 0), "slider_crank": (4, 3, 0),
                  "slider_crank_planar": (3, 3, 1), "double_fourbar": (5, 6, 2)},
    "pybullet": {"fourbar": (3, 3, 1), "fourbar_spatial": (4, 3, 0), "slider_crank": (4, 3, 0),
                 "slider_crank_planar": (3, 3, 1), "double_fourbar": (5, 6, 2)},
    "exudyn": {"fourbar": (9, 8, 0), "fourbar_spatial": (21, 22, 2), "slider_crank": (21, 23, 3),
               "slider_crank_planar": (9, 8, 0), "double_fourbar": (15, 14, 0)},
}


@pytest.mark.parametrize("adapter_name, name", [(a, s) for a, scenes in MODEL_SIZES.items()
                                                for s in scenes])
def test_model_size(adapter_name, name):
    adapter = get_adapter(adapter_name)
    size = adapter.model_size(adapter.build(scenario.load(name)))
    assert (size["coordinates"], size["constraint_equations"], size["redundant_equations"]) == \
        MODEL_SIZES[adapter_name][name]
    assert isinstance(size["notes"], str) and size["notes"]


@pytest.mark.parametrize("engine", ["mujoco", "pinocchio", "pybullet"])
def test_a_mechanism_with_no_joint_to_ground_is_unsupported_by_tree_builders(engine):
    """Two bodies hinged together and to nothing else: the in-house engine and Exudyn run it;
    the engines that build a tree of joints from the ground cannot (it was 'failed', a
    ValueError of the spanning tree, where a mechanism an adapter cannot build is
    'unsupported')."""
    result = mbh.run_case(floating_pair(), engine, "best", dt=1e-3, t_end=0.01)
    assert result.status == "unsupported"
    assert "the system graph is disconnected" in result.reason
    assert result.reason.startswith(f"{engine} builds its model as a tree of joints")
