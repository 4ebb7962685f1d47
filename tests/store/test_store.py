"""The result store (mbh._harness.store.runs): rows, parts, resume, cache, migration, listing, comparison.

The committed fixture ``tests/data/store_v1/`` is a run written by :func:`write_v1_store` below,
the schema-1 writer kept only here.  Regenerate it with
``.venv/bin/python -m tests.store.test_store``.
"""

from __future__ import annotations

import json
import math
import shutil
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

import mbh
from mbh._harness.common import environment
from mbh._harness.store import compare as run_compare
from mbh._harness.store import runs as store
from mbh._harness.store.cache import UNCACHED_STATUSES, CaseCache
from mbh._harness.store.location import ROOT_ENV
from mbh._harness.store.manifest import list_runs
from mbh._harness.run.spec import load_campaign
from mbh._harness.store.schema import SCHEMA_VERSION, SchemaError
from mbh._harness.model.trajectory import Trajectory
from tests.helpers import DATA
from tests.store.store_cases import SPECS, campaign, row_for, trajectory

V1_ROOT = DATA / "store_v1"
V1_RUN = "20260101T000000Z-v1demo"


@pytest.fixture
def root(tmp_path, monkeypatch) -> Path:
    results = tmp_path / "results"
    monkeypatch.setenv(ROOT_ENV, str(results))
    return results


# --- rows -----------------------------------------------------------------------------------

def test_rows_round_trip_with_missing_non_finite_and_markup(root):
    run = store.RunStore.create(campaign())
    a, b, c = SPECS[:3]
    run.add(row_for(a, main_output_error=float("nan"), failure_time=None, accurate=None,
                    steps=None, reason='<b>"x" & y</b>\nnext line', error_crank_angle=float("inf"),
                    extra=np.float64(-math.inf), counters=json.dumps({"rhs_evals": 4})), None)
    run.add(row_for(b, status="diverged", failure_time=np.float64(0.25), accurate=False,
                    steps=np.int64(7), error_crank_angle=2.5, extra=None, only_here="ok"), None)
    run.add(row_for(c, accurate=True, failure_time=1, error_crank_angle=None), None)

    run.finish("complete")
    for frame in (run.cases(), mbh.load_run(run.run_id),
                  pd.read_parquet(run.path / "cases.parquet")):  # a reader without the store
        frame = frame.set_index("case_id")
        assert list(frame.index) == [a.case_id, b.case_id, c.case_id]
        assert (frame["run_id"] == run.run_id).all()
        assert np.isnan(frame.loc[a.case_id, "main_output_error"])
        assert frame.loc[a.case_id, "error_crank_angle"] == math.inf
        assert frame.loc[a.case_id, "extra"] == -math.inf
        assert np.isnan(frame.loc[b.case_id, "extra"])
        assert np.isnan(frame.loc[c.case_id, "error_crank_angle"])
        assert frame.loc[a.case_id, "reason"] == '<b>"x" & y</b>\nnext line'
        assert pd.isna(frame.loc[a.case_id, "failure_time"])
        assert frame.loc[b.case_id, "failure_time"] == 0.25
        assert frame.loc[c.case_id, "failure_time"] == 1.0
        assert pd.isna(frame.loc[a.case_id, "only_here"])
        assert frame.loc[b.case_id, "only_here"] == "ok"
        assert json.loads(frame.loc[a.case_id, "counters"]) == {"rhs_evals": 4}
    frame = run.cases().set_index("case_id")
    # integer and boolean columns stay integer/boolean with a missing value among them
    assert frame["steps"].dtype == pd.Int64Dtype() and frame["accurate"].dtype == pd.BooleanDtype()
    assert pd.isna(frame.loc[a.case_id, "steps"]) and frame.loc[b.case_id, "steps"] == 7
    assert pd.isna(frame.loc[a.case_id, "accurate"]) and frame.loc[c.case_id, "accurate"]
    assert not frame.loc[b.case_id, "accurate"]


def test_rows_must_be_flat_scalars_of_the_declared_types(root):
    run = store.RunStore.create(campaign())
    with pytest.raises(TypeError, match="'counters'.*dict"):
        run.add(row_for(SPECS[0], counters={"rhs_evals": 4}), None)
    with pytest.raises(TypeError, match="'dt'"):
        run.add(row_for(SPECS[0], dt="0.001"), None)
    with pytest.raises(ValueError, match="case_id"):
        run.add({"status": "ok"}, None)
    assert run.cases().empty and run.done_case_ids() == set()


def test_an_undeclared_column_keeps_one_type_across_parts(root):
    run = store.RunStore.create(campaign())
    run.add(row_for(SPECS[0], error_x=None, flag=True), None)
    run.add(row_for(SPECS[1], error_x=1, flag=None), None)
    run.add(row_for(SPECS[2], error_x=0.5), None)  # integer and float mix
    reopened = store.RunStore.open(run.run_id)  # learns the types from the stored parts
    with pytest.raises(TypeError, match="'error_x': a string value.*hold double"):
        reopened.add(row_for(SPECS[3], error_x="n/a"), None)
    with pytest.raises(TypeError, match="'flag': a double value.*hold bool"):
        run.add(row_for(SPECS[3], flag=0.5), None)
    frame = reopened.cases()
    assert list(frame["error_x"].iloc[1:]) == [1.0, 0.5] and np.isnan(frame["error_x"].iloc[0])
    assert frame["flag"].iloc[0] and pd.isna(frame["flag"].iloc[1])


def test_an_empty_run_reads_as_an_empty_frame_with_the_declared_columns(root):
    frame = store.RunStore.create(campaign()).cases()
    assert frame.empty and {"case_id", "status", "wall_time_s", "dt"} <= set(frame.columns)


def test_stray_temp_files_are_ignored_and_parts_keep_numbering(root):
    run = store.RunStore.create(campaign())
    run.add(row_for(SPECS[0]), None)
    # what a writer killed mid-write leaves behind: a dot-prefixed temp name, half written
    (run.path / "cases" / ".part-000001.parquet.tmp-999-1").write_bytes(b"PAR1 truncated")
    run.add(row_for(SPECS[1]), None)
    assert [p.name for p in run._cases.parts()] == ["part-000000.parquet", "part-000001.parquet"]
    assert list(run.cases()["case_id"]) == [SPECS[0].case_id, SPECS[1].case_id]


def test_a_case_stored_twice_counts_once_keeping_the_first(root):
    run = store.RunStore.create(campaign())
    run.add(row_for(SPECS[0], status="ok"), None)
    run.add(row_for(SPECS[1]), None)
    run.add(row_for(SPECS[0], status="failed"), None)
    frame = run.cases()
    assert list(frame["case_id"]) == [SPECS[0].case_id, SPECS[1].case_id]
    assert frame["status"].iloc[0] == "ok"


# --- trajectories -----------------------------------------------------------------------------

def test_trajectories_round_trip(root):
    run = store.RunStore.create(campaign())
    stored = trajectory(status="diverged", reason="state exploded", failure_time=0.01,
                        wall_time_s=0.5, steps=12, notes=["redundant closure: 1 equation"],
                        counters={"rhs_evals": np.int64(48), "factorizations": 3})
    run.add(row_for(SPECS[1], status="diverged"), stored)
    run.add(row_for(SPECS[0]), None)
    back = run.trajectory(SPECS[1].case_id)
    for name in ("times", "position", "quaternion", "velocity", "angular_velocity"):
        np.testing.assert_array_equal(getattr(back, name), getattr(stored, name))
    assert (back.status, back.reason, back.failure_time, back.wall_time_s, back.steps) == \
        ("diverged", "state exploded", 0.01, 0.5, 12)
    assert back.counters == {"rhs_evals": 48, "factorizations": 3}
    assert back.notes == ["redundant closure: 1 equation"]
    frame = run.cases().set_index("case_id")
    assert (run.path / frame.loc[SPECS[1].case_id, "trajectory_file"]).is_file()
    assert pd.isna(frame.loc[SPECS[0].case_id, "trajectory_file"])
    with pytest.raises(KeyError, match="no trajectory"):
        run.trajectory(SPECS[0].case_id)


def test_an_empty_trajectory_round_trips(root):
    run = store.RunStore.create(campaign())
    run.add(row_for(SPECS[2], status="unsupported"),
            Trajectory.empty(3, status="unsupported", reason="no prismatic joint"))
    back = run.trajectory(SPECS[2].case_id)
    assert back.position.shape == (0, 3, 3) and back.quaternion.shape == (0, 3, 4)
    assert back.status == "unsupported" and back.reason == "no prismatic joint"


# --- manifest, resume -------------------------------------------------------------------------

def test_manifest_records_the_run(root):
    run = store.RunStore.create(campaign())
    manifest = json.loads((run.path / "manifest.json").read_text())
    assert manifest["run_id"] == run.run_id and run.run_id.endswith("Z-demo")
    assert manifest["status"] == "running" and manifest["ended"] is None
    assert manifest["schema_version"] == SCHEMA_VERSION
    assert manifest["campaign_text"] == campaign().text
    assert manifest["n_cases"] == len(SPECS)
    assert set(manifest["scenario_hashes"]) == {"fourbar", "slider_crank"}
    assert all(len(h) == 64 for h in manifest["scenario_hashes"].values())
    assert manifest["packages"]["numpy"] == np.__version__
    assert set(manifest["packages"]) == set(environment.RECORDED_PACKAGES)
    assert manifest["machine"]["cpu_count"] >= 1
    assert set(manifest["git"]) == {"commit", "dirty"}
    assert manifest["calibration_s"] is None

    run.set_calibration(2.5)
    with pytest.raises(ValueError, match="positive"):
        run.set_calibration(0.0)
    with pytest.raises(ValueError, match="run status"):
        run.finish("done")
    run.finish("complete")
    reopened = store.RunStore.open(run.run_id)
    assert reopened.calibration_s == 2.5
    assert reopened.manifest["status"] == "complete" and reopened.manifest["ended"]


def test_a_shipped_campaign_makes_a_run(root):
    shipped = load_campaign("smoke")
    run = store.RunStore.create(shipped)
    manifest = store.RunStore.open(run.run_id).manifest
    assert manifest["campaign_text"] == shipped.path.read_text(encoding="utf-8")
    assert set(manifest["scenario_hashes"]) == {case.scenario for case in shipped.cases}
    assert manifest["n_cases"] == len(shipped.cases)
    for spec in shipped.cases:
        run.add(row_for(spec), trajectory())
    assert run.done_case_ids() == {spec.case_id for spec in shipped.cases}
    spec = shipped.cases[-1]
    np.testing.assert_array_equal(run.trajectory(spec.case_id).times, trajectory().times)
    cache = CaseCache()
    cache.put(spec, "h", "1", "s", row_for(spec), None)
    assert cache.lookup(spec, "h", "1", "s")[0]["case_id"] == spec.case_id


def test_git_state_without_git_is_unknown(monkeypatch):
    monkeypatch.setenv("PATH", "")
    assert environment.git_state() == {"commit": None, "dirty": None}


def test_runs_created_in_the_same_second_get_distinct_ids(root):
    ids = {store.RunStore.create(campaign()).run_id for _ in range(3)}
    assert len(ids) == 3


def test_resume_completes_with_no_duplicate_and_no_missing_case(root):
    first = store.RunStore.create(campaign())
    for spec in SPECS[:2]:
        first.add(row_for(spec), trajectory())
    first.finish("interrupted")

    resumed = store.RunStore.open(first.run_id)
    done = resumed.done_case_ids()
    assert done == {SPECS[0].case_id, SPECS[1].case_id}
    resumed.mark_running()
    assert store.RunStore.open(first.run_id).manifest["status"] == "running"
    for spec in SPECS:
        if spec.case_id not in done:
            resumed.add(row_for(spec), trajectory())
    resumed.finish("complete")

    frame = store.load_run(first.run_id)
    assert sorted(frame["case_id"]) == sorted(spec.case_id for spec in SPECS)
    assert not frame["case_id"].duplicated().any()
    assert sorted(pd.read_parquet(first.path / "cases.parquet")["case_id"]) == \
        sorted(frame["case_id"])


def test_opening_a_missing_run_names_the_runs_there_are(root):
    run = store.RunStore.create(campaign())
    with pytest.raises(FileNotFoundError, match=f"no run 'nope'.*{run.run_id}"):
        store.RunStore.open("nope")


def test_list_runs_oldest_first(root):
    runs = [store.RunStore.create(campaign(name)) for name in ("a", "b", "c")]
    # start times against name order, so an order by run id or by folder would fail
    for run, started in zip(runs, ("2026-03-01T00:00:00.000000+00:00",
                                   "2026-02-01T00:00:00.000000+00:00",
                                   "2026-01-01T00:00:00.000000+00:00")):
        run.manifest["started"] = started
        run._write_manifest()
    (root / "cache").mkdir()  # the cache folder is not a run
    assert [m["campaign"] for m in list_runs()] == ["c", "b", "a"]
    assert [m["campaign"] for m in mbh.list_runs(root)] == ["c", "b", "a"]


def test_sweep_rows_have_their_own_table(root):
    run = store.RunStore.create(campaign())
    run.add_sweep({"sweep_id": "fourbar|mujoco|best", "scenario": "fourbar", "largest_dt": 0.005})
    run.add_sweep({"sweep_id": "fourbar|mujoco|default", "scenario": "fourbar",
                   "largest_dt": None})
    frame = run.sweeps()
    assert list(frame["largest_dt"].iloc[:1]) == [0.005] and np.isnan(frame["largest_dt"].iloc[1])
    assert run.cases().empty


# --- cache ------------------------------------------------------------------------------------

def test_cache_hits_an_identical_case_and_misses_on_every_key_part(root):
    cache = CaseCache()
    spec = SPECS[1]
    row = row_for(spec, error_crank_angle=float("nan"), accurate=None, steps=None)
    stored = trajectory(wall_time_s=0.1)
    assert cache.lookup(spec, "hash0", "1.0", "s0") is None
    cache.put(spec, "hash0", "1.0", "s0", row, stored, run_id="run-1")

    hit_row, hit_trajectory = cache.lookup(spec, "hash0", "1.0", "s0")
    assert hit_row["reused_from"] == "run-1"
    for key, value in row.items():
        same = (value == hit_row[key]) or (value != value and hit_row[key] != hit_row[key])
        assert same, key
    np.testing.assert_array_equal(hit_trajectory.position, stored.position)

    other = {"adapter": "mujoco", "method": "rk4+direct", "dt": 0.005, "t_end": 2.0}
    misses = [(spec, "hash1", "1.0", "s0"), (spec, "hash0", "1.1", "s0"),
              (spec, "hash0", "1.0", "s1")] + [
        (replace(spec, **{part: value}), "hash0", "1.0", "s0")
        for part, value in other.items()]
    for key in misses:
        assert cache.lookup(*key) is None, key
    # the scenario name is not part of the key: the content hash is
    renamed = replace(spec, scenario="fourbar_copy")
    assert cache.lookup(renamed, "hash0", "1.0", "s0") is not None


def test_cache_keeps_the_first_entry_and_skips_machine_dependent_statuses(root):
    cache = CaseCache()
    spec = SPECS[0]
    cache.put(spec, "h", "1", "s", row_for(spec, wall_time_s=1.0), None)
    cache.put(spec, "h", "1", "s", row_for(spec, wall_time_s=9.0), None)
    hit_row, hit_trajectory = cache.lookup(spec, "h", "1", "s")
    assert hit_row["wall_time_s"] == 1.0 and hit_trajectory is None
    assert hit_row["reused_from"] == "cache"
    for status in UNCACHED_STATUSES:
        cache.put(spec, "h", status, "s", row_for(spec, status=status), None)
        assert cache.lookup(spec, "h", status, "s") is None
    assert not [p for p in (root / "cache").iterdir() if p.name.startswith(".")]


def test_a_cached_row_stored_again_carries_the_new_run_id(root):
    run = store.RunStore.create(campaign())
    cache = CaseCache()
    spec = SPECS[0]
    run.add(row_for(spec), trajectory())
    cache.put(spec, "h", "1", "s", row_for(spec), trajectory(), run_id=run.run_id)
    again = store.RunStore.create(campaign())
    hit_row, hit_trajectory = cache.lookup(spec, "h", "1", "s")
    again.add(hit_row, hit_trajectory)
    frame = again.cases()
    assert frame["run_id"].iloc[0] == again.run_id and frame["reused_from"].iloc[0] == run.run_id


# --- schema migration -----------------------------------------------------------------------

def write_v1_store(root: Path) -> None:
    """Write the schema-1 run :data:`V1_RUN` under ``root`` (see mbh._harness.store.schema).

    Schema 1: rows with ``wall_time`` (no ``wall_time_s``, no per-step or per-simulated-second
    time), part files without a version in their metadata, a manifest without
    ``calibration_s``.
    """
    run = root / V1_RUN
    shutil.rmtree(run, ignore_errors=True)
    (run / "cases").mkdir(parents=True)
    manifest = {"schema_version": 1, "run_id": V1_RUN, "campaign": "v1demo",
                "campaign_path": "campaigns/v1demo.toml", "campaign_text": "[x]\n",
                "n_cases": 3, "started": "2026-01-01T00:00:00.000000+00:00",
                "ended": "2026-01-01T00:01:00.000000+00:00", "status": "complete",
                "git": {"commit": None, "dirty": None}, "packages": {}, "machine": {},
                "scenario_hashes": {"fourbar": "0" * 64}}
    (run / "manifest.json").write_text(json.dumps(manifest, indent=2))
    rows = [row_for(SPECS[0], wall_time=2.0, steps=1000),
            row_for(SPECS[1], wall_time=0.5, steps=100, main_output_error=None),
            row_for(SPECS[2], status="unsupported", wall_time=0.0, steps=0,
                    main_output_error=None)]
    for index, row in enumerate(rows):
        del row["wall_time_s"]
        row["run_id"] = V1_RUN
        pq.write_table(pa.Table.from_pylist([row]), run / "cases" / f"part-{index:06d}.parquet")


def test_a_schema_1_store_reads_migrated():
    run = store.RunStore.open(V1_RUN, root=V1_ROOT)
    assert run.manifest["schema_version"] == SCHEMA_VERSION == 2
    assert run.manifest["created_schema_version"] == 1
    assert run.calibration_s is None
    frame = run.cases().set_index("case_id")
    assert "wall_time" not in frame.columns
    assert list(frame["wall_time_s"]) == [2.0, 0.5, 0.0]
    assert list(frame["wall_time_per_step_s"].iloc[:2]) == [2.0 / 1000, 0.5 / 100]
    assert np.isnan(frame["wall_time_per_step_s"].iloc[2])  # no step taken
    assert list(frame["wall_time_per_sim_s"]) == [2.0 / 1.0, 0.5 / 1.0, 0.0 / 0.5]
    assert [m["run_id"] for m in list_runs(V1_ROOT)] == [V1_RUN]


def test_a_schema_1_run_resumed_by_this_code_reads_as_one_table(tmp_path):
    shutil.copytree(V1_ROOT, tmp_path / "v1")
    run = store.RunStore.open(V1_RUN, root=tmp_path / "v1")
    run.add(row_for(SPECS[3], wall_time_s=4.0, wall_time_per_step_s=0.004,
                    wall_time_per_sim_s=8.0), None)
    run.set_calibration(1.5)  # rewrites the manifest at schema 2
    again = store.RunStore.open(V1_RUN, root=tmp_path / "v1")
    assert again.manifest["created_schema_version"] == 1 and again.calibration_s == 1.5
    frame = again.cases()
    assert list(frame["wall_time_s"]) == [2.0, 0.5, 0.0, 4.0]
    assert list(frame["wall_time_per_step_s"].iloc[[0, 3]]) == [2.0 / 1000, 0.004]


def test_a_newer_schema_is_refused_by_name(root):
    run = store.RunStore.create(campaign())
    run.manifest["schema_version"] = SCHEMA_VERSION + 1
    run._write_manifest()
    with pytest.raises(SchemaError, match=f"manifest.json: schema version {SCHEMA_VERSION + 1}"):
        store.RunStore.open(run.run_id)


# --- comparison -------------------------------------------------------------------------------

def frame_of(rows: list[dict]) -> pd.DataFrame:
    return pd.DataFrame([{"scenario": "s", "adapter": "e", "method": "m", "dt": 0.01, **row}
                         for row in rows])


def test_compare_runs_classifies_every_change():
    before = frame_of([
        {"case_id": "fails", "status": "ok", "main_output_error": 1e-6, "wall_time_s": 1.0},
        {"case_id": "passes", "status": "diverged", "main_output_error": None, "wall_time_s": 1.0},
        {"case_id": "worse", "status": "ok", "main_output_error": 1e-6, "wall_time_s": 1.0},
        {"case_id": "better", "status": "ok", "main_output_error": 1e-6, "wall_time_s": 1.0},
        {"case_id": "slower", "status": "ok", "main_output_error": 1e-6, "wall_time_s": 1.0},
        {"case_id": "faster", "status": "ok", "main_output_error": 1e-6, "wall_time_s": 1.0},
        {"case_id": "same", "status": "ok", "main_output_error": 1e-6, "wall_time_s": 1.0},
        {"case_id": "still failing", "status": "failed", "main_output_error": None,
         "wall_time_s": 1.0},
        {"case_id": "only in a", "status": "ok", "main_output_error": 1e-6, "wall_time_s": 1.0},
    ])
    # run b's machine is twice as slow (calibration 2 s against 1 s): a doubled wall time is
    # no change, a doubled calibrated time needs 4x the wall time
    after = frame_of([
        {"case_id": "same", "status": "ok", "main_output_error": 5e-6, "wall_time_s": 2.0},
        {"case_id": "fails", "status": "diverged", "main_output_error": 1e-9, "wall_time_s": 2.0},
        {"case_id": "passes", "status": "ok", "main_output_error": 1e-6, "wall_time_s": 2.0},
        {"case_id": "worse", "status": "ok", "main_output_error": 1.1e-5, "wall_time_s": 2.0},
        {"case_id": "better", "status": "ok", "main_output_error": 0.9e-7, "wall_time_s": 8.0},
        {"case_id": "slower", "status": "ok", "main_output_error": 1e-6, "wall_time_s": 3.1},
        {"case_id": "faster", "status": "ok", "main_output_error": 1e-6, "wall_time_s": 1.3},
        {"case_id": "still failing", "status": "diverged", "main_output_error": None,
         "wall_time_s": 2.0},
        {"case_id": "only in b", "status": "ok", "main_output_error": 1e-6, "wall_time_s": 1.0},
    ])
    result = run_compare.compare_runs(before, after, 1.0, 2.0).set_index("case_id")
    assert result["change"].to_dict() == {
        "fails": "newly failing", "passes": "newly passing", "worse": "less accurate",
        "better": "more accurate", "slower": "slower", "faster": "faster", "same": "unchanged",
        "still failing": "unchanged"}
    assert result.loc["slower", "time_ratio"] == pytest.approx(3.1 / 2.0, rel=1e-15)
    assert result.loc["same", "error_ratio"] == pytest.approx(5.0, rel=1e-15)
    assert list(result.columns[:4]) == ["scenario", "adapter", "method", "dt"]
    assert result.loc["fails", "status_b"] == "diverged"


def test_compare_runs_without_calibration_or_below_the_error_floor_is_unchanged():
    before = frame_of([{"case_id": "x", "status": "ok", "main_output_error": 1e-14,
                        "wall_time_s": 1.0}])
    after = frame_of([{"case_id": "x", "status": "ok", "main_output_error": 1e-12,
                       "wall_time_s": 9.0}])
    assert run_compare.compare_runs(before, after, 1.0, 1.0)["change"].item() == "less accurate"
    result = run_compare.compare_runs(before, after, None, 1.0, error_floor=1e-10)
    assert result["change"].item() == "unchanged" and np.isnan(result["time_ratio"].item())
    assert result["error_ratio"].item() == 1.0
    with pytest.raises(ValueError, match="calibration_b"):
        run_compare.compare_runs(before, after, 1.0, 0.0)


def test_compare_runs_reads_stored_runs(root):
    runs = []
    for wall in (1.0, 5.0):
        run = store.RunStore.create(campaign())
        run.set_calibration(1.0)
        for spec in SPECS:
            run.add(row_for(spec, wall_time_s=wall), None)
        runs.append(run)
    result = run_compare.compare_runs(runs[0].cases(), runs[1].cases(), runs[0].calibration_s,
                                runs[1].calibration_s)
    assert list(result["case_id"]) == [spec.case_id for spec in SPECS]
    assert (result["change"] == "slower").all()


if __name__ == "__main__":
    write_v1_store(V1_ROOT)
    sys.exit(0)
